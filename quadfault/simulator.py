"""The closed-loop simulation: scenario -> plant -> sensors -> recording.

An explicit, readable loop. Per physics step k (time t_k):

1. the sensors measure the plant state (noise-free by default, as in the paper);
2. every ``control_period`` the controller computes rotor commands from the measurement;
3. row k of the recording stores the measurement and the command sent (before the plant's
   efficiency, noise and saturation) and the true efficiency used over the step;
4. the plant integrates the step with that command held (zero-order hold).

``integrator="reference"`` reproduces the authors' MATLAB loop instead (see
:class:`~quadfault.dynamics.ReferenceEuler`): step first, then control; row k holds the state
after the step and the command computed from it, which acts from row k+1 to k+2 (the
one-sample lag is kept in the recording, as in the authors' data). Its times are
``t_k = (k + 1) dt``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from quadfault.controller import ControllerConfig, GeometricController
from quadfault.dynamics import RigidBodyState
from quadfault.errors import ConfigError
from quadfault.motors import MotorModel
from quadfault.plant import INTEGRATORS, Plant
from quadfault.recording import Recording
from quadfault.rotation import expm_so3, rot_to_quat
from quadfault.scenarios import Scenario
from quadfault.vehicle import Vehicle


@dataclass(frozen=True)
class SensorNoise:
    """Standard deviations of white measurement noise (all zero by default, as in the paper).

    Attributes:
        position [m], velocity [m/s], attitude [rad] (rotation-vector noise), gyro [rad/s],
        accel [m/s^2].
    """

    position: float = 0.0
    velocity: float = 0.0
    attitude: float = 0.0
    gyro: float = 0.0
    accel: float = 0.0

    def __post_init__(self):
        for k in ("position", "velocity", "attitude", "gyro", "accel"):
            v = getattr(self, k)
            if not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"sensor noise {k} must be >= 0, got {v!r}")

    @property
    def any(self) -> bool:
        return any((self.position, self.velocity, self.attitude, self.gyro, self.accel))

    def measure(self, state: RigidBodyState, specific_force, rng: np.random.Generator):
        """Noisy copy of ``state`` and of the accelerometer reading."""
        if not self.any:
            return state, specific_force
        shape = state.p.shape
        p = state.p + self.position * rng.standard_normal(shape)
        v = state.v + self.velocity * rng.standard_normal(shape)
        R = state.R @ expm_so3(self.attitude * rng.standard_normal(shape)) if self.attitude else state.R
        w = state.w + self.gyro * rng.standard_normal(shape)
        sf = None if specific_force is None else specific_force + self.accel * rng.standard_normal(shape)
        return RigidBodyState(p, v, R, w), sf


#: ``SimConfig.backend`` values (the compiled path lives in ``quadfault._sim_numba``).
BACKENDS = ("auto", "numpy", "numba")


@dataclass(frozen=True)
class SimConfig:
    """Simulation settings.

    Attributes:
        dt: physics step [s] (1 kHz as in the paper).
        integrator: ``"rk4"`` (RKMK4 on SO(3)) or ``"reference"`` (the authors' Euler step).
        control_period: controller period [s]; ``None`` = every physics step.
        saturate: clip rotor commands to [0, f_max] (the reference clips only at 0).
        sensor_noise: measurement noise.
        controller: geometric controller options.
        record_accel: add the accelerometer columns ``ax, ay, az``.
        backend: ``"auto"`` (the compiled numba kernel when numba is installed and the case
            is supported, else numpy), ``"numpy"`` (force the pure loop) or ``"numba"``
            (require the kernel); both give the same results (docs/performance.md).
    """

    dt: float = 1e-3
    integrator: str = "rk4"
    control_period: float | None = None
    saturate: bool = True
    sensor_noise: SensorNoise = field(default_factory=SensorNoise)
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    record_accel: bool = True
    backend: str = "auto"

    def __post_init__(self):
        if self.backend not in BACKENDS:
            raise ConfigError(f"backend must be one of {BACKENDS}, got {self.backend!r}")
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ConfigError(f"dt must be positive [s], got {self.dt!r}")
        if self.integrator not in INTEGRATORS:
            raise ConfigError(f"integrator must be one of {INTEGRATORS}, got {self.integrator!r}")
        if self.control_period is not None and not (self.control_period >= self.dt):
            raise ConfigError("control_period must be >= dt")

    @classmethod
    def reference(cls, **changes) -> "SimConfig":
        """The authors' MATLAB setup: Euler step with its input lag, no upper saturation,
        a_d = 0, Omega_d = 0, un-normalised b2d."""
        base = cls(integrator="reference", saturate=False, controller=ControllerConfig.reference())
        return replace(base, **changes)

    @property
    def control_decimation(self) -> int:
        if self.control_period is None:
            return 1
        k = self.control_period / self.dt
        if abs(k - round(k)) > 1e-9:
            raise ConfigError("control_period must be a whole multiple of dt")
        return int(round(k))


def initial_state(scenario: Scenario, t0: float = 0.0,
                  controller: GeometricController | None = None) -> RigidBodyState:
    """The desired state at ``t0``.

    With a geometric ``controller`` the attitude and rate are its feed-forward ``R_d`` and
    ``Omega_d`` (a smooth start); without one, level attitude and zero rate (the reference).
    """
    ref = scenario.trajectory(t0)
    p, v = np.array(ref.position, float), np.array(ref.velocity, float)
    if controller is None:
        return RigidBodyState(p, v, np.eye(3), np.zeros(3))
    out = controller.compute(t0, p, v, np.eye(3), np.zeros(3), ref)
    Rd = out.Rd
    # at R = R_d the body rate that zeroes e_Omega is Omega_d itself
    w = controller.feedforward_rates(t0)[0] if controller.config.angular_feedforward else np.zeros(3)
    return RigidBodyState(p, v, Rd, np.array(w, float))


def _use_compiled(cfg: SimConfig, ctrl, effects) -> bool:
    """Whether :func:`simulate` runs the compiled kernel (``quadfault._sim_numba``)."""
    if cfg.backend == "numpy":
        return False
    from quadfault import _sim_numba

    why = None
    if not _sim_numba.AVAILABLE:
        why = "numba is not installed (pip install 'quadfault[fast]')"
    elif effects:
        why = "unmodelled effects run on the numpy path only"
    elif type(ctrl) is not GeometricController:
        why = "only the GeometricController is compiled"
    if why is not None and cfg.backend == "numba":
        raise ConfigError(f"backend 'numba' cannot run this simulation: {why}")
    return why is None


def _progress(total, enabled, desc):
    if not enabled:
        return None
    from quadfault.progress import progress_bar

    return progress_bar(total=total, desc=desc, unit="step")


def simulate(scenario: Scenario, *, vehicle: Vehicle | None = None,
             config: SimConfig | None = None, seed: int | None = 0,
             effects: tuple = (), thrust_noise: float | None = None,
             controller: GeometricController | None = None, nominal: Vehicle | None = None,
             progress: bool = False) -> Recording:
    """Fly ``scenario`` and return the recording (with the true ``eta`` for scoring).

    Args:
        scenario: efficiency schedule, trajectory, duration and thrust noise.
        vehicle: the true vehicle (paper F450 by default).
        config: simulation settings.
        seed: seeds one ``numpy.random.Generator`` for the thrust and sensor noise.
        effects: unmodelled effects of the true plant (``quadfault.effects``).
        thrust_noise: overrides the scenario's sigma_f.
        controller: a custom controller (default: geometric, on the nominal vehicle).
        nominal: the vehicle the controller and the recording's sidecar know (default: the
            true vehicle; differs when an effect such as an inertia error is simulated).
        progress: show a progress bar.
    """
    cfg = config or SimConfig()
    true_vehicle = vehicle or Vehicle()
    nominal = nominal or true_vehicle
    if not cfg.saturate:
        true_vehicle = true_vehicle.replace(max_thrust=math.inf)
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer))
                             or seed < 0):
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
    rng = np.random.default_rng(seed)
    sigma = scenario.thrust_noise if thrust_noise is None else thrust_noise
    plant = Plant(true_vehicle, scenario.efficiency, MotorModel(sigma, cfg.saturate), effects,
                  cfg.integrator, cfg.dt, rng)
    ctrl = controller or GeometricController(nominal, scenario.trajectory, cfg.controller)
    reference = cfg.integrator == "reference"
    n = int(round(scenario.duration / cfg.dt))
    if n < 2:
        raise ConfigError(f"duration {scenario.duration} s is shorter than two steps")
    t0 = cfg.dt if reference else 0.0
    plant.reset(initial_state(scenario, t0, None if reference or not isinstance(
        ctrl, GeometricController) else ctrl))
    decim = cfg.control_decimation
    out_p, out_v, out_R = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3, 3))
    out_w, out_f, out_eta = np.empty((n, 3)), np.empty((n, 4)), np.empty((n, 4))
    out_acc = np.empty((n, 3))
    times = t0 + cfg.dt * np.arange(n)
    f_cmd = np.zeros(true_vehicle.n_rotors)
    bar = _progress(n, progress, f"simulate {scenario.name}")
    sf_meas = np.array([0.0, 0.0, -true_vehicle.gravity])
    # The reference trajectory is a function of time only: evaluate it once for all steps.
    precomputed = isinstance(ctrl, GeometricController)
    if precomputed:
        refs = ctrl.trajectory(times)
        ffs = ctrl.feedforward_rates(times) if ctrl.config.angular_feedforward else None
    # Compiled fast path: the same loop in quadfault._sim_numba fills the same outputs.
    n_pure = n
    if _use_compiled(cfg, ctrl, effects):
        from quadfault import _sim_numba

        *outs, bad = _sim_numba.run(plant, ctrl, cfg, rng, times, refs, ffs, plant.state, bar)
        out_p, out_v, out_R, out_w, out_f, out_eta, out_acc = outs
        if bad >= 0:
            raise ConfigError(f"simulation diverged at t = {times[bad]:.3f} s (non-finite state)")
        n_pure = 0
    for k in range(n_pure):
        t = times[k]
        if reference:
            state = plant.advance_reference()
        else:
            state = plant.state
        meas, _ = cfg.sensor_noise.measure(state, None, rng)
        if k % decim == 0:
            if precomputed:
                ref_k = type(refs)(*(a[k] for a in refs))
                ff_k = None if ffs is None else (ffs[0][k], ffs[1][k])
                f_cmd, _ = ctrl.motor_commands(t, meas.p, meas.v, meas.R, meas.w, ref_k, ff_k)
            else:
                f_cmd, _ = ctrl.motor_commands(t, meas.p, meas.v, meas.R, meas.w)
        step = plant.step(f_cmd, t)
        if cfg.record_accel:
            sf_meas = step.specific_force
            if cfg.sensor_noise.accel:
                sf_meas = sf_meas + cfg.sensor_noise.accel * rng.standard_normal(3)
        out_p[k], out_v[k], out_w[k] = meas.p, meas.v, meas.w
        out_R[k] = meas.R
        out_f[k], out_eta[k], out_acc[k] = f_cmd, step.eta, sf_meas
        if not np.all(np.isfinite(plant.state.p)):
            raise ConfigError(f"simulation diverged at t = {t:.3f} s (non-finite state)")
        if bar is not None and k % 1000 == 0:
            bar.update(min(1000, n - k))
    if bar is not None:
        bar.close()
    out_q = rot_to_quat(out_R)
    vbat = None if scenario.voltage is None else scenario.voltage(times)
    meta = {
        "scenario": scenario.name,
        "seed": seed,
        "integrator": cfg.integrator,
        "dt": cfg.dt,
        "thrust_noise": sigma,
        "fault_windows": [[m, a, b if math.isfinite(b) else None]
                          for m, a, b in scenario.fault_windows()],
    }
    if effects:
        meta["effects"] = [e.describe() for e in effects]
    return Recording(t=times, omega=out_w, thrust_cmd=out_f, vehicle=nominal, position=out_p,
                     velocity=out_v, quaternion=out_q,
                     accel=out_acc if cfg.record_accel else None, vbat=vbat, eta_true=out_eta,
                     frame="NED", source=f"quadfault simulate ({cfg.integrator})", meta=meta)
