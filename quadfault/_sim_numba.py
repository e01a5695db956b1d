"""Compiled (numba) fast path of :func:`quadfault.simulator.simulate`.

The same computation as the pure-numpy loop, compiled with ``numba.njit(cache=True)`` for the
common case: the :class:`~quadfault.controller.GeometricController` (any
:class:`~quadfault.controller.ControllerConfig`), no unmodelled effects, the ``rk4`` or
``reference`` integrator, sensor noise, control decimation, motor saturation and thrust noise.
Everything that is a function of time only (reference trajectory, feed-forward rates,
efficiency schedule) and every random number is prepared in numpy before the loop and passed
in as arrays.

Every ``@njit`` helper below mirrors one pure function one to one and says which; the
equations are not a second model but a transcription, guarded by
``tests/test_simulator_fast.py`` (compiled == pure to <= 1e-9 over a 10 s flight).

Random numbers: ``Generator.standard_normal((n, m))`` yields exactly the stream of ``n * m``
single draws taken in row order, so blocks of rows drawn before each chunk of steps, with the
columns laid out in the order the pure loop draws them each step (sensor p, v, [attitude],
gyro; the motors; the accelerometer), reproduce the pure path's noise bit for bit (see
:func:`noise_layout`).

Without numba this module still imports (``AVAILABLE`` is False) and the helpers run as plain
Python, which is how the tests check them one by one against the pure functions.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from quadfault.errors import ConfigError

try:  # the optional ``fast`` extra
    from numba import njit

    AVAILABLE = True
except ImportError:  # pragma: no cover - exercised only without numba
    AVAILABLE = False

    def njit(*args, **kwargs):
        """Stand-in decorator: the functions stay plain Python."""
        if len(args) == 1 and callable(args[0]) and not kwargs:
            return args[0]
        return lambda f: f


# --- rotation.py ---------------------------------------------------------------------------
@njit(cache=True)
def cross(a, b):
    """Mirrors :func:`quadfault.rotation.cross` (one 3-vector)."""
    out = np.empty(3)
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
    return out


@njit(cache=True)
def hat(w):
    """Mirrors :func:`quadfault.rotation.hat` (paper eq. 5)."""
    out = np.zeros((3, 3))
    out[0, 1] = -w[2]
    out[0, 2] = w[1]
    out[1, 0] = w[2]
    out[1, 2] = -w[0]
    out[2, 0] = -w[1]
    out[2, 1] = w[0]
    return out


@njit(cache=True)
def vee(m):
    """Mirrors :func:`quadfault.rotation.vee`."""
    out = np.empty(3)
    out[0] = 0.5 * (m[2, 1] - m[1, 2])
    out[1] = 0.5 * (m[0, 2] - m[2, 0])
    out[2] = 0.5 * (m[1, 0] - m[0, 1])
    return out


@njit(cache=True)
def matmul(A, B):
    """``A @ B`` for 3x3 matrices."""
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            out[i, j] = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j]
    return out


@njit(cache=True)
def matvec(A, x):
    """``A @ x`` for a matrix with any number of rows and a vector."""
    out = np.zeros(A.shape[0])
    for i in range(A.shape[0]):
        s = 0.0
        for j in range(A.shape[1]):
            s += A[i, j] * x[j]
        out[i] = s
    return out


@njit(cache=True)
def put(dst, src):
    """``dst[...] = src`` element by element (1-D or 2-D). Array-valued slice assignment
    would compile numba's shape-error formatting, which costs seconds of JIT time."""
    if dst.ndim == 1:
        for i in range(dst.shape[0]):
            dst[i] = src[i]
    else:
        for i in range(dst.shape[0]):
            for j in range(dst.shape[1]):
                dst[i, j] = src[i, j]


@njit(cache=True)
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def expm_so3(phi):
    """Mirrors :func:`quadfault.rotation.expm_so3` (Rodrigues, Taylor series below 1e-4 rad)."""
    th2 = dot(phi, phi)
    if th2 < 1e-8:
        a = 1.0 - th2 / 6.0 + th2 * th2 / 120.0
        b = 0.5 - th2 / 24.0 + th2 * th2 / 720.0
    else:
        th = math.sqrt(th2)
        a = math.sin(th) / th
        b = (1.0 - math.cos(th)) / (th * th)
    H = hat(phi)
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            out[i, j] = b * (phi[i] * phi[j]) + a * H[i, j]
    d = 1.0 - b * th2
    out[0, 0] += d
    out[1, 1] += d
    out[2, 2] += d
    return out


@njit(cache=True)
def dcm_orthonormalize_reference(R):
    """Mirrors :func:`quadfault.rotation.dcm_orthonormalize_reference`."""
    x, y = R[0].copy(), R[1].copy()
    err = dot(x, y)
    xo = x - 0.5 * err * y
    yo = y - 0.5 * err * x
    zo = cross(xo, yo)
    out = np.empty((3, 3))
    put(out[0], 0.5 * (3 - dot(xo, xo)) * xo)
    put(out[1], 0.5 * (3 - dot(yo, yo)) * yo)
    put(out[2], 0.5 * (3 - dot(zo, zo)) * zo)
    return out


# --- dynamics.py ---------------------------------------------------------------------------
class Body(NamedTuple):
    """Rigid-body parameters of a :class:`~quadfault.vehicle.Vehicle` as plain arrays."""

    mass: float  # [kg]
    gravity: float  # [m/s^2]
    inertia: np.ndarray  # (3, 3) [kg m^2]
    inertia_inverse: np.ndarray  # (3, 3)
    allocation: np.ndarray  # (4, n): rotor thrusts -> [T; Mx; My; Mz]
    allocation_inverse: np.ndarray  # (n, 4)
    max_thrust: float  # per-rotor f_max [N] (inf = no upper limit)


def body_of(vehicle) -> Body:
    return Body(float(vehicle.mass), float(vehicle.gravity),
                np.ascontiguousarray(vehicle.inertia, dtype=float),
                np.ascontiguousarray(vehicle.inertia_inverse, dtype=float),
                np.ascontiguousarray(vehicle.allocation, dtype=float),
                np.ascontiguousarray(vehicle.allocation_inverse, dtype=float),
                float(vehicle.rotor_max_thrust))


@njit(cache=True)
def translational_acceleration(R, thrust, body):
    """Mirrors :func:`quadfault.dynamics.translational_acceleration` (eq. 2, no F_ext)."""
    acc = np.empty(3)
    for i in range(3):
        acc[i] = -(thrust / body.mass) * R[i, 2]
    acc[2] += body.gravity
    return acc


@njit(cache=True)
def angular_acceleration(w, moment, body):
    """Mirrors :func:`quadfault.dynamics.angular_acceleration` (eq. 4, no M_ext)."""
    m = moment - cross(w, matvec(body.inertia, w))
    return matvec(body.inertia_inverse, m)


@njit(cache=True)
def specific_force_body(R, acceleration_world, gravity):
    """Mirrors :func:`quadfault.dynamics.specific_force_body`: ``R^T (a - g e3)``."""
    f = acceleration_world.copy()
    f[2] -= gravity
    out = np.empty(3)
    for i in range(3):
        out[i] = R[0, i] * f[0] + R[1, i] * f[1] + R[2, i] * f[2]
    return out


@njit(cache=True)
def dexpinv(theta, w):
    """Mirrors :func:`quadfault.dynamics._dexpinv`."""
    tw = cross(theta, w)
    return w + 0.5 * tw + cross(theta, tw) / 12.0


@njit(cache=True)
def step_rk4(p0, v0, R0, w0, thrust, moment, body, dt):
    """Mirrors :func:`quadfault.dynamics.step_rk4` (RKMK4, no external wrench).

    ``_derivatives`` is inlined: (p', v', Omega') = (v, eq. 2, eq. 4).
    """
    h = 0.5 * dt
    k1p, k1v, k1w = v0, translational_acceleration(R0, thrust, body), \
        angular_acceleration(w0, moment, body)
    th1 = w0
    p2, v2, R2, w2 = p0 + h * k1p, v0 + h * k1v, matmul(R0, expm_so3(h * th1)), w0 + h * k1w
    k2p, k2v, k2w = v2, translational_acceleration(R2, thrust, body), \
        angular_acceleration(w2, moment, body)
    th2 = dexpinv(h * th1, w2)
    p3, v3, R3, w3 = p0 + h * k2p, v0 + h * k2v, matmul(R0, expm_so3(h * th2)), w0 + h * k2w
    k3p, k3v, k3w = v3, translational_acceleration(R3, thrust, body), \
        angular_acceleration(w3, moment, body)
    th3 = dexpinv(h * th2, w3)
    p4, v4, R4, w4 = p0 + dt * k3p, v0 + dt * k3v, matmul(R0, expm_so3(dt * th3)), w0 + dt * k3w
    k4p, k4v, k4w = v4, translational_acceleration(R4, thrust, body), \
        angular_acceleration(w4, moment, body)
    th4 = dexpinv(dt * th3, w4)
    c = dt / 6.0
    return (p0 + c * (k1p + 2 * k2p + 2 * k3p + k4p),
            v0 + c * (k1v + 2 * k2v + 2 * k3v + k4v),
            matmul(R0, expm_so3(c * (th1 + 2 * th2 + 2 * th3 + th4))),
            w0 + c * (k1w + 2 * k2w + 2 * k3w + k4w))


@njit(cache=True)
def reference_euler_step(p0, v0, R0, w0, lag, body, dt):
    """Mirrors :meth:`quadfault.dynamics.ReferenceEuler.step`.

    ``lag`` holds the reference's stored ``(a, w_dot, force_world, moment)`` as rows of a
    (4, 3) array and is updated in place, like the object's attributes.
    """
    w = w0 + lag[1] * dt
    v = v0 + lag[0] * dt
    A = hat(w * dt)
    A[0, 0] += 1.0
    A[1, 1] += 1.0
    A[2, 2] += 1.0
    R = dcm_orthonormalize_reference(matmul(R0, A))
    p = p0 + v * dt
    for i in range(3):
        lag[0, i] = -lag[2, i] / body.mass
    lag[0, 2] += body.gravity
    put(lag[1], matvec(body.inertia_inverse, lag[3] - cross(w, matvec(body.inertia, w))))
    return p, v, R, w


@njit(cache=True)
def reference_euler_apply(lag, thrust, moment, R):
    """Mirrors :meth:`quadfault.dynamics.ReferenceEuler.apply` (stores T R e3 and M)."""
    for i in range(3):
        lag[2, i] = thrust * R[i, 2]
        lag[3, i] = moment[i]


# --- motors.py -----------------------------------------------------------------------------
@njit(cache=True)
def motor_apply(f_cmd, eta, f_max, saturate, thrust_noise, eps):
    """Mirrors :meth:`quadfault.motors.MotorModel.apply` (eqs. 11, 13), with the standard
    normal draws ``eps`` passed in (ignored when ``thrust_noise`` is 0)."""
    n = f_cmd.shape[0]
    f = np.empty(n)
    for i in range(n):
        fi = max(f_cmd[i], 0.0)
        if saturate:
            fi = min(fi, f_max)
        f[i] = fi * eta[i]
        if thrust_noise > 0:
            f[i] = f[i] * math.exp(thrust_noise * eps[i])
    return f


# --- controller.py -------------------------------------------------------------------------
class Gains(NamedTuple):
    """:class:`~quadfault.controller.GeometricController` gains and options as arrays."""

    kx: np.ndarray
    kv: np.ndarray
    kR: np.ndarray
    kW: np.ndarray
    acceleration_feedforward: bool
    angular_feedforward: bool
    normalize_b2d: bool


def gains_of(controller) -> Gains:
    cfg = controller.config
    return Gains(np.asarray(controller.kx, float), np.asarray(controller.kv, float),
                 np.asarray(controller.kR, float), np.asarray(controller.kW, float),
                 bool(cfg.acceleration_feedforward), bool(cfg.angular_feedforward),
                 bool(cfg.normalize_b2d))


@njit(cache=True)
def desired_attitude(f_n, b1d, normalize_b2d):
    """Mirrors :meth:`GeometricController._desired_attitude`: columns (b1, b2d, b3d)."""
    b3d = f_n / math.sqrt(dot(f_n, f_n))
    b2d = cross(b3d, b1d)
    if normalize_b2d:
        b2d = b2d / math.sqrt(dot(b2d, b2d))
    b1 = cross(b2d, b3d)
    Rd = np.empty((3, 3))
    for i in range(3):
        Rd[i, 0], Rd[i, 1], Rd[i, 2] = b1[i], b2d[i], b3d[i]
    return Rd


@njit(cache=True)
def motor_commands(p, v, R, w, pos_d, vel_d, acc_d, b1d, w_d, w_dot_d, gains, body):
    """Mirrors :meth:`GeometricController.compute` (eqs. 9, 10) followed by
    :meth:`GeometricController.motor_commands` (nominal allocation inverse).

    ``body`` is the *nominal* vehicle; ``w_d, w_dot_d`` are used only with angular
    feed-forward.
    """
    ex = p - pos_d
    ev = v - vel_d
    f_n = gains.kx * ex + gains.kv * ev
    f_n[2] += body.mass * body.gravity
    if gains.acceleration_feedforward:
        f_n = f_n - body.mass * acc_d
    Rd = desired_attitude(f_n, b1d, gains.normalize_b2d)
    thrust = f_n[0] * R[0, 2] + f_n[1] * R[1, 2] + f_n[2] * R[2, 2]
    RT = R.T.copy()
    eR = 0.5 * vee(matmul(Rd.T.copy(), R) - matmul(RT, Rd))
    J = body.inertia
    Jw = matvec(J, w)
    if gains.angular_feedforward:
        RtRd = matmul(RT, Rd)
        w_d_body = matvec(RtRd, w_d)
        eW = w - w_d_body
        ff = cross(w, Jw) - matvec(J, cross(w, w_d_body) - matvec(RtRd, w_dot_d))
    else:
        eW = w
        ff = cross(w, Jw)
    M = -gains.kR * eR - gains.kW * eW + ff
    wrench = np.empty(4)
    wrench[0], wrench[1], wrench[2], wrench[3] = thrust, M[0], M[1], M[2]
    return matvec(body.allocation_inverse, wrench)


# --- simulator.py --------------------------------------------------------------------------
@njit(cache=True)
def measure(p, v, R, w, noise_row, layout, sensor_std):
    """Mirrors :meth:`quadfault.simulator.SensorNoise.measure` (state part).

    ``sensor_std`` = (position, velocity, attitude, gyro); ``layout`` = column offsets of
    the draws in ``noise_row`` (see :func:`noise_layout`; -1 = not drawn).
    """
    if layout[0] < 0:
        return p, v, R, w
    i_p, i_v, i_att, i_w = layout[0], layout[1], layout[2], layout[3]
    pm = p + sensor_std[0] * noise_row[i_p:i_p + 3]
    vm = v + sensor_std[1] * noise_row[i_v:i_v + 3]
    Rm = R
    if i_att >= 0:
        Rm = matmul(R, expm_so3(sensor_std[2] * noise_row[i_att:i_att + 3]))
    wm = w + sensor_std[3] * noise_row[i_w:i_w + 3]
    return pm, vm, Rm, wm


@njit(cache=True)
def run_steps(k0, k1, reference, decimation, dt, carry, lag, f_cmd, sf_meas,
              refs, eta, noise, layout, sensor_std, accel_std, record_accel,
              gains, nominal, plant, saturate, thrust_noise, out):
    """Steps ``k0 .. k1-1`` of the loop in :func:`quadfault.simulator.simulate`.

    ``carry`` (rows p, v, w, then R in rows 3..5 of a (6, 3) array) the plant state, ``lag``
    the reference integrator's memory, ``f_cmd`` the held command and ``sf_meas`` the last
    accelerometer reading are updated in place, so the loop runs in chunks; ``noise`` holds
    the chunk's draws (row 0 = step ``k0``). Returns the first step whose new state is not
    finite, or -1.
    """
    out_p, out_v, out_R, out_w, out_f, out_eta, out_acc = out
    pos_d, vel_d, acc_d, b1d, w_d, w_dot_d = refs
    p, v, w = carry[0].copy(), carry[1].copy(), carry[2].copy()
    R = carry[3:6].copy()
    diverged = -1
    for k in range(k0, k1):
        row = noise[k - k0]
        if reference:
            p, v, R, w = reference_euler_step(p, v, R, w, lag, plant, dt)
        mp, mv, mR, mw = measure(p, v, R, w, row, layout, sensor_std)
        if k % decimation == 0:
            put(f_cmd, motor_commands(mp, mv, mR, mw, pos_d[k], vel_d[k], acc_d[k], b1d[k],
                                      w_d[k], w_dot_d[k], gains, nominal))
        # Plant.step: produced thrust, wrench, accelerometer truth, integration
        f = motor_apply(f_cmd, eta[k], plant.max_thrust, saturate, thrust_noise,
                        row[layout[4]:] if layout[4] >= 0 else row)
        wrench = matvec(plant.allocation, f)
        thrust, moment = wrench[0], wrench[1:].copy()
        acc = translational_acceleration(R, thrust, plant)
        sf = specific_force_body(R, acc, plant.gravity)
        if reference:
            reference_euler_apply(lag, thrust, moment, R)
        else:
            p, v, R, w = step_rk4(p, v, R, w, thrust, moment, plant, dt)
        if record_accel:
            put(sf_meas, sf)
            if accel_std != 0.0:
                put(sf_meas, sf + accel_std * row[layout[5]:layout[5] + 3])
        put(out_p[k], mp)
        put(out_v[k], mv)
        put(out_w[k], mw)
        put(out_R[k], mR)
        put(out_f[k], f_cmd)
        put(out_eta[k], eta[k])
        put(out_acc[k], sf_meas)
        if not (np.isfinite(p[0]) and np.isfinite(p[1]) and np.isfinite(p[2])):
            diverged = k
            break
    put(carry[0], p)
    put(carry[1], v)
    put(carry[2], w)
    put(carry[3:6], R)
    return diverged


# --- driver (plain Python) -------------------------------------------------------------------
def noise_layout(sensor_noise, n_rotors: int, thrust_noise: float, record_accel: bool):
    """Column offsets of one step's standard-normal draws, in the pure loop's order.

    Returns ``(layout, width)``: ``layout`` = offsets of (position, velocity, attitude, gyro,
    motors, accelerometer), -1 where the pure loop draws nothing.
    """
    layout = [-1] * 6
    col = 0
    if sensor_noise.any:  # SensorNoise.measure: p, v, [attitude], w
        layout[0], layout[1] = 0, 3
        col = 6
        if sensor_noise.attitude:
            layout[2] = col
            col += 3
        layout[3] = col
        col += 3
    if thrust_noise > 0:  # MotorModel.apply
        layout[4] = col
        col += n_rotors
    if record_accel and sensor_noise.accel:  # the accelerometer, after the plant step
        layout[5] = col
        col += 3
    return np.array(layout, dtype=np.int64), col


def run(plant, controller, config, rng, times, refs, feedforward, initial, bar=None,
        chunk: int = 5000):
    """Run the compiled loop; returns ``(out_p, out_v, out_R, out_w, out_f, out_eta, out_acc,
    diverged_step)`` exactly as the pure loop fills them (``diverged_step`` = -1 if none).

    ``refs`` is the trajectory at ``times`` (a FlatOutput of arrays), ``feedforward`` the
    pair (Omega_d, Omega_d') at ``times`` or None, ``initial`` the plant's initial state.
    The loop runs ``chunk`` steps at a time (noise drawn per chunk: the same stream, bounded
    memory; the progress bar moves per chunk).
    """
    n = len(times)
    vehicle = plant.vehicle
    n_rot = vehicle.n_rotors
    sn = config.sensor_noise
    layout, width = noise_layout(sn, n_rot, plant.motor.thrust_noise, config.record_accel)
    eta = np.asarray(plant.efficiency(times), dtype=float)
    if eta.shape != (n, n_rot):
        raise ConfigError(f"the efficiency schedule gave shape {eta.shape} for {n} times, "
                          f"expected ({n}, {n_rot}); use backend='numpy' for a scalar-only one")
    eta = np.ascontiguousarray(eta)
    if feedforward is None:
        w_d = np.zeros((n, 3))
        w_dot_d = w_d
    else:
        w_d, w_dot_d = (np.ascontiguousarray(a, float) for a in feedforward)
    ref_arrays = tuple(np.ascontiguousarray(a, float) for a in refs) + (w_d, w_dot_d)
    carry = np.empty((6, 3))
    carry[0], carry[1], carry[2], carry[3:6] = initial.p, initial.v, initial.w, initial.R
    lag = np.zeros((4, 3))
    f_cmd = np.zeros(n_rot)
    sf_meas = np.array([0.0, 0.0, -vehicle.gravity])
    out = (np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3, 3)), np.empty((n, 3)),
           np.empty((n, n_rot)), np.empty((n, n_rot)), np.empty((n, 3)))
    head = (config.integrator == "reference", config.control_decimation, float(config.dt),
            carry, lag, f_cmd, sf_meas, ref_arrays, eta)
    tail = (layout, np.array([sn.position, sn.velocity, sn.attitude, sn.gyro], float),
            float(sn.accel), bool(config.record_accel), gains_of(controller),
            body_of(controller.vehicle), body_of(vehicle), bool(plant.motor.saturate),
            float(plant.motor.thrust_noise), out)
    diverged = -1
    for k0 in range(0, n, chunk):
        k1 = min(n, k0 + chunk)
        noise = rng.standard_normal((k1 - k0, width)) if width else np.zeros((k1 - k0, 1))
        diverged = run_steps(k0, k1, *head, noise, *tail)
        if bar is not None:
            bar.update(k1 - k0)
        if diverged >= 0:
            break
    return out + (diverged,)
