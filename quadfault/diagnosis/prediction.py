"""Held-out open-loop prediction: nominal vs diagnosed model vs trivial baselines.

From up to ``max_starts`` evenly spaced free-flight samples, the recorded state is
integrated with the recorded commands by the simulator's own integrator
(:func:`quadfault.model.dynamics.step_rk4`, all starts at once as a batch; at most 100 steps over
the longest horizon, so consecutive held commands are merged into their duration-weighted
mean) and compared with the recorded state after each horizon (default 0.05, 0.1, 0.2, 0.5
s). Every start lies in one cross-validation fold and the diagnosed model is the fit that did
not see that fold, so the prediction is held out. Four predictors:

* ``nominal`` -- the sidecar's vehicle, the commands, nothing else;
* ``model`` -- nominal plus the accepted effects (fold fits);
* ``constant_velocity`` -- position ``p + v h``, velocity ``v``, attitude rotating at the
  current body rate, rate unchanged;
* ``constant_acceleration`` -- the same with the acceleration and angular acceleration
  measured over the block before the start (``p + v h + a h^2 / 2``, ``w + alpha h``).

A pose log reports position, velocity, attitude and body-rate errors; an IMU-only log has no
position or attitude to start from, so it predicts the body rate and the attitude change
(relative to the start, measured by integrating the gyro) -- never nothing. Errors are RMS
over the starts; starts whose horizon would cross a gap or an excluded span are not used.
"""

from __future__ import annotations

import numpy as np

from quadfault.diagnosis.library import (
    WrenchInputs,
    body_vehicle,
    external_wrench,
    needs_rate,
    thrust_series,
)
from quadfault.diagnosis.residuals import Replay
from quadfault.model.dynamics import RigidBodyState, step_rk4
from quadfault.model.rotation import expm_so3, rotation_angle

HORIZONS = (0.05, 0.1, 0.2, 0.5)
BASELINES = ("constant_velocity", "constant_acceleration")


def _measured_rotation(rp: Replay, rec, starts, n):
    """Attitude relative to each start after ``n`` intervals: the recorded one (pose), or the
    gyro integrated over the intervals (IMU-only)."""
    kn = rp.knots
    if rec.has_pose:
        R = rec.rotation[kn]
        return np.swapaxes(R[starts], -1, -2) @ R[starts + n]
    out = np.broadcast_to(np.eye(3), (len(starts), 3, 3)).copy()
    for j in range(n):
        out = out @ expm_so3(rp.w[starts + j] * rp.dt[starts + j][:, None])
    return out


def _rollout(rec, rp: Replay, terms, starts, steps, sub):
    """States after each of ``steps`` integration steps of ``sub`` intervals."""
    veh = rp.vehicle
    rated = needs_rate(terms)
    f, f_end = thrust_series(rp, terms, ends=True) if rated else (thrust_series(rp, terms), None)
    body = body_vehicle(veh, terms)
    kn = rp.knots
    S = len(starts)
    if rec.has_pose:
        s = RigidBodyState(
            rec.position[kn][starts].copy(),
            rec.velocity[kn][starts].copy(),
            rec.rotation[kn][starts].copy(),
            rec.omega[kn][starts].copy(),
        )
    else:  # attitude relative to the start; the translational state is not predicted
        s = RigidBodyState(
            np.zeros((S, 3)),
            np.zeros((S, 3)),
            np.broadcast_to(np.eye(3), (S, 3, 3)).copy(),
            rec.omega[kn][starts].copy(),
        )
    wterms = [(c, np.asarray(x, float)) for c, x in terms if c.stage == "wrench"]
    out = []
    for j in range(steps):
        span = starts[:, None] + j * sub + np.arange(sub)
        dts = rp.dt[span]
        dt = dts.sum(axis=1)
        fm = np.einsum("sk,skn->sn", dts, f[span]) / dt[:, None]  # mean held thrust
        W = veh.wrench(fm)
        T, M = W[:, 0], W[:, 1:]
        rate = None
        if rated:  # mean rate over the step: from the thrust held before it to its last one
            before = np.maximum(span[:, 0] - 1, 0)
            rate = (f_end[span[:, -1]] - f_end[before]) / dt[:, None]

        def external(st, T=T, M=M, rate=rate):
            F, Mx = external_wrench(wterms, WrenchInputs(veh, st.R, st.v, st.w, T, M, rate))
            return (
                np.zeros(st.p.shape) if F is None else F,
                np.zeros(st.w.shape) if Mx is None else Mx,
            )

        s = step_rk4(s, T, M, body, dt[:, None], external if wterms else None)
        out.append(s)
    return out


def _baseline(rec, rp: Replay, starts, n, kind):
    """Constant-velocity / constant-acceleration extrapolation over ``n`` intervals."""
    kn = rp.knots
    h = (rp.t[starts + n] - rp.t[starts])[:, None]
    w0 = rec.omega[kn][starts]
    back = np.maximum(starts - _block_steps(rp), 0)
    dtb = (rp.t[starts] - rp.t[back])[:, None]
    alpha = (w0 - rec.omega[kn][back]) / np.maximum(dtb, 1e-12)
    acc = 0.0
    if kind == "constant_velocity":
        alpha = 0.0 * alpha
    R_rel = expm_so3(w0 * h + 0.5 * alpha * h * h)
    w = w0 + alpha * h
    if not rec.has_pose:
        return None, None, R_rel, w
    p0, v0 = rec.position[kn][starts], rec.velocity[kn][starts]
    if kind == "constant_acceleration":
        acc = (v0 - rec.velocity[kn][back]) / np.maximum(dtb, 1e-12)
    return p0 + v0 * h + 0.5 * acc * h * h, v0 + acc * h, R_rel, w


def _block_steps(rp: Replay) -> int:
    """Intervals per block (the span of the baselines' acceleration estimate)."""
    return max(1, int(np.bincount(rp.block[rp.block >= 0]).max()))


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x)))) if np.size(x) else float("nan")


def open_loop_errors(
    rec, rp: Replay, fold_terms, fold_of_block, horizons=HORIZONS, max_starts: int = 60
) -> dict:
    """Held-out prediction errors at ``horizons`` [s] (module docstring).

    ``fold_terms``: per fold, the accepted effects ``[(cand, x), ...]`` fitted without that
    fold (empty lists: no effect accepted); ``fold_of_block``: fold index of each block."""
    med = float(np.median(rp.dt[rp.block >= 0]))  # the (merged) step inside blocks
    M = len(rp.dt)
    gap = np.r_[0, np.cumsum(rp.block < 0)]  # intervals outside blocks (gaps, excluded) so far
    back = _block_steps(rp)
    usable = [h for h in sorted(horizons) if 0 < h]
    while usable:
        nh = max(1, int(round(usable[-1] / med)))
        cand = np.arange(back, max(back, M - nh))
        cand = cand[
            (gap[cand + nh] == gap[cand]) & (gap[cand] == gap[cand - back]) & (rp.block[cand] >= 0)
        ]
        if len(cand):
            break
        usable.pop()
    if not usable:
        return {}
    starts = cand[np.unique(np.linspace(0, len(cand) - 1, min(max_starts, len(cand))).astype(int))]
    sub = max(1, -(-nh // 100))
    steps = nh // sub
    at = sorted({max(1, min(steps, int(round(h / med / sub)))) for h in usable})
    folds = fold_of_block[rp.block[starts]]
    pose = rec.has_pose
    keys = (["position_rmse_m", "velocity_rmse_m_per_s"] if pose else []) + [
        "attitude_rmse_deg",
        "rate_rmse_rad_per_s",
    ]
    errors = {k: {} for k in keys}
    per_start = {}
    kn = rp.knots
    S = len(starts)
    for label in ("nominal", "model"):
        P, V = np.zeros((steps, S, 3)), np.zeros((steps, S, 3))
        Rr, Wr = np.zeros((steps, S, 3, 3)), np.zeros((steps, S, 3))
        for k in np.unique(folds):
            sel = np.flatnonzero(folds == k)
            terms = [] if label == "nominal" else list(fold_terms[k])
            for j, st in enumerate(_rollout(rec, rp, terms, starts[sel], steps, sub)):
                P[j, sel], V[j, sel], Rr[j, sel], Wr[j, sel] = st.p, st.v, st.R, st.w
        for key in keys:
            errors[key][label] = []
        for a in at:
            n = a * sub
            R_meas = _measured_rotation(rp, rec, starts, n)
            R_pred = (
                np.swapaxes(rec.rotation[kn][starts], -1, -2) @ Rr[a - 1] if pose else Rr[a - 1]
            )
            e_att = np.degrees(rotation_angle(np.swapaxes(R_pred, -1, -2) @ R_meas))
            e_w = np.linalg.norm(Wr[a - 1] - rec.omega[kn][starts + n], axis=1)
            if pose:
                e_p = np.linalg.norm(P[a - 1] - rec.position[kn][starts + n], axis=1)
                errors["position_rmse_m"][label].append(_rms(e_p))
                errors["velocity_rmse_m_per_s"][label].append(
                    _rms(np.linalg.norm(V[a - 1] - rec.velocity[kn][starts + n], axis=1))
                )
                per_start.setdefault(label, []).append(e_p)
            else:
                per_start.setdefault(label, []).append(e_att)
            errors["attitude_rmse_deg"][label].append(_rms(e_att))
            errors["rate_rmse_rad_per_s"][label].append(_rms(e_w))
    for kind in BASELINES:
        for key in keys:
            errors[key][kind] = []
        for a in at:
            n = a * sub
            p, v, R_rel, w = _baseline(rec, rp, starts, n, kind)
            R_meas = _measured_rotation(rp, rec, starts, n)
            errors["attitude_rmse_deg"][kind].append(
                _rms(np.degrees(rotation_angle(np.swapaxes(R_rel, -1, -2) @ R_meas)))
            )
            errors["rate_rmse_rad_per_s"][kind].append(
                _rms(np.linalg.norm(w - rec.omega[kn][starts + n], axis=1))
            )
            if pose:
                errors["position_rmse_m"][kind].append(
                    _rms(np.linalg.norm(p - rec.position[kn][starts + n], axis=1))
                )
                errors["velocity_rmse_m_per_s"][kind].append(
                    _rms(np.linalg.norm(v - rec.velocity[kn][starts + n], axis=1))
                )
    horizons_s = [float(rp.t[starts[0] + a * sub] - rp.t[starts[0]]) for a in at]
    mid = int(np.argmin(np.abs(np.array(horizons_s) - 0.2)))
    return {
        "horizons_s": horizons_s,
        "n_starts": int(len(starts)),
        "held_out": "each start is predicted by the fit that did not see its fold",
        **errors,
        "_over_time": {
            "t": rp.t[starts],
            "horizon_s": horizons_s[mid],
            "quantity": "position error [m]" if pose else "attitude error [deg]",
            "nominal": per_start["nominal"][mid],
            "model": per_start["model"][mid],
        },
    }
