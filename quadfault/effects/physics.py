"""The physics of the effects over arrays: compiled loops over the kernels.

Each function applies the kernel of :mod:`quadfault.effects.kernels` -- the code the closed
loop runs step by step for the simulator and the environments -- to every row of its
(broadcast) arguments: the mismatch diagnosis (:mod:`quadfault.diagnosis.library`) calls them
over a whole recording, so there is one implementation of each effect. Frames: world NED,
body FRD; rotor thrusts ``f`` [N] have the rotors on the last axis; a scalar argument gives a
scalar.
"""

from __future__ import annotations

import numpy as np

from quadfault.effects.kernels import (
    battery_factor1,
    blade_flapping3,
    com_offset_moment3,
    curve_command1,
    curve_thrust1,
    drag_force3,
    ground_effect_factor1,
    lag_gain1,
    lag_step1,
    rate_damping3,
    recurve1,
    rotor_inertia_moment1,
    thrust_rate1,
    zoh_integral,
    zoh_next1,
)
from quadfault.jit import jit
from quadfault.rotation import mat3, store3, vec3

E3 = np.array([0.0, 0.0, 1.0])


def _rows(batch: tuple, *arrays):
    """Each ``(array, width)`` broadcast to ``batch + width`` as C-contiguous float rows."""
    out = []
    for a, width in arrays:
        a = np.broadcast_to(np.asarray(a, dtype=float), batch + width)
        out.append(np.ascontiguousarray(a.reshape((-1,) + width)))
    return out


def _batch(*arrays) -> tuple:
    """The common batch shape of ``(array, width)`` pairs (``width`` trailing axes each)."""
    return np.broadcast_shapes(*(np.shape(a)[:np.ndim(a) - len(w)] for a, w in arrays))


def _shaped(out: np.ndarray, batch: tuple, width: tuple = ()):
    out = out.reshape(batch + width)
    return out[()] if out.ndim == 0 else out


# ----------------------------------------------------------------------------------------
# thrust stage: produced rotor thrust from the commanded one
@jit
def _curve_rows(curve, x, inverse, out):
    a, b, c = curve[0], curve[1], curve[2]
    for i in range(x.shape[0]):
        out[i] = curve_command1(a, b, c, x[i]) if inverse else curve_thrust1(a, b, c, x[i])


def _curve(curve, x, inverse: bool):
    c = np.array([float(v) for v in curve])
    (xs,) = _rows(np.shape(x), (x, ()))
    out = np.empty(len(xs))
    _curve_rows(c, xs, inverse, out)
    return _shaped(out, np.shape(x))


def curve_thrust(curve, u) -> np.ndarray:
    """Rotor thrust [N] of the command ``u`` through the curve ``f = a + b u + c u^2``."""
    return _curve(curve, u, False)


def curve_command(curve, f) -> np.ndarray:
    """The command ``u >= 0`` that the curve ``(a, b, c)`` maps to thrust ``f`` [N] (the
    larger root; ``u = 0`` where ``f`` is below the curve's value at 0)."""
    return _curve(curve, f, True)


def curve_from_changes(nominal, f_hover: float, changes) -> np.ndarray:
    """The curve ``(a, b, c)`` whose thrust differs from the ``nominal`` curve's by
    ``f_h (d0 + d1 (x - 1) + d2 (x - 1)^2)``, ``x = u / u_h`` the command relative to the
    hover command ``u_h`` (the nominal curve's command for ``f_h`` [N]); ``changes`` =
    ``(d0, d1, d2)`` [-]: hover thrust, slope and curvature changes relative to hover."""
    d0, d1, d2 = (float(v) for v in changes)
    uh = float(curve_command(nominal, f_hover))
    return np.asarray(nominal, dtype=float) + f_hover * np.array(
        [d0 - d1 + d2, (d1 - 2 * d2) / uh, d2 / uh ** 2])


@jit
def _recurve_rows(f, nominal, curve, out):
    nom = (nominal[0], nominal[1], nominal[2])
    cur = (curve[0], curve[1], curve[2])
    for i in range(f.shape[0]):
        out[i] = recurve1(f[i], nom, cur)


def recurve(f, nominal, curve) -> np.ndarray:
    """Thrust [N] produced through ``curve`` by the command that the ``nominal`` curve maps to
    the commanded thrust ``f`` [N] (never negative)."""
    (fs,) = _rows(np.shape(f), (f, ()))
    out = np.empty(len(fs))
    _recurve_rows(fs, np.array(nominal, dtype=float), np.array(curve, dtype=float), out)
    return _shaped(out, np.shape(f))


@jit
def _factor_rows(x, p, q, kind, out):
    for i in range(x.shape[0]):
        if kind == 0:
            out[i] = ground_effect_factor1(x[i], p)
        elif kind == 1:
            out[i] = battery_factor1(x[i], p, q)
        else:
            out[i] = lag_gain1(x[i], p)


def _factor(x, p: float, q: float, kind: int):
    (xs,) = _rows(np.shape(x), (x, ()))
    out = np.empty(len(xs))
    _factor_rows(xs, float(p), float(q), kind, out)
    return _shaped(out, np.shape(x))


def ground_effect_factor(height, rotor_radius: float) -> np.ndarray:
    """Cheeseman-Bennett thrust ratio ``1 / (1 - (r / 4h)^2)`` for height ``h`` [m] above the
    ground and rotor radius ``r`` [m]; ``h`` is clipped to ``r / 2`` (ratio at most 4/3)."""
    return _factor(height, rotor_radius, 0.0, 0)


def battery_factor(voltage, v_ref: float, exponent: float) -> np.ndarray:
    """Thrust ratio ``(V / V_ref)^n`` at battery voltage ``V`` [V] (``n`` = 2 for a motor whose
    speed is proportional to its voltage, 0 for perfect voltage compensation)."""
    return _factor(voltage, v_ref, exponent, 1)


@jit
def _zoh_cumulative_rows(t, values, out):
    for j in range(1, t.shape[0]):
        for m in range(values.shape[1]):
            out[j, m] = zoh_next1(out[j - 1, m], values[j - 1, m], t[j - 1], t[j])


def zoh_cumulative(t_knots: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Cumulative integrals of a zero-order-hold signal at its knots (see :func:`zoh_mean`)."""
    t = np.ascontiguousarray(t_knots, dtype=float)
    v = np.ascontiguousarray(values, dtype=float)
    out = np.zeros(v.shape)
    if len(t):
        _zoh_cumulative_rows(t, v.reshape(len(t), -1), out.reshape(len(t), -1))
    return out


@jit
def _zoh_mean_rows(buf, cap, n, a, b, out):
    for i in range(a.shape[0]):
        for m in range(n):
            hi = zoh_integral(buf, 0, 0, cap, n, 0, cap, b[i], m)
            lo = zoh_integral(buf, 0, 0, cap, n, 0, cap, a[i], m)
            out[i, m] = (hi - lo) / (b[i] - a[i])


def zoh_mean(t_knots: np.ndarray, values: np.ndarray, cumulative: np.ndarray,
             a, b) -> np.ndarray:
    """Mean over ``[a, b]`` of the zero-order-hold signal ``values[j]`` on
    ``[t_knots[j], t_knots[j+1])`` (constant before the first and after the last knot).

    ``cumulative[j]`` is the integral from ``t_knots[0]`` to ``t_knots[j]``. A pure delay
    ``d`` over a step ``[t, t + dt]`` is ``zoh_mean(..., t - d, t + dt - d)``.
    """
    t = np.asarray(t_knots, dtype=float)
    v = np.asarray(values, dtype=float).reshape(len(t), -1)
    c = np.asarray(cumulative, dtype=float).reshape(len(t), -1)
    buf = np.concatenate((t, c.ravel(), v.ravel()))[None]
    batch = _batch((a, ()), (b, ()))
    ra, rb = _rows(batch, (a, ()), (b, ()))
    out = np.empty((len(ra), v.shape[1]))
    _zoh_mean_rows(buf, len(t), v.shape[1], ra, rb, out)
    return out.reshape(batch + np.shape(values)[1:])


def lag_gain(dt, tau: float) -> np.ndarray:
    """First-order-lag update gain ``1 - exp(-dt / tau)`` for a held input."""
    return _factor(dt, tau, 0.0, 2)


@jit
def _lag_rows(f, dt, tau, y0, out):
    for m in range(f.shape[1]):
        y = y0[m]
        for k in range(f.shape[0]):
            y = lag_step1(y, f[k, m], lag_gain1(dt[k], tau))
            out[k, m] = y


def lag_series(f: np.ndarray, dt: np.ndarray, tau: float, y0=None) -> np.ndarray:
    """Rotor thrust after a first-order lag ``tau f'' = f - f'`` with time constant ``tau``
    [s], exact for commands ``f`` (N, n) held for ``dt`` (N,) [s]:
    ``y_k = g_k f_k + (1 - g_k) y_{k-1}``, ``g_k = 1 - exp(-dt_k / tau)``.

    ``y0`` is the thrust before the first step (default: the first command, as the plant
    starts). One call over a recording and one call per plant step are the same kernel
    (:func:`~quadfault.effects.kernels.lag_step1`)."""
    f = np.ascontiguousarray(np.atleast_2d(np.asarray(f, dtype=float)))
    dt = np.ascontiguousarray(np.broadcast_to(np.asarray(dt, dtype=float).ravel(), (len(f),)))
    start = f[0] if y0 is None else np.asarray(y0, dtype=float)
    out = np.empty_like(f)
    _lag_rows(f, dt, float(tau), np.ascontiguousarray(np.broadcast_to(start, f.shape[1:])), out)
    return out


@jit
def _rate_rows(f_end, dt, out):
    for k in range(1, f_end.shape[0]):
        for m in range(f_end.shape[1]):
            out[k, m] = thrust_rate1(f_end[k, m], f_end[k - 1, m], dt[k])


def thrust_rate(f_end: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Mean rate of change [N/s] of a thrust held over each interval: the step from the
    previous interval's final thrust to this one's, ``(f_end_k - f_end_{k-1}) / dt_k`` (0 for
    the first), so block means of the rate telescope exactly."""
    f = np.ascontiguousarray(f_end, dtype=float)
    out = np.zeros_like(f)
    if len(f) > 1:
        d = np.ascontiguousarray(np.broadcast_to(np.asarray(dt, dtype=float), (len(f),)))
        _rate_rows(f.reshape(len(f), -1), d, out.reshape(len(f), -1))
    return out


# ----------------------------------------------------------------------------------------
# wrench stage: external force (world) [N] and moment (body) [N m]
@jit
def _wrench_rows(kind, R, v, T, p, q, out_F, out_M):
    for i in range(R.shape[0]):
        if kind == 0:
            store3(out_F[i], drag_force3(mat3(R[i]), vec3(v[i]), vec3(p[i])))
        elif kind == 1:
            F, M = blade_flapping3(mat3(R[i]), vec3(v[i]), T[i], p[i, 0], q[i, 0])
            store3(out_F[i], F)
            store3(out_M[i], M)
        elif kind == 2:
            store3(out_M[i], com_offset_moment3(T[i], p[i, 0], p[i, 1]))
        elif kind == 3:
            store3(out_M[i], rate_damping3(vec3(v[i]), vec3(p[i]), vec3(q[i])))
        else:
            s = 0.0
            for m in range(p.shape[1]):
                s += v[i, m] * q[i, m]
            store3(out_M[i], (0.0, 0.0, rotor_inertia_moment1(s, T[i])))


def _wrench(kind, batch, R, v, T, p, q):
    """:func:`_wrench_rows` over ``batch``: ``(R, width), ...`` pairs; returns (F, M)."""
    rR, rv, rT, rp, rq = _rows(batch, R, v, T, p, q)
    n = int(np.prod(batch))
    F, M = np.zeros((n, 3)), np.zeros((n, 3))
    _wrench_rows(kind, rR, rv, rT, rp, rq, F, M)
    return F.reshape(batch + (3,)), M.reshape(batch + (3,))


_NO_T, _NO_P = (0.0, ()), (0.0, (1,))  # unused thrust / parameter rows


def drag_force(R: np.ndarray, v_air: np.ndarray, k) -> np.ndarray:
    """``-R diag(k) R^T v_air`` [N] for air-relative velocity ``v_air`` (world) [m/s]."""
    k = np.asarray(k, dtype=float)
    k = np.broadcast_to(k, k.shape[:-1] + (3,)) if k.ndim else np.full(3, float(k))
    batch = _batch((R, (3, 3)), (v_air, (3,)), (k, (3,)))
    return _wrench(0, batch, (R, (3, 3)), (v_air, (3,)), _NO_T, (k, (3,)), _NO_P)[0]


def com_offset_moment(thrust, offset) -> np.ndarray:
    """Extra body moment [N m] of collective thrust ``thrust`` [N] when the CoM sits at
    ``offset`` = (r_x, r_y) [m] from the rotor-plane centre: ``r x (0, 0, T)``."""
    batch = _batch((thrust, ()), (offset, (2,)))
    return _wrench(2, batch, (np.eye(3), (3, 3)), ((0.0,) * 3, (3,)), (thrust, ()),
                   (offset, (2,)), _NO_P)[1]


def blade_flapping_wrench(R: np.ndarray, v_air: np.ndarray, thrust, k_force: float,
                          k_moment: float) -> tuple[np.ndarray, np.ndarray]:
    """Rotor drag and blade flapping of rotors moving through the air in their plane.

    With the air-relative body velocity ``v_b = R^T v_air`` [m/s] and collective thrust ``T``
    [N]: the in-plane force ``F_b = -k_force T (v_bx, v_by, 0)`` [N] (``k_force`` [s/m]) and
    the moment ``M_b = k_moment T e3 x v_b = k_moment T (-v_by, v_bx, 0)`` [N m] (``k_moment``
    [s]; > 0: nose up when flying forward, as the flapped discs tilt back above the CoM).
    Returns ``(F_world, M_body)``.
    """
    batch = _batch((R, (3, 3)), (v_air, (3,)), (thrust, ()))
    return _wrench(1, batch, (R, (3, 3)), (v_air, (3,)), (thrust, ()),
                   (float(k_force), (1,)), (float(k_moment), (1,)))


def rotor_inertia_moment(rate: np.ndarray, yaw_signs: np.ndarray, kappa: float) -> np.ndarray:
    """Body moment [N m] of the rotors' reaction when they spin up or down:
    ``M_z = kappa sum_i s_i df_i/dt`` (``rate`` = df/dt [N/s], ``s_i`` = the sign of rotor
    i's drag torque on the body, ``kappa`` [m s] = J_r omega / (2 f) at the operating point,
    J_r the rotor inertia)."""
    rate = np.asarray(rate, dtype=float)
    n = (rate.shape[-1],)
    batch = _batch((rate, n), (yaw_signs, n))
    return _wrench(4, batch, (np.eye(3), (3, 3)), (rate, n), (float(kappa), ()),
                   (np.zeros(n), n), (yaw_signs, n))[1]


def rate_damping_moment(w: np.ndarray, linear, quadratic) -> np.ndarray:
    """Aerodynamic damping of the body rate ``w`` [rad/s]:
    ``M = -(D1 + D2 |w|) w`` per body axis [N m] (``linear`` D1 [N m s/rad], ``quadratic``
    D2 [N m s^2/rad^2])."""
    batch = _batch((w, (3,)), (linear, (3,)), (quadratic, (3,)))
    return _wrench(3, batch, (np.eye(3), (3, 3)), (w, (3,)), _NO_T, (linear, (3,)),
                   (quadratic, (3,)))[1]


# ----------------------------------------------------------------------------------------
# vehicle stage: the rigid body the plant flies (set once per flight)
def scaled_inertia(inertia: np.ndarray, scale) -> np.ndarray:
    """``D J D`` with ``D = diag(sqrt(scale))``: diagonal entries scaled by ``scale``."""
    d = np.sqrt(np.asarray(scale, dtype=float))
    return inertia * d[:, None] * d[None, :]


def vehicle_with(vehicle, mass_scale: float = 1.0, inertia_scale=(1.0, 1.0, 1.0)):
    """The vehicle with mass ``mass_scale m`` and inertia ``D J D`` (:func:`scaled_inertia`);
    the rotors (allocation, per-rotor thrust limit) are unchanged."""
    return vehicle.replace(mass=vehicle.mass * float(mass_scale),
                           inertia=scaled_inertia(vehicle.inertia, inertia_scale),
                           max_thrust=vehicle.rotor_max_thrust)
