"""Compiled (numba) twin of the core physics: one vehicle step, the single-vehicle simulator
loop and the batched kernel :func:`step_batch`.

The same computation as the pure-numpy code, compiled with ``numba.njit(cache=True)``:
the :class:`~quadfault.controller.GeometricController` (any
:class:`~quadfault.controller.ControllerConfig`), the motor model, the ``rk4`` (RKMK4) or
``reference`` integrator, sensor noise. Everything that is a function of time only
(reference trajectory, feed-forward rates, efficiency schedule) and every random number is
prepared in numpy and passed in as arrays.

Layout of the code (three modules, one model):

* :mod:`quadfault._numba_kernels` -- the **scalar kernels**: vectors are 3-tuples of float64
  and rotation matrices 9-tuples (row-major), so the hot path allocates nothing. Each mirrors
  one pure function and says which; it is a transcription, not a second model, guarded by
  ``tests/test_simulator_fast.py`` (compiled == pure to <= 1e-9 over a flight, helper by
  helper to ~1e-14) and ``tests/test_throughput_kernel.py``. ``plant_step`` there is **the**
  per-vehicle physics step (motor model, allocation, RKMK4).
* this module -- the loops: the single-vehicle :func:`run_steps` and the batched
  :func:`step_batch` both call ``plant_step`` and the controller kernel ``_controller``;
  :func:`controller_batch`, :func:`draw_normals` and the driver :func:`run`.
* :mod:`quadfault._numba_mirrors` -- array wrappers with the pure functions' names
  (``expm_so3``, ``step_rk4``, ``motor_commands``, ...), re-exported here, for the tests and
  other compiled modules (``estimators.ekf_numba``). They allocate; the loops don't.

Random numbers: ``Generator.standard_normal((n, m))`` yields exactly the stream of ``n * m``
single draws taken in row order, so blocks of rows drawn before each chunk of steps, with the
columns laid out in the order the pure loop draws them each step (sensor p, v, [attitude],
gyro; the motors; the accelerometer), reproduce the pure path's noise bit for bit (see
:func:`noise_layout`).

All kernels use ``error_model="numpy"`` (a division by zero gives inf / NaN as in numpy,
never an exception inside a parallel loop) and no ``fastmath`` (results stay equal to the
numpy path to rounding). Threads: numba's default, one per core (``NUMBA_NUM_THREADS`` or
``numba.set_num_threads`` to change it).

Without numba this module still imports (``AVAILABLE`` is False) and the helpers run as plain
Python, which is how the tests check them one by one against the pure functions.
"""

from __future__ import annotations

import numpy as np

from quadfault._numba_kernels import (  # noqa: F401  (re-exported: tests, vector env)
    AVAILABLE,
    Body,
    Gains,
    _axpy,
    _controller,
    _mat,
    _measure,
    _motor_wrench,
    _specific_force,
    _store_mat,
    _store_vec,
    _tacc,
    _vec,
    body_of,
    gains_of,
    njit,
    plant_step,
    prange,
)
from quadfault._numba_mirrors import (  # noqa: F401  (re-exported: tests, ekf_numba)
    _arr3,
    _arr33,
    angular_acceleration,
    cross,
    dcm_orthonormalize_reference,
    desired_attitude,
    dexpinv,
    dot,
    expm_so3,
    hat,
    matmul,
    matvec,
    measure,
    motor_apply,
    motor_commands,
    put,
    reference_euler_apply,
    reference_euler_step,
    specific_force_body,
    step_rk4,
    translational_acceleration,
    vee,
)
from quadfault.errors import ConfigError


# --- the batched kernel ----------------------------------------------------------------------
@njit
def _advance(i, p, v, R, w, f_cmd, eta, sigma, z, z_off, saturate, body, dt,
             control_every, refs, gains, nominal):
    """Vehicle ``i`` of :func:`step_batch`: ``eta.shape[1]`` substeps, in place."""
    pi, vi, Ri, wi = _vec(p[i]), _vec(v[i]), _mat(R[i]), _vec(w[i])
    fi, zi, ei, si = f_cmd[i], z[i], eta[i], sigma[i]  # views made once per vehicle and call
    ri = refs[i] if control_every > 0 else refs[0]
    for j in range(eta.shape[1]):
        if control_every > 0 and j % control_every == 0:
            _controller(pi, vi, Ri, wi, ri, gains, nominal, fi)
        pi, vi, Ri, wi, _, _ = plant_step(pi, vi, Ri, wi, fi, ei, j, saturate, si, zi,
                                          z_off[i, j], body, dt)
    _store_vec(p[i], pi)
    _store_vec(v[i], vi)
    _store_mat(R[i], Ri)
    _store_vec(w[i], wi)


@njit(parallel=True)
def _step_batch_parallel(p, v, R, w, f_cmd, eta, sigma, z, z_off, saturate, body, dt,
                         control_every, refs, gains, nominal):
    for i in prange(p.shape[0]):
        _advance(i, p, v, R, w, f_cmd, eta, sigma, z, z_off, saturate, body, dt,
                 control_every, refs, gains, nominal)


@njit
def _step_batch_serial(p, v, R, w, f_cmd, eta, sigma, z, z_off, saturate, body, dt,
                       control_every, refs, gains, nominal):
    for i in range(p.shape[0]):
        _advance(i, p, v, R, w, f_cmd, eta, sigma, z, z_off, saturate, body, dt,
                 control_every, refs, gains, nominal)


#: below this many vehicles :func:`step_batch` runs on the calling thread (a parallel launch
#: costs more than it saves for a handful of vehicles)
PARALLEL_MIN_VEHICLES = 64


def step_batch(p, v, R, w, f_cmd, eta, sigma, z, z_off, saturate, body, dt,
               control_every=0, refs=None, gains=None, nominal=None):
    """Advance N vehicles by ``k = eta.shape[1]`` physics substeps, in place, in parallel.

    Per vehicle i and substep j: when ``control_every > 0`` and ``j % control_every == 0``
    the geometric controller (eqs. 9, 10; :func:`_controller`, from the *true* state, with
    the reference ``refs[i]`` (6, 3) held over the call, ``gains`` and the nominal vehicle
    ``nominal`` (default ``body``)) writes ``f_cmd[i]``; then :func:`plant_step` (motor model
    eqs. 11, 13 with efficiency ``eta[i, j]`` and thrust noise
    ``sigma[i] * z[i, z_off[i, j]:+n]``, allocation, RKMK4 eqs. 1-4 of length ``dt`` [s]).

    Shapes: ``p, v, w`` (N, 3), ``R`` (N, 3, 3), ``f_cmd`` (N, n) (updated with the
    controller), ``eta`` (N, k, n), ``sigma`` (N,), ``z`` (N, m) standard normals, ``z_off``
    (N, k) int64, ``refs`` (N, 6, 3). All float64 and C-contiguous (numba's prange over the
    vehicles from ``PARALLEL_MIN_VEHICLES`` on; numba's thread count, one per core by default).
    """
    if control_every > 0 and (refs is None or gains is None):
        raise ConfigError("step_batch: the controller (control_every > 0) needs refs and gains")
    if refs is None:
        refs = np.zeros((1, 6, 3))
    gains = no_gains() if gains is None else gains
    nominal = body if nominal is None else nominal
    kernel = _step_batch_parallel if len(p) >= PARALLEL_MIN_VEHICLES else _step_batch_serial
    kernel(p, v, R, w, f_cmd, eta, sigma, z, z_off, bool(saturate), body, float(dt),
           int(control_every), refs, gains, nominal)


@njit(parallel=True)
def _controller_batch_parallel(p, v, R, w, refs, gains, nominal, out):
    for i in prange(p.shape[0]):
        _controller(_vec(p[i]), _vec(v[i]), _mat(R[i]), _vec(w[i]), refs[i], gains, nominal,
                    out[i])


@njit
def _controller_batch_serial(p, v, R, w, refs, gains, nominal, out):
    for i in range(p.shape[0]):
        _controller(_vec(p[i]), _vec(v[i]), _mat(R[i]), _vec(w[i]), refs[i], gains, nominal,
                    out[i])


def controller_batch(p, v, R, w, refs, gains, nominal, out):
    """The geometric controller (eqs. 9, 10; :func:`_controller`) for N states into ``out``
    (N, n): ``p, v, w`` (N, 3), ``R`` (N, 3, 3), ``refs`` (N, 6, 3) as in :func:`_controller`."""
    kernel = (_controller_batch_parallel if len(p) >= PARALLEL_MIN_VEHICLES
              else _controller_batch_serial)
    kernel(p, v, R, w, refs, gains, nominal, out)


@njit
def draw_normals(generators, rows, sizes, z):
    """``z[i, :sizes[i]] = generators[i].standard_normal(sizes[i])`` for i in ``rows``.

    numba's ``Generator.standard_normal`` is numpy's algorithm on the generator's own bit
    generator (shared state), so this gives the numbers -- and leaves the generators in the
    state -- of the same calls in Python, without a Python call per generator.
    """
    for r in range(rows.shape[0]):
        i = rows[r]
        g = generators[i]
        for k in range(sizes[i]):
            z[i, k] = g.standard_normal()


def no_gains() -> Gains:
    """Placeholder gains for :func:`step_batch` calls without the controller."""
    z = np.zeros(3)
    return Gains(z, z, z, z, False, False, False)


# --- simulator.py: the single-vehicle loop ----------------------------------------------------
@njit
def _reference_step(p, v, R, w, lag, body, dt):
    """:func:`reference_euler_step` on tuples (the MATLAB reproduction; allocates)."""
    pa, va, Ra, wa = reference_euler_step(_arr3(p), _arr3(v), _arr33(R), _arr3(w), lag, body, dt)
    return _vec(pa), _vec(va), _mat(Ra), _vec(wa)


@njit
def _store_row(dst, x):
    for i in range(dst.shape[0]):
        dst[i] = x[i]


@njit
def run_steps(k0, k1, reference, decimation, dt, carry, lag, f_cmd, sf_meas,
              refs, eta, noise, layout, sensor_std, accel_std, record_accel,
              gains, nominal, plant, saturate, thrust_noise, out):
    """Steps ``k0 .. k1-1`` of the loop in :func:`quadfault.simulator.simulate`.

    ``carry`` (rows p, v, w, then R in rows 3..5 of a (6, 3) array) the plant state, ``lag``
    the reference integrator's memory, ``f_cmd`` the held command and ``sf_meas`` the last
    accelerometer reading are updated in place, so the loop runs in chunks; ``noise`` holds
    the chunk's draws (row 0 = step ``k0``); ``refs`` (n_steps, 6, 3) the controller's
    reference rows (see :func:`_controller`). Returns the first step whose new state is not
    finite, or -1.
    """
    out_p, out_v, out_R, out_w, out_f, out_eta, out_acc = out
    p, v, w = _vec(carry[0]), _vec(carry[1]), _vec(carry[2])
    R = (carry[3, 0], carry[3, 1], carry[3, 2], carry[4, 0], carry[4, 1], carry[4, 2],
         carry[5, 0], carry[5, 1], carry[5, 2])
    e_off = max(layout[4], 0)
    diverged = -1
    for k in range(k0, k1):
        row = noise[k - k0]
        if reference:
            p, v, R, w = _reference_step(p, v, R, w, lag, plant, dt)
        mp, mv, mR, mw = _measure(p, v, R, w, row, layout, sensor_std)
        if k % decimation == 0:
            _controller(mp, mv, mR, mw, refs[k], gains, nominal, f_cmd)
        # Plant.step: produced thrust, wrench, accelerometer truth, integration
        R_before = R
        if reference:
            thrust, moment = _motor_wrench(f_cmd, eta, k, saturate, thrust_noise, row, e_off,
                                           plant)
            reference_euler_apply(lag, thrust, _arr3(moment), _arr33(R))
        else:
            p, v, R, w, thrust, moment = plant_step(p, v, R, w, f_cmd, eta, k, saturate,
                                                    thrust_noise, row, e_off, plant, dt)
        if record_accel:
            sf = _specific_force(R_before, _tacc(R_before, thrust, plant), plant.gravity)
            if accel_std != 0.0:
                sf = _axpy(sf, accel_std, _vec(row, layout[5]))
            _store_vec(sf_meas, sf)
        _store_vec(out_p[k], mp)
        _store_vec(out_v[k], mv)
        _store_vec(out_w[k], mw)
        _store_mat(out_R[k], mR)
        _store_row(out_f[k], f_cmd)
        _store_row(out_eta[k], eta[k])
        _store_row(out_acc[k], sf_meas)
        if not (np.isfinite(p[0]) and np.isfinite(p[1]) and np.isfinite(p[2])):
            diverged = k
            break
    _store_vec(carry[0], p)
    _store_vec(carry[1], v)
    _store_vec(carry[2], w)
    for r in range(3):
        carry[3 + r, 0], carry[3 + r, 1], carry[3 + r, 2] = R[3 * r], R[3 * r + 1], R[3 * r + 2]
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


def reference_rows(refs, w_d, w_dot_d) -> np.ndarray:
    """(n, 6, 3) rows (position, velocity, acceleration, b1d, Omega_d, Omega_d') for
    :func:`_controller` from a FlatOutput of arrays and the feed-forward rates."""
    pos, vel, acc, b1d = (np.asarray(a, float) for a in refs[:4])
    n = pos.shape[0]
    out = np.empty((n, 6, 3))
    for r, a in enumerate((pos, vel, acc, b1d, w_d, w_dot_d)):
        out[:, r] = a
    return out


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
        w_d = w_dot_d = np.zeros((n, 3))
    else:
        w_d, w_dot_d = (np.asarray(a, float) for a in feedforward)
    ref_rows = reference_rows(refs, w_d, w_dot_d)
    carry = np.empty((6, 3))
    carry[0], carry[1], carry[2], carry[3:6] = initial.p, initial.v, initial.w, initial.R
    lag = np.zeros((4, 3))
    f_cmd = np.zeros(n_rot)
    sf_meas = np.array([0.0, 0.0, -vehicle.gravity])
    out = (np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3, 3)), np.empty((n, 3)),
           np.empty((n, n_rot)), np.empty((n, n_rot)), np.empty((n, 3)))
    head = (config.integrator == "reference", config.control_decimation, float(config.dt),
            carry, lag, f_cmd, sf_meas, ref_rows, eta)
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
