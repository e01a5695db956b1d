"""Multi-step open-loop prediction from recorded states (before / after the diagnosis).

From up to ``max_starts`` evenly spaced samples the recorded state is integrated with the
recorded commands over ``horizon`` seconds by the simulator's own integrator
(:func:`quadfault.dynamics.step_rk4`, all starts at once as a batch; at most 100 steps per
horizon, so at high sample rates consecutive held commands are merged into their
duration-weighted mean), once with the nominal
model and once with the accepted effects; the errors against the recorded state at the
horizon are reported as RMS over the starts.
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
from quadfault.dynamics import RigidBodyState, step_rk4
from quadfault.rotation import rotation_angle


def _rollout(rec, rp: Replay, terms, starts, nh, max_steps=100):
    veh = rp.vehicle
    rated = needs_rate(terms)
    f, f_end = thrust_series(rp, terms, ends=True) if rated else (thrust_series(rp, terms), None)
    body = body_vehicle(veh, terms)
    kn = rp.knots
    P, V, Rm, W0 = rec.position[kn], rec.velocity[kn], rec.rotation[kn], rec.omega[kn]
    s = RigidBodyState(P[starts].copy(), V[starts].copy(), Rm[starts].copy(), W0[starts].copy())
    wterms = [(c, np.asarray(x, float)) for c, x in terms if c.stage == "wrench"]
    sub = max(1, -(-nh // max_steps))  # intervals merged per integration step
    n_steps = nh // sub
    curve = np.zeros(n_steps)
    for j in range(n_steps):
        span = starts[:, None] + j * sub + np.arange(sub)  # (S, sub) interval indices
        dts = rp.dt[span]
        dt = dts.sum(axis=1)
        fm = np.einsum("sk,skn->sn", dts, f[span]) / dt[:, None]  # mean held thrust
        idx = starts + (j + 1) * sub - 1
        W = veh.wrench(fm)
        T, M = W[:, 0], W[:, 1:]
        rate = None
        if rated:  # mean rate over the step: from the thrust held before it to its last one
            before = np.maximum(span[:, 0] - 1, 0)
            rate = (f_end[idx] - f_end[before]) / dt[:, None]

        def external(st, T=T, M=M, rate=rate):
            F, Mx = external_wrench(wterms, WrenchInputs(veh, st.R, st.v, st.w, T, M, rate))
            return (np.zeros(st.p.shape) if F is None else F,
                    np.zeros(st.w.shape) if Mx is None else Mx)

        s = step_rk4(s, T, M, body, dt[:, None], external if wterms else None)
        curve[j] = np.sqrt(np.mean(np.sum((s.p - P[idx + 1]) ** 2, axis=1)))
    end = starts + n_steps * sub
    ep = np.linalg.norm(s.p - P[end], axis=1)
    ev = np.linalg.norm(s.v - V[end], axis=1)
    ea = np.degrees(rotation_angle(np.swapaxes(s.R, -1, -2) @ Rm[end]))
    return ep, ev, ea, curve


def open_loop_errors(rec, rp: Replay, terms, horizon: float = 0.5, max_starts: int = 60) -> dict:
    """Errors at ``horizon`` [s] of the nominal model and of the diagnosed model."""
    med = float(np.median(rp.dt))
    nh = max(1, int(round(horizon / med)))
    M = len(rp.dt)
    if M <= nh + 1:
        return {}
    gap = np.r_[0, np.cumsum(rp.block < 0)]  # intervals outside blocks (gaps) so far
    cand = np.arange(0, M - nh)
    cand = cand[gap[cand + nh] == gap[cand]]
    if len(cand) == 0:
        return {}
    starts = cand[np.unique(np.linspace(0, len(cand) - 1, min(max_starts, len(cand))).astype(int))]
    out = {"horizon_s": nh * med, "n_starts": int(len(starts))}
    curves = {}
    for label, tm in (("nominal", []), ("model", list(terms))):
        ep, ev, ea, curve = _rollout(rec, rp, tm, starts, nh)
        out.setdefault("position_rmse_m", {})[label] = float(np.sqrt(np.mean(ep ** 2)))
        out.setdefault("velocity_rmse_m_per_s", {})[label] = float(np.sqrt(np.mean(ev ** 2)))
        out.setdefault("attitude_rmse_deg", {})[label] = float(np.sqrt(np.mean(ea ** 2)))
        curves[label] = curve
    out["_curve_t"] = np.linspace(0, nh * med, len(curves["nominal"]) + 1)[1:]
    out["_curves"] = curves
    return out
