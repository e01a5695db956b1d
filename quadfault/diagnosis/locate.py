"""Locate the mismatch: time intervals per channel and the regime that explains it.

The normalised baseline residual of each channel is smoothed over about 0.5 s
(Savitzky-Golay, order 2, edges by polynomial fit: ``scipy.signal.savgol_filter`` with
``mode="interp"``, written here in numpy to spare the diagnosis the ~1 s import of
``scipy.signal``; the tests cross-check it); an interval is reported where the
smoothed residual exceeds 4 times the noise it would show on pure noise (the filter's noise
gain). For every channel whose normalised RMS exceeds 1.5, each regime variable (airspeed,
height above z = 0, thrust level T / mg, command rate, tilt, body rate) is correlated with the
smoothed residual (signed and absolute); the best-correlated one is reported with the residual
RMS in five quantile bins of that variable as evidence.
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from quadfault.diagnosis.residuals import Replay, channel_unit
from quadfault.diagnosis.result import Interval

REGIME_UNITS = {
    "airspeed": "m/s",
    "height": "m",
    "thrust_level": "T/(m g)",
    "command_rate": "1/s",
    "tilt": "deg",
    "body_rate": "rad/s",
}


def savgol_coeffs(window: int, order: int = 2) -> np.ndarray:
    """Smoothing weights of a centred Savitzky-Golay window (odd ``window``)."""
    x = np.arange(window, dtype=float) - window // 2
    return np.linalg.pinv(np.vander(x, order + 1, increasing=True))[0]


def savgol_filter(z: np.ndarray, window: int, order: int = 2) -> np.ndarray:
    """Savitzky-Golay smoothing of ``z`` (n, k) along axis 0 (odd ``window`` <= n); the first
    and last ``window // 2`` rows take the polynomial fitted to the first / last window."""
    z = np.asarray(z, dtype=float)
    n, h = len(z), window // 2
    out = np.empty_like(z)
    out[h : n - h] = sliding_window_view(z, window, axis=0) @ savgol_coeffs(window, order)
    V = np.vander(np.arange(window, dtype=float), order + 1, increasing=True)
    P = V @ np.linalg.pinv(V)  # fitted values of a window at each of its positions
    out[:h] = P[:h] @ z[:window]
    out[n - h :] = P[window - h :] @ z[n - window :]
    return out


def regime_variables(rp: Replay) -> dict:
    """Block means of the regime variables (B,) each."""
    veh = rp.vehicle
    out = {}
    T = rp.f.sum(axis=1)
    if rp.has_pose:
        out["airspeed"] = rp.block_mean(np.linalg.norm(rp.v, axis=1)[:, None])[:, 0]
        out["height"] = rp.block_mean(-rp.p[:, 2:3])[:, 0]
        cz = np.clip(rp.R[:, 2, 2] / np.maximum(np.linalg.norm(rp.R[:, :, 2], axis=1), 1e-9), -1, 1)
        out["tilt"] = rp.block_mean(np.degrees(np.arccos(cz))[:, None])[:, 0]
    out["thrust_level"] = rp.block_mean((T / veh.weight)[:, None])[:, 0]
    df = np.zeros_like(T)
    df[1:] = np.abs(np.diff(rp.f, axis=0)).sum(axis=1) / rp.dt[1:]
    out["command_rate"] = rp.block_mean((df / veh.weight)[:, None])[:, 0]
    out["body_rate"] = rp.block_mean(np.linalg.norm(rp.w, axis=1)[:, None])[:, 0]
    return out


def _window(rp: Replay) -> int:
    w = int(round(0.5 / float(np.median(rp.block_dur))))
    w = max(5, w + (w % 2 == 0))
    return min(w, rp.n_blocks - (1 - rp.n_blocks % 2))


def _runs(mask):
    edges = np.diff(np.r_[0, mask.astype(int), 0])
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)))


def _corr(a, b):
    if np.std(a) < 1e-12 or np.std(b) < 1e-12:
        return 0.0
    return float(np.corrcoef(a, b)[0, 1])


def locate(rp: Replay, residual: np.ndarray, scale: np.ndarray, per_channel: int = 5):
    """``(where, regimes)``: located intervals and regime evidence."""
    z = residual / scale
    win = _window(rp)
    if win < 5:
        return [], []
    gain = float(np.sqrt(np.sum(savgol_coeffs(win, 2) ** 2)))
    zs = savgol_filter(z, win, 2)
    thresh = 4.0 * gain
    where = []
    for j, ch in enumerate(rp.channels):
        mask = np.abs(zs[:, j]) > thresh
        # close short holes, drop blips
        runs = [(a, b) for a, b in _runs(mask)]
        merged = []
        for a, b in runs:
            if merged and a - merged[-1][1] < win:
                merged[-1] = (merged[-1][0], b)
            else:
                merged.append((a, b))
        merged = [(a, b) for a, b in merged if b - a >= max(3, win // 2)]
        merged.sort(key=lambda ab: -np.max(np.abs(zs[ab[0] : ab[1], j])))
        unit = channel_unit(ch)
        for a, b in merged[:per_channel]:
            seg = residual[a:b, j]
            excess = float(np.sqrt(np.mean(seg**2)) / scale[j])
            where.append(
                Interval(
                    ch,
                    float(rp.block_t[a] - 0.5 * rp.block_dur[a]),
                    float(rp.block_t[b - 1] + 0.5 * rp.block_dur[b - 1]),
                    f"mean residual {np.mean(seg):+.3g} {unit}, "
                    f"peak {seg[np.argmax(np.abs(seg))]:+.3g} {unit}, "
                    f"{excess:.1f}x noise",
                    excess,
                )
            )
    where.sort(key=lambda w: (w.t0, w.channel))
    regimes = []
    variables = regime_variables(rp)
    for j, ch in enumerate(rp.channels):
        if np.sqrt(np.mean(z[:, j] ** 2)) < 1.5:
            continue
        best = None
        for name, var in variables.items():
            c = max(abs(_corr(zs[:, j], var)), abs(_corr(np.abs(zs[:, j]), var)))
            if best is None or c > best[1]:
                best = (name, c)
        name, c = best
        var = variables[name]
        edges = np.quantile(var, np.linspace(0, 1, 6))
        bins = []
        for lo, hi in zip(edges[:-1], edges[1:]):
            sel = (var >= lo) & (var <= hi)
            if sel.any():
                bins.append([float(lo), float(hi), float(np.sqrt(np.mean(residual[sel, j] ** 2)))])
        regimes.append(
            {
                "channel": ch,
                "variable": name,
                "unit": REGIME_UNITS[name],
                "correlation": c,
                "bins_lo_hi_rms": bins,
                "all": {
                    k: max(abs(_corr(zs[:, j], v)), abs(_corr(np.abs(zs[:, j]), v)))
                    for k, v in variables.items()
                },
            }
        )
    return where, regimes
