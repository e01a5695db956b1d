"""The closed-loop simulation: scenario -> plant -> sensors -> recording.

:func:`simulate` flies one vehicle through :class:`quadfault.model.flight.Flight` (the closed loop
every user of the model shares). Per physics step k (time t_k):

1. the sensors measure the plant state (noise-free by default, as in the paper);
2. every ``control_period`` the geometric controller computes rotor commands from the
   measurement;
3. row k of the recording stores the measurement and the command sent (before the plant's
   efficiency, noise and saturation) and the true efficiency used over the step;
4. the plant integrates the step with that command held (zero-order hold).

``integrator="reference"`` reproduces the authors' MATLAB loop instead (see
:func:`~quadfault.model.dynamics.reference_euler_step`): step first, then control; row k holds the
state after the step and the command computed from it, which acts from row k+1 to k+2 (the
one-sample lag is kept in the recording, as in the authors' data). Its times are
``t_k = (k + 1) dt``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from quadfault.errors import ConfigError
from quadfault.io.recording import Recording
from quadfault.model.controller import ControllerConfig, GeometricController
from quadfault.model.dynamics import RigidBodyState
from quadfault.model.flight import Flight, Records
from quadfault.model.motors import MotorModel
from quadfault.model.plant import INTEGRATORS, EffectsHook, Plant
from quadfault.model.rotation import rot_to_quat
from quadfault.model.scenarios import Scenario
from quadfault.model.sensor_presets import as_sensor_noise
from quadfault.model.sensors import SensorNoise
from quadfault.model.vehicle import Vehicle
from quadfault.progress import progress_bar


@dataclass(frozen=True)
class SimConfig:
    """Simulation settings.

    Attributes:
        dt: physics step [s] (1 kHz as in the paper).
        integrator: ``"rk4"`` (RKMK4 on SO(3)) or ``"reference"`` (the authors' Euler step).
        control_period: controller period [s]; ``None`` = every physics step.
        saturate: clip rotor commands to [0, f_max] (the reference clips only at 0).
        sensor_noise: the sensors: a :class:`SensorNoise` or what ``as_sensor_noise`` takes (a
            preset name such as ``"px4"``; default noise-free).
        controller: geometric controller options.
        record_accel: add the accelerometer columns ``ax, ay, az``.
    """

    dt: float = 1e-3
    integrator: str = "rk4"
    control_period: float | None = None
    saturate: bool = True
    sensor_noise: SensorNoise = field(default_factory=SensorNoise)
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    record_accel: bool = True

    def __post_init__(self):
        object.__setattr__(self, "sensor_noise", as_sensor_noise(self.sensor_noise))
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ConfigError(f"dt must be positive [s], got {self.dt!r}")
        if self.integrator not in INTEGRATORS:
            raise ConfigError(f"integrator must be one of {INTEGRATORS}, got {self.integrator!r}")
        if self.control_period is not None and not (self.control_period >= self.dt):
            raise ConfigError("control_period must be >= dt")

    @classmethod
    def reference(cls, **changes) -> SimConfig:
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


def initial_state(
    scenario: Scenario, t0: float = 0.0, controller: GeometricController | None = None
) -> RigidBodyState:
    """The desired state at ``t0``.

    With a geometric ``controller`` the attitude and rate are its feed-forward ``R_d`` and
    ``Omega_d`` (a smooth start: on the reference, eq. 9 gives exactly that ``R_d``, and at
    ``R = R_d`` the rate that zeroes ``e_Omega`` is ``Omega_d``); without one, level attitude
    and zero rate (the reference code).
    """
    ref = scenario.trajectory(t0)
    p, v = np.array(ref.position, float), np.array(ref.velocity, float)
    if controller is None:
        return RigidBodyState(p, v, np.eye(3), np.zeros(3))
    Rd, w, _ = controller.feedforward(t0, compiled=False)  # once: not worth compiling
    if not controller.config.angular_feedforward:
        w = np.zeros(np.shape(w))
    return RigidBodyState(p, v, Rd, np.array(w, float))


def _progress(total, enabled, desc):
    if not enabled:
        return None
    return progress_bar(total=total, desc=desc, unit="step")


#: steps per call of the loop (the progress bar moves between calls)
CHUNK = 5000


def simulate(
    scenario: Scenario,
    *,
    vehicle: Vehicle | None = None,
    config: SimConfig | None = None,
    seed: int | None = 0,
    effects: tuple = (),
    thrust_noise: float | None = None,
    controller: GeometricController | None = None,
    nominal: Vehicle | None = None,
    progress: bool = False,
    stop_at_loss: bool = False,
) -> Recording:
    """Fly ``scenario`` and return the recording (with the true ``eta`` for scoring).

    Args:
        scenario: efficiency schedule, trajectory, duration and thrust noise.
        vehicle: the true vehicle (paper F450 by default).
        config: simulation settings.
        seed: seeds one ``numpy.random.Generator`` for the thrust and sensor noise.
        effects: unmodelled effects of the true plant (``quadfault.model.effects`` or any object
            of the :class:`~quadfault.model.plant.Effect` protocol).
        thrust_noise: overrides the scenario's sigma_f.
        controller: a :class:`GeometricController` (default: on the nominal vehicle with
            ``config.controller``, tracking the scenario's trajectory).
        nominal: the vehicle the controller and the recording's sidecar know (default: the
            true vehicle; differs when an effect such as an inertia error is simulated).
        progress: show a progress bar.
        stop_at_loss: end the flight at the first row where it loses the vehicle or goes
            below the scenario's ground (:func:`flight_end`); the recording stops there and
            its ``meta["end"]`` gives ``reason``, ``t`` and ``planned_duration`` [s]. A
            flight that diverges after such a row is returned up to it instead of raising.
    """
    cfg = config or SimConfig()
    true_vehicle = vehicle or Vehicle()
    nominal = nominal or true_vehicle
    if not cfg.saturate:
        true_vehicle = true_vehicle.replace(max_thrust=math.inf)
    if seed is not None and (
        isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0
    ):
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
    rng = np.random.default_rng(seed)
    sigma = scenario.thrust_noise if thrust_noise is None else thrust_noise
    plant = Plant(true_vehicle, MotorModel(sigma, cfg.saturate), effects, cfg.integrator, cfg.dt)
    ctrl = controller or GeometricController(nominal, scenario.trajectory, cfg.controller)
    if not isinstance(ctrl, GeometricController):
        raise ConfigError(
            f"controller must be a GeometricController, got "
            f"{type(ctrl).__name__} (other controllers fly with "
            f"agents.rollout.fly)"
        )
    reference = cfg.integrator == "reference"
    n = int(round(scenario.duration / cfg.dt))
    if n < 2:
        raise ConfigError(f"duration {scenario.duration} s is shorter than two steps")
    t0 = cfg.dt if reference else 0.0
    times = t0 + cfg.dt * np.arange(n)
    plant.reset()
    flight = Flight(
        plant,
        cfg.sensor_noise,
        controller=ctrl,
        control_every=cfg.control_decimation,
        record_accel=cfg.record_accel,
        t0=t0,
    )
    flight.reset(rng)
    flight.set_state(initial_state(scenario, t0, None if reference else ctrl))
    eta = flight.plan(n, scenario.efficiency)
    bar = _progress(n, progress, f"simulate {scenario.name}")
    chunk = CHUNK // 10 if isinstance(plant.hook, EffectsHook) else CHUNK
    chunks = []
    for k0 in range(0, n, chunk):
        k1 = min(n, k0 + chunk)
        rows = flight.step(
            None,
            k1 - k0,
            record=flight.records(k1 - k0, accel=cfg.record_accel),
            measure_first=True,
        )
        done = int(flight.steps_run[0])
        chunks.append(rows)
        if bar is not None:
            bar.update(k1 - k0)
        event = (
            None
            if not stop_at_loss
            else _first_event(times[k0 : k0 + done], rows.p[0, :done], scenario, LOST_CONTROL_ERROR)
        )
        if event is not None:
            n = k0 + event[0] + 1
            end = {
                "reason": event[1],
                "t": float(times[n - 1]),
                "planned_duration": float(scenario.duration),
            }
            break
        if not flight.state().is_finite():
            raise ConfigError(
                f"simulation diverged at t = {times[k0 + done - 1]:.3f} s (non-finite state)"
            )
    else:
        end = None
    if bar is not None:
        bar.close()
    plant.check_effects()
    times, eta = times[:n], eta[:n]
    out = Records(1, *(np.concatenate(parts, axis=1)[:, :n] for parts in list(zip(*chunks))[1:]))
    vbat = None if scenario.voltage is None else scenario.voltage(times)
    meta: dict[str, Any] = {
        "scenario": scenario.name,
        "seed": seed,
        "integrator": cfg.integrator,
        "dt": cfg.dt,
        "thrust_noise": sigma,
        # whether the plant limited each rotor's thrust to the vehicle's max_thrust: the
        # estimators clip the commands at that limit only when it did
        "saturated": bool(cfg.saturate),
        "fault_windows": [
            [m, a, b if math.isfinite(b) else None] for m, a, b in scenario.fault_windows()
        ],
    }
    if cfg.sensor_noise.any:
        meta["sensor_noise"] = cfg.sensor_noise.describe()
    if effects:
        meta["effects"] = [
            e.describe() if hasattr(e, "describe") else {"name": type(e).__name__} for e in effects
        ]
    if end is not None:
        meta["end"] = end
    return Recording(
        t=times,
        omega=out.w[0],
        thrust_cmd=out.f_cmd[0],
        vehicle=nominal,
        position=out.p[0],
        velocity=out.v[0],
        quaternion=rot_to_quat(out.R[0]),
        accel=out.accel[0] if cfg.record_accel else None,
        vbat=vbat,
        eta_true=eta,
        frame="NED",
        source=f"quadfault simulate ({cfg.integrator})",
        meta=meta,
    )


#: tracking error [m] above which a flight has lost the vehicle (:func:`flight_end`)
LOST_CONTROL_ERROR = 2.0


def flight_end(
    rec: Recording, scenario: Scenario, lost_error: float = LOST_CONTROL_ERROR
) -> tuple[int, str] | None:
    """Where a simulated flight stops being a flight: ``(row, reason)`` of the first row where
    the vehicle is below the scenario's ground (``"below_ground"``: altitude ``-p_z`` under
    ``scenario.ground_altitude``) or farther than ``lost_error`` [m] from the reference
    (``"lost_control"``), or None when neither happens."""
    return _first_event(rec.t, rec.position, scenario, lost_error)


def _first_event(t, position, scenario: Scenario, lost_error: float):
    """:func:`flight_end` of times ``t`` (N,) and true positions (N, 3) [m]."""
    err = np.linalg.norm(position - scenario.trajectory(t).position, axis=1)
    events = [(np.flatnonzero(err > lost_error), "lost_control")]
    if scenario.ground_altitude is not None:
        events.append((np.flatnonzero(-position[:, 2] < scenario.ground_altitude), "below_ground"))
    first = [(int(rows[0]), reason) for rows, reason in events if rows.size]
    return min(first) if first else None


__all__ = [
    "LOST_CONTROL_ERROR",
    "SensorNoise",
    "SimConfig",
    "flight_end",
    "initial_state",
    "simulate",
]
