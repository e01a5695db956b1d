"""The candidate library: physically named effects with bounded parameter vectors.

Every candidate predicts through :mod:`quadfault.effects` (the same physics the simulator's
plant runs) and :mod:`quadfault.dynamics` (the same rigid-body equations). A candidate acts at
one stage of the model:

* ``thrust`` -- transforms the produced rotor thrusts (efficiency, scale, ground effect,
  delay, lag; applied in that order);
* ``wrench`` -- adds an external force (world) and/or moment (body) (drag, wind, CoM offset,
  inertia).

Bounds scale with the nominal vehicle (mass m [kg], gravity g, rotor distance ``arm`` [m]).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadfault import effects as fx
from quadfault.diagnosis.residuals import Replay, model_channels


def lag_series(f: np.ndarray, dt: np.ndarray, tau: float) -> np.ndarray:
    """:func:`quadfault.effects.lag_series` (the same recursion
    ``y_k = y_{k-1} + g_k (f_k - y_{k-1})``, the same result to rounding) without a
    per-sample Python loop for any steps (jittery or merged logs) and without importing
    ``scipy.signal``: the linear recurrence is solved by a parallel prefix scan (log2 N
    vectorised passes)."""
    f = np.asarray(f, dtype=float)
    g = fx.lag_gain(dt, tau)
    a = np.repeat((1.0 - g)[:, None], f.shape[1], axis=1)
    b = g[:, None] * f
    a[0], b[0] = 0.0, f[0]  # starts at the first command, as the plant does
    s = 1
    while s < len(f):
        b[s:] += a[s:] * b[:-s]
        a[s:] *= a[:-s]
        s *= 2
    return b


def drag_basis(rp: Replay) -> np.ndarray:
    """``(M, 3, 3)``: column i is the drag force [N] of ``k = e_i`` (1 N s/m on body axis i)
    at every interval of ``rp`` (:func:`quadfault.effects.drag_force`, linear in ``k``);
    cached on the replay."""
    D = rp.__dict__.get("_drag_basis")
    if D is None:
        D = np.stack([fx.drag_force(rp.R, rp.v, e) for e in np.eye(3)], axis=-1)
        object.__setattr__(rp, "_drag_basis", D)
    return D


@dataclass(frozen=True)
class Candidate:
    """One named effect of the library.

    Attributes:
        name: canonical effect name (CONTRACT.md sec. 4).
        labels: name of each scalar parameter, with its unit.
        lower, upper: bounds; x0: neutral value (the nominal model).
        starts: initial guesses tried before the local fit (multi-modal effects).
        stage: ``"thrust"`` or ``"wrench"``; order: position among thrust stages.
        needs_pose: the effect needs position/velocity/attitude (not testable on IMU logs).
        rotor_side: the effect acts between the command and the rotor speed (motor
            dynamics, the command curve), so measured rotor speeds see it (``rotor_*``
            channels of :mod:`~quadfault.diagnosis.residuals`); effects after the rotor
            speed (propeller, aerodynamics) leave those channels unchanged.
        frames: ``((param_key, "world" | "body"), ...)``: public parameters that are
            vectors in the world or body frame, reported in the recording's own frame.
    """

    name: str
    labels: tuple
    lower: tuple
    upper: tuple
    x0: tuple
    starts: tuple
    stage: str
    order: int = 0
    needs_pose: bool = False
    rotor_side: bool = False
    frames: tuple = ()

    @property
    def size(self) -> int:
        return len(self.x0)

    # model hooks -------------------------------------------------------------------------
    def thrust(self, x, rp: Replay, f):
        n = self.name
        if n == "motor_efficiency":
            return f * x[None, :]
        if n == "thrust_scale":
            return f * x[0]
        if n == "ground_effect":
            r = float(np.sqrt(max(x[0], 0.0)))
            return f * fx.ground_effect_factor(-rp.p[:, 2], r)[:, None]
        if n in TIMING:
            return timing_thrust(n, x, rp.t, rp.dt, f)
        raise KeyError(n)

    def wrench(self, x, vehicle, R, v, w, thrust, moment):
        """External force (world) [N] and moment (body) [N m]; either may be None."""
        n = self.name
        if n == "drag":
            return fx.drag_force(R, v, x), None
        if n == "wind":
            return np.broadcast_to(x, v.shape), None
        if n == "com_offset":
            return None, fx.com_offset_moment(thrust, x)
        if n == "inertia":
            Jt = fx.scaled_inertia(vehicle.inertia, x)
            return None, fx.inertia_moment(w, moment, vehicle.inertia, Jt)
        raise KeyError(n)


#: thrust-stage effects with memory: on merged (fast) logs they act on the raw commands
TIMING = ("delay", "motor_lag")


def timing_thrust(name: str, x, t: np.ndarray, dt: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Held thrust over each interval of sample times ``t`` after a pure ``delay`` (the mean
    of the command zero-order hold shifted by ``x[0]`` [s]) or a first-order ``motor_lag``
    (time constant ``x[0]`` [s])."""
    if name == "delay":
        tk = t[:-1]
        c = fx.zoh_cumulative(tk, f)
        return fx.zoh_mean(tk, f, c, tk - x[0], t[1:] - x[0])
    if name == "motor_lag":
        return lag_series(f, dt, x[0])
    raise KeyError(name)


def build_library(rp: Replay) -> list[Candidate]:
    """All candidates, with bounds scaled to the nominal vehicle of ``rp``."""
    m, g, arm = rp.vehicle.mass, rp.vehicle.gravity, rp.arm
    dt = float(np.median(rp.dt))
    one4, one3 = (1.0,) * 4, (1.0,) * 3
    lib = [
        Candidate("motor_efficiency", ("eta1 [-]", "eta2 [-]", "eta3 [-]", "eta4 [-]"),
                  (0.1,) * 4, (1.6,) * 4, one4, (one4,), "thrust", 0),
        Candidate("thrust_scale", ("scale [-]",), (0.2,), (2.0,), (1.0,), ((1.0,),), "thrust", 0),
        Candidate("ground_effect", ("rotor_radius^2 [m^2]",), (0.0,), ((3 * arm) ** 2,), (0.0,),
                  tuple(((k * arm) ** 2,) for k in (0.3, 0.6, 1.0, 1.5)), "thrust", 1,
                  needs_pose=True),
        Candidate("delay", ("delay [s]",), (0.0,), (0.3,), (0.0,),
                  tuple((d,) for d in np.unique(np.r_[np.arange(0.0, 0.2, max(dt, 0.01)), 0.25])),
                  "thrust", 2, rotor_side=True),
        Candidate("motor_lag", ("tau [s]",), (1e-4,), (0.6,), (1e-4,),
                  tuple((tau,) for tau in (0.005, 0.01, 0.02, 0.04, 0.07, 0.12, 0.2, 0.35)),
                  "thrust", 3, rotor_side=True),
        Candidate("drag", ("kx [N s/m]", "ky [N s/m]", "kz [N s/m]"), (0.0,) * 3,
                  (30.0 * m,) * 3, (0.0,) * 3, ((0.0,) * 3, (0.5 * m,) * 3), "wrench",
                  needs_pose=True),
        Candidate("wind", ("Fx [N]", "Fy [N]", "Fz [N]"), (-m * g,) * 3, (m * g,) * 3,
                  (0.0,) * 3, ((0.0,) * 3,), "wrench", needs_pose=True,
                  frames=(("force_N", "world"), ("air_velocity_m_per_s", "world"))),
        Candidate("com_offset", ("rx [m]", "ry [m]"), (-arm,) * 2, (arm,) * 2, (0.0, 0.0),
                  ((0.0, 0.0),), "wrench", frames=(("offset_m", "body"),)),
        Candidate("inertia", ("sx [-]", "sy [-]", "sz [-]"), (0.2,) * 3, (5.0,) * 3, one3,
                  (one3,), "wrench"),
    ]
    return lib


def thrust_series(rp: Replay, terms) -> np.ndarray:
    """Produced rotor thrusts (M, n) [N] after the thrust-stage terms ``[(cand, x), ...]``.

    On merged (fast) logs (``rp.raw``) the timing effects act on the raw commands, which are
    then merged; the pointwise stages (efficiency, scale, ground effect) follow on the merged
    thrust -- exact for the constant factors, and for the ground effect up to its variation
    within one internal step."""
    stages = sorted((t for t in terms if t[0].stage == "thrust"), key=lambda t: t[0].order)
    timing = [t for t in stages if t[0].name in TIMING]
    f = rp.f
    if timing and rp.raw is not None:
        raw = rp.raw
        fr = raw["f"]
        for cand, x in timing:
            fr = timing_thrust(cand.name, np.asarray(x, dtype=float), raw["t"], raw["dt"], fr)
        f = np.asarray(raw["merge"] @ fr)
        stages = [t for t in stages if t[0].name not in TIMING]
    for cand, x in stages:
        f = cand.thrust(np.asarray(x, dtype=float), rp, f)
    return f


def predict_intervals(rp: Replay, terms) -> np.ndarray:
    """Model channels (M, C) per interval for the nominal model plus ``terms``."""
    f = thrust_series(rp, terms)
    W = rp.vehicle.wrench(f)
    T, M = W[:, 0], W[:, 1:]
    F = Mx = None
    for cand, x in terms:
        if cand.stage != "wrench":
            continue
        if cand.name == "drag":  # the same force, from its cached linear basis
            dF, dM = drag_basis(rp) @ np.asarray(x, dtype=float), None
        else:
            dF, dM = cand.wrench(np.asarray(x, dtype=float), rp.vehicle, rp.R, rp.v, rp.w, T, M)
        if dF is not None:
            F = dF if F is None else F + dF
        if dM is not None:
            Mx = dM if Mx is None else Mx + dM
    out = model_channels(rp, f, F, Mx, T, M)
    if rp.has_rotor:  # measured rotor speeds see only the effects before the rotor speed
        out = np.hstack((out, thrust_series(rp, [t for t in terms if t[0].rotor_side])))
    return out


def predict(rp: Replay, terms) -> np.ndarray:
    """Block-mean model channels (B, C)."""
    return rp.block_mean(predict_intervals(rp, terms))


def public_params(cand: Candidate, x, sd, vehicle, selected: dict) -> tuple[dict, dict]:
    """``params`` and ``uncertainty`` (one sigma) as reported in the diagnosis JSON."""
    x = np.asarray(x, dtype=float)
    sd = np.asarray(sd, dtype=float)
    n = cand.name
    if n == "motor_efficiency":
        return {"eta": x.tolist()}, {"eta": sd.tolist()}
    if n == "thrust_scale":
        return {"scale": x[0]}, {"scale": sd[0]}
    if n == "ground_effect":
        r = float(np.sqrt(max(x[0], 0.0)))
        sr = float(sd[0] / (2 * r)) if r > 0 else float(np.sqrt(sd[0]))
        return {"rotor_radius_m": r, "ground_z_m": 0.0}, {"rotor_radius_m": sr}
    if n == "delay":
        return {"delay_s": x[0]}, {"delay_s": sd[0]}
    if n == "motor_lag":
        return {"tau_s": x[0]}, {"tau_s": sd[0]}
    if n == "drag":
        return {"k_N_s_per_m": x.tolist()}, {"k_N_s_per_m": sd.tolist()}
    if n == "wind":
        if "drag" in selected:
            k = np.asarray(selected["drag"], dtype=float)
            kk = np.array([0.5 * (k[0] + k[1])] * 2 + [k[2]])
            kk = np.maximum(kk, 1e-9)
            return ({"air_velocity_m_per_s": (x / kk).tolist(), "force_N": x.tolist()},
                    {"air_velocity_m_per_s": (sd / kk).tolist(), "force_N": sd.tolist()})
        return {"force_N": x.tolist()}, {"force_N": sd.tolist()}
    if n == "com_offset":
        return {"offset_m": x.tolist()}, {"offset_m": sd.tolist()}
    if n == "inertia":
        return ({"scale": x.tolist(), "inertia_diag_kg_m2": (np.diag(vehicle.inertia) * x).tolist()},
                {"scale": sd.tolist()})
    raise KeyError(n)


EXPLANATIONS = {
    "motor_efficiency": "rotor thrusts are eta_i times the commanded ones (per-rotor thrust loss)",
    "thrust_scale": "all rotors produce a common factor of the commanded thrust",
    "ground_effect": "thrust grows near the ground (Cheeseman-Bennett, ground plane at z = 0)",
    "delay": "the rotor thrust follows the command after a pure delay",
    "motor_lag": "the rotor thrust follows the command through first-order dynamics",
    "drag": "a force opposes the velocity through the air, F = -R diag(k) R^T v",
    "wind": "a steady external force pushes the vehicle (moving air)",
    "com_offset": "the centre of mass is offset from the rotor-plane centre: thrust makes a moment",
    "inertia": "the inertia differs from the nominal value (angular response scaled)",
}

#: Effects the data cannot always tell apart; counted as one class in the blinded study.
EQUIVALENT = {"thrust_scale": "thrust", "motor_efficiency": "thrust",
              "delay": "timing", "motor_lag": "timing"}
