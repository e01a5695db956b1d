"""The physics of each effect for one vehicle at one instant: the kernels.

Plain, allocation-free Python under :func:`quadfault.jit.jit` (vectors are 3-tuples, ``R`` a
row-major 9-tuple, as in :mod:`quadfault.dynamics`). They are the one implementation of each
effect: the closed loop runs them step by step through the effect chain
(:mod:`quadfault.effects.chain`), and the array functions of :mod:`quadfault.effects.physics`
that the diagnosis calls over whole recordings are compiled loops over them. Frames: world
NED, body FRD. docs/effects.md gives every equation.
"""

from __future__ import annotations

import math

from quadfault.jit import jit


# ----------------------------------------------------------------------------------------
# thrust stage: the thrust [N] a rotor produces
@jit
def curve_thrust1(a, b, c, u):
    """Thrust [N] of command ``u`` through the curve ``f = a + b u + c u^2``."""
    return a + u * (b + c * u)


@jit
def curve_command1(a, b, c, f):
    """The command ``u >= 0`` the curve ``(a, b, c)`` maps to thrust ``f`` [N] (the larger
    root; 0 below the curve's value at 0)."""
    f = f - a
    if c == 0.0:
        return max(f / b, 0.0)
    disc = max(b * b + 4.0 * c * f, 0.0)
    return max((math.sqrt(disc) - b) / (2.0 * c), 0.0)


@jit
def recurve1(f, nominal, curve):
    """Thrust [N] through ``curve`` of the command the ``nominal`` curve maps to ``f`` [N]
    (never negative); both curves are 3-tuples ``(a, b, c)``."""
    u = curve_command1(nominal[0], nominal[1], nominal[2], f)
    return max(curve_thrust1(curve[0], curve[1], curve[2], u), 0.0)


@jit
def battery_voltage1(t, v_start, v_end, duration):
    """Battery voltage [V] at ``t`` [s] falling linearly from ``v_start`` to ``v_end`` over
    ``duration`` [s] (then constant)."""
    frac = min(max(t / duration, 0.0), 1.0)
    return v_start + (v_end - v_start) * frac


@jit
def battery_factor1(voltage, v_ref, exponent):
    """Thrust ratio ``(V / V_ref)^n`` at battery voltage ``V`` [V]."""
    return (max(voltage, 1e-6) / v_ref) ** exponent


@jit
def ground_effect_factor1(height, rotor_radius):
    """Cheeseman-Bennett ratio ``1 / (1 - (r / 4h)^2)``, ``h`` [m] clipped to ``r / 2``."""
    h = max(height, max(0.5 * rotor_radius, 1e-6))
    q = rotor_radius / (4.0 * h)
    return 1.0 / (1.0 - q * q)


@jit
def lag_gain1(dt, tau):
    """First-order-lag update gain ``1 - exp(-dt / tau)`` for an input held over ``dt``."""
    return -math.expm1(-dt / max(tau, 1e-9))


@jit
def lag_step1(y, f, g):
    """The lagged thrust after a step of held input ``f`` from ``y`` with gain ``g``
    (:func:`lag_gain1`): exact solution of ``tau y' = f - y``."""
    return g * f + (1.0 - g) * y


@jit
def thrust_rate1(f_end, f_prev, dt):
    """Mean rate of change [N/s] of a thrust that went from ``f_prev`` to ``f_end`` over
    ``dt`` [s]."""
    return (f_end - f_prev) / dt


@jit
def zoh_next1(c, f, t_prev, t):
    """Integral up to knot ``t`` of a zero-order-hold signal: ``c`` up to the previous knot
    ``t_prev`` plus its value ``f`` held since."""
    return c + f * (t - t_prev)


@jit
def zoh_integral(buf, row, base, cap, n, head, count, x, col):
    """Integral up to ``x`` of column ``col`` of a zero-order-hold signal stored as knots in
    row ``row`` of ``buf`` from column ``base``: times ``[0, cap)``, integrals up to each
    knot ``[cap, cap + cap n)`` and values ``[cap + cap n, cap + 2 cap n)`` (``n`` columns
    per knot), knot ``j`` (0 the oldest of ``count``) in slot ``(head + j) % cap``. The
    signal holds its first value before the first knot and its last after the last."""
    lo, hi = 0, count  # the number of knots at or before x, by bisection
    while lo < hi:
        mid = (lo + hi) // 2
        if buf[row, base + (head + mid) % cap] <= x:
            lo = mid + 1
        else:
            hi = mid
    s = (head + max(lo - 1, 0)) % cap
    k = base + cap + s * n + col
    return buf[row, k] + buf[row, k + cap * n] * (x - buf[row, base + s])


@jit
def gust_step3(g, a, c, gen):
    """Ornstein-Uhlenbeck gust velocity [m/s] after one step: ``a g + c z`` with ``a =
    exp(-dt / tau)``, ``c = sigma sqrt(1 - a^2)`` and three standard normals from ``gen``."""
    z0 = gen.standard_normal()
    z1 = gen.standard_normal()
    z2 = gen.standard_normal()
    return (a * g[0] + c * z0, a * g[1] + c * z1, a * g[2] + c * z2)


# ----------------------------------------------------------------------------------------
# wrench stage: external force (world) [N] and moment (body) [N m]
@jit
def body_velocity3(R, v):
    """``R^T v``: a world vector in body axes."""
    return (R[0] * v[0] + R[3] * v[1] + R[6] * v[2],
            R[1] * v[0] + R[4] * v[1] + R[7] * v[2],
            R[2] * v[0] + R[5] * v[1] + R[8] * v[2])


@jit
def world_vector3(R, b):
    """``R b``: a body vector in world axes."""
    return (R[0] * b[0] + R[1] * b[1] + R[2] * b[2],
            R[3] * b[0] + R[4] * b[1] + R[5] * b[2],
            R[6] * b[0] + R[7] * b[1] + R[8] * b[2])


@jit
def drag_force3(R, v_air, k):
    """``-R diag(k) R^T v_air`` [N] for air-relative velocity ``v_air`` (world) [m/s] and
    drag ``k`` [N s/m] per body axis."""
    vb = body_velocity3(R, v_air)
    F = world_vector3(R, (vb[0] * k[0], vb[1] * k[1], vb[2] * k[2]))
    return (-F[0], -F[1], -F[2])


@jit
def com_offset_moment3(thrust, rx, ry):
    """Body moment [N m] of collective thrust ``thrust`` [N] with the CoM at ``(rx, ry)``
    [m] from the rotor-plane centre: ``r x (0, 0, T)``."""
    return (ry * thrust, -rx * thrust, 0.0)


@jit
def blade_flapping3(R, v_air, thrust, k_force, k_moment):
    """Rotor drag and blade flapping: with ``v_b = R^T v_air``, the force
    ``F_b = -k_force T (v_bx, v_by, 0)`` (returned in world axes) [N] and the moment
    ``M_b = k_moment T (-v_by, v_bx, 0)`` [N m]."""
    vb = body_velocity3(R, v_air)
    kf = k_force * thrust
    F = world_vector3(R, (kf * vb[0], kf * vb[1], kf * 0.0))
    km = k_moment * thrust
    return (-F[0], -F[1], -F[2]), (km * -vb[1], km * vb[0], km * 0.0)


@jit
def rate_damping3(w, linear, quadratic):
    """``M = -(D1 + D2 |w|) w`` per body axis [N m] for body rate ``w`` [rad/s]."""
    return (-(linear[0] + quadratic[0] * abs(w[0])) * w[0],
            -(linear[1] + quadratic[1] * abs(w[1])) * w[1],
            -(linear[2] + quadratic[2] * abs(w[2])) * w[2])


@jit
def rotor_inertia_moment1(yaw_rate_sum, kappa):
    """Yaw moment [N m] ``kappa sum_i s_i df_i/dt`` from the signed sum of rotor thrust rates
    ``sum_i s_i df_i/dt`` [N/s]."""
    return kappa * yaw_rate_sum
