"""The single env's control step on the compiled plant step (``physics="numba"``).

:func:`env_substeps` is the loop of :meth:`QuadFaultEnv.step` -- per substep: the measured
state (:class:`~quadfault.simulator.SensorNoise`), the plant step
(:func:`quadfault._numba_kernels.plant_step`: motor model eqs. 11, 13, allocation, RKMK4
eqs. 1-4, the same kernel the simulator and the vector env run) and the accelerometer truth
(``specific_force_body`` of eq. 2 at the step start) plus its noise -- in one compiled call
per control step. The random numbers are the numpy path's, drawn by the caller in one block:
:func:`step_noise_layout` says where each substep's draws sit.

:class:`CompiledStep` holds what the env's compiled path needs per episode: the vehicle and
gains as arrays, the noise layout, and tables of the functions of time only -- the reference
and feed-forward rates at the control steps' boundaries and the true efficiency at the
substeps -- evaluated in chunks of :data:`CHUNK` control steps (one vectorised call instead
of a few scalar calls per step), and the compiled twin of the geometric controller
(``quadfault._sim_numba.controller_batch``).

Without numba (``AVAILABLE`` False) the loop stays plain Python (slow, for the tests only):
the env then uses its numpy path.
"""

from __future__ import annotations

import numpy as np

from estimators.base import Sample
from quadfault import _sim_numba
from quadfault._numba_kernels import (
    AVAILABLE,
    _axpy,
    _mat,
    _measure,
    _specific_force,
    _store_mat,
    _store_vec,
    _tacc,
    _vec,
    njit,
    plant_step,
)
from quadfault.dynamics import RigidBodyState
from quadfault.trajectory import FlatOutput


def step_noise_layout(sensor_noise, n_rotors: int, thrust_noise: float):
    """Where one substep's standard normals sit, in the numpy path's order of draws.

    Returns ``(layout, width, meas_width)``: ``layout`` = column offsets of (position,
    velocity, attitude, gyro, motors, accelerometer) inside a substep's row of ``width``
    draws (-1: not drawn); the first ``meas_width`` columns are the measurement's, which
    substep 0 does not draw (it reuses the end-of-step measurement of the previous step).
    """
    layout, width = _sim_numba.noise_layout(sensor_noise, n_rotors, thrust_noise, True)
    meas_width = int(layout[3]) + 3 if sensor_noise.any else 0  # p, v, [attitude], w
    return layout, width, meas_width


@njit
def _finite(p, v, R, w):
    """Whether every component of the state is finite (``RigidBodyState.is_finite``)."""
    for k in range(3):
        if not (np.isfinite(p[k]) and np.isfinite(v[k]) and np.isfinite(w[k])):
            return False
    for k in range(9):
        if not np.isfinite(R[k]):
            return False
    return True


@njit
def env_substeps(p, v, R, w, mp, mv, mR, mw, f_cmd, eta, sigma, z, layout, sensor_std,
                 accel_std, saturate, body, dt, out_p, out_v, out_R, out_w, out_sf):
    """Up to ``eta.shape[0]`` physics substeps of one vehicle, in place.

    ``p, v, w`` (3,) and ``R`` (3, 3) the true state (updated); ``mp, mv, mR, mw`` the
    measurement for substep 0; ``f_cmd`` (n,) the held commands [N]; ``eta`` (S, n) the true
    efficiency per substep; ``sigma`` the thrust noise; ``z`` (S, width) the standard normals
    (row j = substep j, columns as :func:`step_noise_layout`); ``sensor_std`` = (position,
    velocity, attitude, gyro) [m, m/s, rad, rad/s], ``accel_std`` [m/s^2]. Writes each
    substep's measured state and accelerometer reading (body FRD [m/s^2]) into the ``out_*``
    rows. Returns the number of substeps run: it stops after the first non-finite state, as
    the numpy loop does.
    """
    pi, vi, Ri, wi = _vec(p), _vec(v), _mat(R), _vec(w)
    qp, qv, qR, qw = _vec(mp), _vec(mv), _mat(mR), _vec(mw)
    e_off = max(layout[4], 0)
    n_sub = eta.shape[0]
    done = 0
    for j in range(n_sub):
        row = z[j]
        if j > 0:
            qp, qv, qR, qw = _measure(pi, vi, Ri, wi, row, layout, sensor_std)
        _store_vec(out_p[j], qp)
        _store_vec(out_v[j], qv)
        _store_mat(out_R[j], qR)
        _store_vec(out_w[j], qw)
        R_before = Ri
        pi, vi, Ri, wi, thrust, _ = plant_step(pi, vi, Ri, wi, f_cmd, eta, j, saturate, sigma,
                                               row, e_off, body, dt)
        sf = _specific_force(R_before, _tacc(R_before, thrust, body), body.gravity)
        if layout[5] >= 0:
            sf = _axpy(sf, accel_std, _vec(row, layout[5]))
        _store_vec(out_sf[j], sf)
        done = j + 1
        if not _finite(pi, vi, Ri, wi):
            break
    _store_vec(p, pi)
    _store_vec(v, vi)
    _store_mat(R, Ri)
    _store_vec(w, wi)
    return done


def _rows(fn, ts: np.ndarray, shape: tuple) -> np.ndarray:
    """``fn(ts)`` (a tuple of ``shape[0]`` arrays (len(ts), shape[1])) as one array
    (len(ts), *shape); time by time when ``fn`` takes scalar times only."""
    try:
        out = np.stack([np.asarray(a, dtype=float) for a in fn(ts)], axis=1)
        if out.shape == (len(ts),) + tuple(shape):
            return out
    except (ValueError, TypeError, IndexError):
        pass
    return np.array([np.stack([np.asarray(a, dtype=float) for a in fn(t)])
                     for t in ts.tolist()]).reshape((len(ts),) + tuple(shape))


#: control steps per evaluation of the time tables (reference, feed-forward, efficiency)
CHUNK = 64


class CompiledStep:
    """One episode of :class:`~quad_fault_env.envs.quad_fault.QuadFaultEnv` on the compiled
    path: built lazily at the episode's first step, so resets stay cheap."""

    def __init__(self, env):
        self.env = env
        self.trajectory = env.scenario.trajectory
        self.efficiency = env.scenario.efficiency
        self.controller = env.controller
        self.S, self.dt, self.n = env.substeps, env.dt, env.vehicle.n_rotors
        sn = env.sensor_noise
        self.body = _sim_numba.body_of(env.vehicle)
        self.gains = _sim_numba.gains_of(env.controller)
        self.sensor_std = np.array([sn.position, sn.velocity, sn.attitude, sn.gyro], float)
        self.accel_std = float(sn.accel)
        self.saturate = bool(env.plant.motor.saturate)
        self.sigma = float(env.scenario.thrust_noise)
        self.layout, self.width, self.meas_width = step_noise_layout(sn, self.n, self.sigma)
        self._k0 = -1  # first control step of the tables
        self._refs = self._eta = None

    # -- tables of the functions of time ---------------------------------------------------
    def _tables(self, k: int) -> int:
        """Fill the tables from control step ``k`` if needed; returns k's row in them."""
        i = k - self._k0
        if self._k0 >= 0 and 0 <= i < CHUNK:
            return i
        S, dt = self.S, self.dt
        ts = (np.arange(k, k + CHUNK + 1) * S) * dt  # step boundaries: t = (k S) dt
        tsub = (k * S + np.arange(CHUNK * S + 1)) * dt  # substeps: t = (k S + j) dt
        refs = np.zeros((CHUNK + 1, 6, 3))
        refs[:, :4] = _rows(lambda t: self.trajectory(t)[:4], ts, (4, 3))
        if self.controller.config.angular_feedforward:
            refs[:, 4:] = _rows(self.controller.feedforward_rates, ts, (2, 3))
        eta = _rows(lambda t: (np.asarray(self.efficiency(t), dtype=float),), tsub, (1, self.n))
        eta = eta[:, 0]
        self._k0, self._refs, self._eta = k, refs, np.ascontiguousarray(eta)
        return 0

    def reference(self, k: int) -> FlatOutput:
        """The reference at the start of control step ``k`` (t = k S dt)."""
        i = k - self._k0
        if not (self._k0 >= 0 and 0 <= i <= CHUNK):  # row CHUNK: the last step's end
            i = self._tables(k)
        refs = self._refs[i]
        return FlatOutput(refs[0].copy(), refs[1].copy(), refs[2].copy(), refs[3].copy())

    # -- controller and substeps -----------------------------------------------------------
    def controller_commands(self, k: int, meas: RigidBodyState) -> np.ndarray:
        """The geometric controller (eqs. 5-10) at the start of step ``k`` [N]."""
        i = self._tables(k)
        out = np.empty((1, self.n))
        _sim_numba.controller_batch(meas.p[None], meas.v[None], meas.R[None], meas.w[None],
                                    self._refs[i:i + 1], self.gains, self.body, out)
        return out[0]

    def substeps(self, k: int, f_cmd: np.ndarray, rng: np.random.Generator):
        """Control step ``k``'s substeps from the env's plant state and measurement: returns
        ``(samples, eta_true_samples, specific_force_samples, eta at the step's end)`` and
        sets the plant's state. The normals are drawn in one block in the numpy loop's order
        (and the generator rewound to where that loop leaves it if the state diverges)."""
        env, S = self.env, self.S
        i = self._tables(k)
        eta = self._eta[i * S:i * S + S + 1]
        width, mw = self.width, self.meas_width
        z = np.zeros((S, max(width, 1)))
        need = S * width - mw
        if need:
            saved = rng.bit_generator.state
            z.reshape(-1)[mw:S * width] = rng.standard_normal(need)
        m = env._meas
        p, v, R, w = (np.array(x, dtype=float) for x in env.plant.state)
        out_p, out_v, out_w, out_sf = (np.empty((S, 3)) for _ in range(4))
        out_R = np.empty((S, 3, 3))
        done = env_substeps(p, v, R, w, m.p, m.v, m.R, m.w, f_cmd, eta[:S], self.sigma, z,
                            self.layout, self.sensor_std, self.accel_std, self.saturate,
                            self.body, self.dt, out_p, out_v, out_R, out_w, out_sf)
        if done < S and need:  # diverged: the numpy loop stopped drawing here
            rng.bit_generator.state = saved
            rng.standard_normal(done * width - mw)
        env.plant.state = RigidBodyState(p, v, R, w)
        t = ((k * S + np.arange(done)) * self.dt).tolist()
        samples = [Sample(t[j], out_p[j], out_v[j], out_R[j], out_w[j], f_cmd.copy())
                   for j in range(done)]
        return samples, eta[:done].copy(), out_sf[:done], eta[S].copy()


__all__ = ["AVAILABLE", "CHUNK", "CompiledStep", "env_substeps", "step_noise_layout"]
