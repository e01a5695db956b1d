"""The noise of a recording's streams, measured from the recording alone (no ground truth).

For each stream of :data:`quadfault.model.sensors.STREAMS` that the recording has
(``position``, ``velocity``, ``attitude`` as roll, pitch, yaw; ``gyro``; ``accel``),
:func:`measure_noise` gives, per axis and as one number (the median over the axes):

* ``rate`` [Hz]: the stream's own rate -- an importer's ``meta.import.stream_rates_hz`` when
  it resampled the log, else the rate at which the values change when most values last two
  rows or more (a held stream) -- and the
  samples it is measured on (the distinct ones, or every k-th row of an interpolated stream);
* ``white``: the white noise per sample, from the third difference of those samples
  (``1.4826 MAD(d3 x) / sqrt(20)``; a smooth motion hardly enters a third difference);
  ``white_check`` is ``MAD(d3) / MAD(d2) * sqrt(6/20)``: about 1 for white noise, well below 1
  where the motion, not noise, drives the differences (then ``white`` is an upper bound);
* ``highpass``: the standard deviation of what a zero-phase high-pass at :data:`HIGHPASS_HZ`
  (or a quarter of the rate, the lower) leaves -- white noise plus the motors' vibration;
  ``peak_hz``: the frequency of the largest peak of that residual's spectrum (Welch), and
  ``floor``: the white noise the spectrum's median level above the cut-off implies;
* for the estimator's outputs (position, velocity, attitude), their **inconsistency** with
  the stream they integrate (position with velocity, velocity with the accelerometer's
  specific force rotated to the world and gravity added, attitude with the gyro): the
  residual ``x - integral(dx/dt)`` after a moving average of :data:`DETREND_S` is removed
  (bias and slow drift), its standard deviation ``markov`` and the time ``tau`` [s] at which
  its autocorrelation falls to 1/e. Without ground truth this is what the recording shows of
  the coloured part of an estimator's error (its corrections), a lower bound of that error;
  wander slower than the moving average is left out, which bounds ``tau`` at about a quarter
  of it; a stream is integrated only at :data:`MIN_INTEGRAL_HZ` or faster;
* ``latency`` [s]: how far the stream lags the raw IMU: velocity after the accelerometer,
  attitude after the gyro, position after the velocity plus the velocity's own latency; from
  the peak of the cross-correlation of the two without their slow motion (positive: the
  estimate is late; None where the peak is weak or at the search's end);
* ``bias`` of the gyro and the accelerometer (body frame): the median difference from the
  rate the attitude implies and from the acceleration the velocity implies.

Numbers a recording cannot give (a missing stream, too few samples) are None, with a
``notes`` entry saying why; a stream the importer computed from another (its
``meta.import.missing`` says so, e.g. a velocity differentiated from the position) is not a
measurement and is left out the same way.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from quadfault.model.rotation import logm_so3, quat_to_rot, rot_to_euler_zyx
from quadfault.model.sensors import STREAMS

#: high-pass cut-off of the ``highpass`` residual [Hz]
HIGHPASS_HZ = 20.0
#: the moving average removed from an inconsistency residual [s]
DETREND_S = 2.0
#: the slow motion (and drift) removed before a latency is measured: a moving average [s]
LATENCY_BAND_S = 1.0
#: the least correlation at the peak for a latency to be reported
MIN_CORRELATION = 0.5
#: the largest latency searched [s]
MAX_LAG_S = 0.25
#: the slowest stream integrated for an inconsistency [Hz] (slower ones alias their motion)
MIN_INTEGRAL_HZ = 20.0
#: ``meta.import.stream_rates_hz`` key of each stream
RATE_KEYS = {"position": "pos", "velocity": "vel", "attitude": "q", "gyro": "w", "accel": "acc"}


def _series(rec, name):
    """The stream ``name`` on the recording's rows (n, 3), or None."""
    if name == "position":
        return rec.position
    if name == "velocity":
        return rec.velocity
    if name == "attitude":
        if rec.quaternion is None:
            return None
        return np.unwrap(rot_to_euler_zyx(quat_to_rot(rec.quaternion)), axis=0)
    if name == "gyro":
        return rec.omega
    return rec.accel


def _own_samples(rec, name, x):
    """(rows of the stream's own samples, its rate [Hz], how the rate was found)."""
    t = rec.t
    dt = float(np.median(np.diff(t)))
    row_rate = 1.0 / dt
    duration = float(t[-1] - t[0])
    changed = np.flatnonzero(np.any(np.diff(x, axis=0) != 0.0, axis=1)) + 1
    changed = np.concatenate([[0], changed])
    distinct_rate = len(changed) / max(duration, dt)
    meta_rate = ((rec.meta or {}).get("import") or {}).get("stream_rates_hz", {})
    meta_rate = meta_rate.get(RATE_KEYS[name])
    # held: most values last two rows or more (a quantised stream repeats now and then)
    held = len(changed) > 2 and float(np.median(np.diff(changed))) >= 2.0
    if held:
        rate = distinct_rate if meta_rate is None else min(distinct_rate, float(meta_rate))
        return changed, rate, "held samples (distinct values)"
    if meta_rate is not None and float(meta_rate) < 0.8 * row_rate:
        k = max(1, int(round(row_rate / float(meta_rate))))
        return np.arange(0, len(t), k), float(meta_rate), "importer's stream rate"
    return np.arange(len(t)), row_rate, "every row"


def _segments(t, rows, rate):
    """Runs of ``rows`` without a gap (a step longer than 2.5 periods)."""
    if len(rows) < 2:
        return [rows]
    cut = np.flatnonzero(np.diff(t[rows]) > 2.5 / rate) + 1
    return np.split(rows, cut)


def _mad(x):
    """A robust standard deviation: 1.4826 MAD, or where most values are equal (a quantised
    stream's differences) the standard deviation of all but the largest 1 %."""
    x = np.asarray(x, dtype=float)
    if not x.size:
        return math.nan
    mad = 1.4826 * float(np.median(np.abs(x - np.median(x))))
    if mad > 0:
        return mad
    keep = np.abs(x) <= np.quantile(np.abs(x), 0.99)
    return float(np.std(x[keep]))


def _white(xs):
    """(white per axis, check per axis) from the third and second differences of segments."""
    d3 = [np.diff(s, 3, axis=0) for s in xs if len(s) > 8]
    d2 = [np.diff(s, 2, axis=0) for s in xs if len(s) > 8]
    if not d3:
        return None, None
    d3, d2 = np.concatenate(d3), np.concatenate(d2)
    w = np.array([_mad(d3[:, a]) for a in range(3)]) / math.sqrt(20.0)
    m2 = np.array([_mad(d2[:, a]) for a in range(3)])
    check = np.where(m2 > 0, w * math.sqrt(20.0) / np.where(m2 > 0, m2, 1.0), math.nan)
    return w, check * math.sqrt(6.0 / 20.0)


def _highpass(xs, rate):
    """(std per axis of the high-passed residual, peak frequency [Hz], spectral floor)."""
    fc = min(HIGHPASS_HZ, rate / 4.0)
    sos = signal.butter(2, fc, "highpass", fs=rate, output="sos")
    parts = [signal.sosfiltfilt(sos, s, axis=0) for s in xs if len(s) > 60]
    if not parts:
        return None, None, None
    r = np.concatenate(parts)
    std = r.std(axis=0)
    longest = max(parts, key=len)
    f, p = signal.welch(longest, fs=rate, axis=0, nperseg=min(len(longest), 512))
    above = f > fc * 1.5
    peak = float(f[above][np.argmax(p[above].sum(axis=1))]) if above.any() else None
    floor = np.sqrt(np.median(p[above], axis=0) * rate / 2.0) if above.any() else None
    return std, peak, floor


def _on_rows(t, rows, x):
    """The stream's own samples ``x[rows]`` back on every row (linear between samples)."""
    return np.stack([np.interp(t, t[rows], x[rows, a]) for a in range(x.shape[1])], axis=1)


def _moving_mean(x, n):
    n = max(1, min(int(n), len(x)))
    c = np.cumsum(np.vstack([np.zeros((1, x.shape[1])), x]), axis=0)
    lo = np.clip(np.arange(len(x)) - n // 2, 0, len(x) - n)
    return (c[lo + n] - c[lo]) / n


def _inconsistency(t, x, dxdt):
    """(std per axis, correlation time [s]) of ``x - integral(dxdt)`` without its moving
    average of DETREND_S."""
    dt = float(np.median(np.diff(t)))
    step = np.diff(t)[:, None] * 0.5 * (dxdt[1:] + dxdt[:-1])
    r = x - x[0] - np.vstack([np.zeros((1, 3)), np.cumsum(step, axis=0)])
    r = r - _moving_mean(r, DETREND_S / dt)
    std = r.std(axis=0)
    taus = []
    for a in range(3):
        y = r[:, a] - r[:, a].mean()
        n = min(len(y) // 2, int(DETREND_S / dt))
        ac = np.correlate(y, y[: len(y) - n], "valid")[: n + 1]
        ac = ac / ac[0] if ac[0] > 0 else ac
        below = np.flatnonzero(ac < math.exp(-1.0))
        taus.append(float(below[0] * dt) if below.size else math.nan)
    return std, float(np.nanmedian(taus)) if np.isfinite(taus).any() else None


def _latency(t, x, ref):
    """How late ``x`` follows ``ref`` [s] (both on the rows; per-axis cross-correlation of the
    two without their moving averages of :data:`LATENCY_BAND_S`, summed)."""
    dt = float(np.median(np.diff(t)))
    m = int(MAX_LAG_S / dt)
    n_avg = LATENCY_BAND_S / dt
    a, b = x - _moving_mean(x, n_avg), ref - _moving_mean(ref, n_avg)
    n = len(a)
    if n < 4 * m + 10:
        return None
    lags = np.arange(-m, m + 1)
    cc = np.array([np.sum(a[m + k : n - m + k] * b[m : n - m]) for k in lags])
    k = int(np.argmax(cc))
    norm = math.sqrt(float(np.sum(a[m : n - m] ** 2) * np.sum(b[m : n - m] ** 2)))
    if k in (0, len(cc) - 1) or norm == 0 or cc[k] / norm < MIN_CORRELATION:
        return None  # no clear peak: the motion does not show the lag
    if 0 < k < len(cc) - 1:  # parabola through the peak
        den = cc[k - 1] - 2 * cc[k] + cc[k + 1]
        off = 0.5 * (cc[k - 1] - cc[k + 1]) / den if den != 0 else 0.0
    else:
        off = 0.0
    return float((lags[k] + off) * dt)


def _rates_from_attitude(t, quat):
    """Body rate [rad/s] implied by consecutive attitudes, on the rows (n, 3)."""
    R = quat_to_rot(quat)
    rel = np.einsum("nji,njk->nik", R[:-1], R[1:])
    w = logm_so3(rel) / np.diff(t)[:, None]
    return np.vstack([w, w[-1:]])


#: the keys of a stream's measurement
FIELDS = (
    "rate",
    "rate_from",
    "samples",
    "white",
    "white_axes",
    "white_check",
    "highpass",
    "highpass_axes",
    "peak_hz",
    "floor",
    "markov",
    "tau",
    "latency",
    "bias",
    "notes",
)
#: how an importer's ``meta.import.missing`` names a stream it derived from another
_DERIVED_WORDS = {
    "position": "position",
    "velocity": "velocity",
    "attitude": "attitude",
    "body rate": "gyro",
    "gyro": "gyro",
    "accelerometer": "accel",
}
_HOW = ("differentiated", "integrated", "derived", "reconstructed")


def _derived(rec) -> dict:
    """``{stream: the importer's words}`` of the streams the importer computed from other
    streams (``meta.import.missing``, e.g. "velocity (differentiated from position)")."""
    missing = ((rec.meta or {}).get("import") or {}).get("missing") or []
    out = {}
    for text in missing:
        low = str(text).lower()
        for word, stream in _DERIVED_WORDS.items():
            if low.startswith(word) and any(h in low for h in _HOW):
                out.setdefault(stream, str(text))
    return out


def measure_noise(rec) -> dict:
    """Each stream's noise in recording ``rec`` (see the module docstring): ``{stream:
    {rate, rate_from, samples, white, white_axes, white_check, highpass, highpass_axes,
    peak_hz, floor, markov, tau, latency, bias, notes}}`` for the streams it has."""
    t = np.asarray(rec.t, dtype=float)
    out = {}
    on_rows = {}
    derived = _derived(rec)
    for name in STREAMS:
        x = _series(rec, name)
        if x is None:
            continue
        if name in derived:
            out[name] = {k: None for k in FIELDS}
            out[name]["notes"] = [
                f"derived by the importer ({derived[name]}), not logged: not measured"
            ]
            continue
        x = np.asarray(x, dtype=float)
        rows, rate, how = _own_samples(rec, name, x)
        segs = [x[s] for s in _segments(t, rows, rate)]
        white, check = _white(segs)
        hp, peak, floor = _highpass(segs, rate)
        on_rows[name] = _on_rows(t, rows, x)
        med = lambda v: None if v is None else float(np.median(v))  # noqa: E731
        out[name] = {
            "rate": float(rate),
            "rate_from": how,
            "samples": int(len(rows)),
            "white": med(white),
            "white_axes": None if white is None else white.tolist(),
            "white_check": med(check),
            "highpass": med(hp),
            "highpass_axes": None if hp is None else hp.tolist(),
            "peak_hz": peak,
            "floor": med(floor),
            "markov": None,
            "tau": None,
            "latency": None,
            "bias": None,
            "notes": [],
        }
    g = float(getattr(rec.vehicle, "gravity", 9.81))
    R = None if rec.quaternion is None or "attitude" in derived else quat_to_rot(rec.quaternion)
    acc_world = None
    if R is not None and "accel" in on_rows:
        acc_world = np.einsum("nij,nj->ni", R, on_rows["accel"]) + np.array([0.0, 0.0, g])
    pairs = {  # (the velocity's latency before the position's, which adds it)
        "velocity": acc_world,
        "attitude": None if R is None or "gyro" not in on_rows else "gyro",
        "position": on_rows.get("velocity"),
    }
    for name, rate_of in pairs.items():
        if name not in out or out[name]["rate"] is None:
            continue
        if rate_of is None:
            if name in out:
                out[name]["notes"].append(
                    "no stream to check it against (needs "
                    + {"position": "velocity", "velocity": "attitude and accelerometer"}.get(
                        name, "gyro"
                    )
                    + "): markov, tau and latency not measured"
                )
            continue
        if name == "attitude":
            w_att = _rates_from_attitude(t, rec.quaternion)
            # the attitude's inconsistency with the gyro, as a rotation vector in the body
            err = np.cumsum((w_att - on_rows["gyro"]) * np.gradient(t)[:, None], axis=0)
            std, tau = _inconsistency(t, err, np.zeros_like(err))
            h = np.gradient(t)[:, None]
            lat = _latency(t, np.cumsum(w_att * h, axis=0), np.cumsum(on_rows["gyro"] * h, axis=0))
        else:
            std, tau = _inconsistency(t, on_rows[name], rate_of)
            ref = np.cumsum(rate_of * np.gradient(t)[:, None], axis=0)
            lat = _latency(t, on_rows[name], ref)
        ref_name = {"position": "velocity", "velocity": "accel", "attitude": "gyro"}[name]
        ref_rate = (out[ref_name]["rate"] or 0.0) if ref_name in out else 0.0
        if ref_rate < MIN_INTEGRAL_HZ:
            out[name]["notes"].append(
                f"{ref_name} at {ref_rate:.3g} Hz (below {MIN_INTEGRAL_HZ:g} Hz) is too slow to "
                "integrate: markov, tau and latency not measured"
            )
            continue
        out[name]["markov"] = float(np.median(std))
        out[name]["markov_axes"] = std.tolist()
        out[name]["tau"] = tau
        if lat is None:
            out[name]["notes"].append(
                f"no clear peak of the correlation with {ref_name}: latency not measured"
            )
        elif name == "position":  # after the velocity, itself late after the accelerometer
            v_lat = out.get("velocity", {}).get("latency")
            lat = None if v_lat is None else lat + v_lat
        out[name]["latency"] = lat
    if "gyro" in on_rows and R is not None:
        d = on_rows["gyro"] - _rates_from_attitude(t, rec.quaternion)
        out["gyro"]["bias"] = float(np.median(np.abs(d.mean(axis=0))))
        out["gyro"]["bias_axes"] = d.mean(axis=0).tolist()
    if "accel" in on_rows and R is not None and "velocity" in on_rows:
        dvdt = np.gradient(on_rows["velocity"], t, axis=0)
        d = on_rows["accel"] - np.einsum("nji,nj->ni", R, dvdt - np.array([0.0, 0.0, g]))
        out["accel"]["bias"] = float(np.median(np.abs(d.mean(axis=0))))
        out["accel"]["bias_axes"] = d.mean(axis=0).tolist()
    for name in ("gyro", "accel"):
        if name in on_rows and out[name]["bias"] is None:
            out[name]["notes"].append("bias not measured (needs attitude and velocity)")
    return out


__all__ = ["DETREND_S", "HIGHPASS_HZ", "MAX_LAG_S", "MIN_INTEGRAL_HZ", "measure_noise"]
