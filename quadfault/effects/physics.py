"""The physics of the effects: pure functions, batched over leading axes.

The simulator's plant calls them one step at a time (through the effect classes of
:mod:`quadfault.effects`) and the mismatch diagnosis calls them over a whole recording
(:mod:`quadfault.diagnosis.library`): one implementation of each effect. Frames: world NED,
body FRD; rotor thrusts ``f`` [N] have the rotors on the last axis.
"""

from __future__ import annotations

import numpy as np

from quadfault.rotation import cross

E3 = np.array([0.0, 0.0, 1.0])


# ----------------------------------------------------------------------------------------
# thrust stage: produced rotor thrust from the commanded one
def curve_thrust(curve, u) -> np.ndarray:
    """Rotor thrust [N] of the command ``u`` through the curve ``f = a + b u + c u^2``."""
    a, b, c = (float(x) for x in curve)
    u = np.asarray(u, dtype=float)
    return a + u * (b + c * u)


def curve_command(curve, f) -> np.ndarray:
    """The command ``u >= 0`` that the curve ``(a, b, c)`` maps to thrust ``f`` [N] (the
    larger root; ``u = 0`` where ``f`` is below the curve's value at 0)."""
    a, b, c = (float(x) for x in curve)
    f = np.asarray(f, dtype=float) - a
    if c == 0.0:
        return np.maximum(f / b, 0.0)
    disc = np.maximum(b * b + 4.0 * c * f, 0.0)
    return np.maximum((np.sqrt(disc) - b) / (2.0 * c), 0.0)


def curve_from_changes(nominal, f_hover: float, changes) -> np.ndarray:
    """The curve ``(a, b, c)`` whose thrust differs from the ``nominal`` curve's by
    ``f_h (d0 + d1 (x - 1) + d2 (x - 1)^2)``, ``x = u / u_h`` the command relative to the
    hover command ``u_h`` (the nominal curve's command for ``f_h`` [N]); ``changes`` =
    ``(d0, d1, d2)`` [-]: hover thrust, slope and curvature changes relative to hover."""
    d0, d1, d2 = (float(v) for v in changes)
    uh = float(curve_command(nominal, f_hover))
    return np.asarray(nominal, dtype=float) + f_hover * np.array(
        [d0 - d1 + d2, (d1 - 2 * d2) / uh, d2 / uh ** 2])


def recurve(f, nominal, curve) -> np.ndarray:
    """Thrust [N] produced through ``curve`` by the command that the ``nominal`` curve maps to
    the commanded thrust ``f`` [N] (never negative)."""
    return np.maximum(curve_thrust(curve, curve_command(nominal, f)), 0.0)


def ground_effect_factor(height, rotor_radius: float) -> np.ndarray:
    """Cheeseman-Bennett thrust ratio ``1 / (1 - (r / 4h)^2)`` for height ``h`` [m] above the
    ground and rotor radius ``r`` [m]; ``h`` is clipped to ``r / 2`` (ratio at most 4/3)."""
    h = np.maximum(np.asarray(height, dtype=float), max(0.5 * rotor_radius, 1e-6))
    return 1.0 / (1.0 - (rotor_radius / (4.0 * h)) ** 2)


def battery_factor(voltage, v_ref: float, exponent: float) -> np.ndarray:
    """Thrust ratio ``(V / V_ref)^n`` at battery voltage ``V`` [V] (``n`` = 2 for a motor whose
    speed is proportional to its voltage, 0 for perfect voltage compensation)."""
    v = np.maximum(np.asarray(voltage, dtype=float), 1e-6)
    return (v / v_ref) ** exponent


def zoh_cumulative(t_knots: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Cumulative integrals of a zero-order-hold signal at its knots (see :func:`zoh_mean`)."""
    out = np.zeros_like(values, dtype=float)
    out[1:] = np.cumsum(values[:-1] * np.diff(t_knots)[:, None], axis=0)
    return out


def zoh_mean(t_knots: np.ndarray, values: np.ndarray, cumulative: np.ndarray,
             a, b) -> np.ndarray:
    """Mean over ``[a, b]`` of the zero-order-hold signal ``values[j]`` on
    ``[t_knots[j], t_knots[j+1])`` (constant before the first and after the last knot).

    ``cumulative[j]`` is the integral from ``t_knots[0]`` to ``t_knots[j]``. A pure delay
    ``d`` over a step ``[t, t + dt]`` is ``zoh_mean(..., t - d, t + dt - d)``.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)

    def integral(x):
        j = np.clip(np.searchsorted(t_knots, x, side="right") - 1, 0, len(t_knots) - 1)
        return cumulative[j] + values[j] * (x - t_knots[j])[..., None]

    return (integral(b) - integral(a)) / (b - a)[..., None]


def lag_gain(dt, tau: float) -> np.ndarray:
    """First-order-lag update gain ``1 - exp(-dt / tau)`` for a held input."""
    return -np.expm1(-np.asarray(dt, dtype=float) / max(tau, 1e-9))


def lag_series(f: np.ndarray, dt: np.ndarray, tau: float, y0=None) -> np.ndarray:
    """Rotor thrust after a first-order lag ``tau f'' = f - f'`` with time constant ``tau``
    [s], exact for commands ``f`` (N, n) held for ``dt`` (N,) [s]:
    ``y_k = y_{k-1} + g_k (f_k - y_{k-1})``, ``g_k = 1 - exp(-dt_k / tau)``.

    ``y0`` is the thrust before the first step (default: the first command, as the plant
    starts). The linear recurrence is solved by a parallel prefix scan (log2 N vectorised
    passes), so one call over a recording and one call per plant step are the same function.
    """
    f = np.atleast_2d(np.asarray(f, dtype=float))
    g = lag_gain(np.atleast_1d(dt), tau)
    a = np.repeat((1.0 - g)[:, None], f.shape[1], axis=1)
    b = g[:, None] * f
    start = f[0] if y0 is None else np.asarray(y0, dtype=float)
    b[0] += a[0] * start
    a[0] = 0.0
    s = 1
    while s < len(f):
        b[s:] += a[s:] * b[:-s]
        a[s:] *= a[:-s]
        s *= 2
    return b


def thrust_rate(f_end: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Mean rate of change [N/s] of a thrust held over each interval: the step from the
    previous interval's final thrust to this one's, ``(f_end_k - f_end_{k-1}) / dt_k`` (0 for
    the first), so block means of the rate telescope exactly."""
    f_end = np.asarray(f_end, dtype=float)
    out = np.zeros_like(f_end)
    out[1:] = (f_end[1:] - f_end[:-1]) / np.asarray(dt, dtype=float)[1:, None]
    return out


# ----------------------------------------------------------------------------------------
# wrench stage: external force (world) [N] and moment (body) [N m]
def drag_force(R: np.ndarray, v_air: np.ndarray, k) -> np.ndarray:
    """``-R diag(k) R^T v_air`` [N] for air-relative velocity ``v_air`` (world) [m/s]."""
    R = np.asarray(R, dtype=float)
    vb = (np.swapaxes(R, -1, -2) @ np.asarray(v_air, dtype=float)[..., None])[..., 0]
    return -(R @ (vb * np.asarray(k, dtype=float))[..., None])[..., 0]


def com_offset_moment(thrust, offset) -> np.ndarray:
    """Extra body moment [N m] of collective thrust ``thrust`` [N] when the CoM sits at
    ``offset`` = (r_x, r_y) [m] from the rotor-plane centre: ``r x (0, 0, T)``."""
    T = np.asarray(thrust, dtype=float)
    r = np.asarray(offset, dtype=float)
    return np.stack((r[1] * T, -r[0] * T, np.zeros_like(T)), axis=-1)


def blade_flapping_wrench(R: np.ndarray, v_air: np.ndarray, thrust, k_force: float,
                          k_moment: float) -> tuple[np.ndarray, np.ndarray]:
    """Rotor drag and blade flapping of rotors moving through the air in their plane.

    With the air-relative body velocity ``v_b = R^T v_air`` [m/s] and collective thrust ``T``
    [N]: the in-plane force ``F_b = -k_force T (v_bx, v_by, 0)`` [N] (``k_force`` [s/m]) and
    the moment ``M_b = k_moment T e3 x v_b = k_moment T (-v_by, v_bx, 0)`` [N m] (``k_moment``
    [s]; > 0: nose up when flying forward, as the flapped discs tilt back above the CoM).
    Returns ``(F_world, M_body)``.
    """
    R = np.asarray(R, dtype=float)
    T = np.asarray(thrust, dtype=float)[..., None]
    vb = (np.swapaxes(R, -1, -2) @ np.asarray(v_air, dtype=float)[..., None])[..., 0]
    inplane = vb * np.array([1.0, 1.0, 0.0])
    F = -(R @ (k_force * T * inplane)[..., None])[..., 0]
    M = k_moment * T * cross(E3, inplane)
    return F, M


def rotor_inertia_moment(rate: np.ndarray, yaw_signs: np.ndarray, kappa: float) -> np.ndarray:
    """Body moment [N m] of the rotors' reaction when they spin up or down:
    ``M_z = kappa sum_i s_i df_i/dt`` (``rate`` = df/dt [N/s], ``s_i`` = the sign of rotor
    i's drag torque on the body, ``kappa`` [m s] = J_r omega / (2 f) at the operating point,
    J_r the rotor inertia)."""
    Mz = kappa * (np.asarray(rate, dtype=float) @ np.asarray(yaw_signs, dtype=float))
    return np.stack((np.zeros_like(Mz), np.zeros_like(Mz), Mz), axis=-1)


def rate_damping_moment(w: np.ndarray, linear, quadratic) -> np.ndarray:
    """Aerodynamic damping of the body rate ``w`` [rad/s]:
    ``M = -(D1 + D2 |w|) w`` per body axis [N m] (``linear`` D1 [N m s/rad], ``quadratic``
    D2 [N m s^2/rad^2])."""
    w = np.asarray(w, dtype=float)
    return -(np.asarray(linear, dtype=float) + np.asarray(quadratic, dtype=float) * np.abs(w)) * w


# ----------------------------------------------------------------------------------------
# vehicle stage: the rigid body the plant flies
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
