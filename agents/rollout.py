"""Closed-loop flights with an estimator in the loop, without the Gymnasium environment.

:func:`fly` flies the model's one closed loop (:class:`quadfault.model.flight.Flight`, the loop of
:func:`quadfault.sim.simulator.simulate`) with Python acting between its steps: per physics
step, the sensors measure (``Flight.sense``), the controller computes the commands from
the measurement and the current ``eta_hat``, the loop steps the motors and the plant, then
the estimator gets the sample just sent (state at ``t_k``, command held from ``t_k``). The
estimate is therefore causal: the command at ``t_k`` uses samples up to ``t_{k-1}``.

Sources of ``eta_hat`` (the built-in ablation): every name of the estimator registry
(:mod:`estimators.registry`), among them

* ``"irls"`` -- :class:`estimators.irls.SlidingWindowIRLS` (the paper's estimator);
* ``"ekf"`` -- :class:`estimators.ekf.MotorEfficiencyEKF`;
* ``"none"`` -- always nominal (1, 1, 1, 1): the estimate-aware controller then equals the
  geometric controller with saturation-aware allocation;
* ``"truth"`` -- **oracle ablation**: the plant's true efficiency. Labelled as such
  everywhere; never a deployable configuration.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agents.fault_tolerant import FaultTolerantConfig, make_controller
from agents.metrics import CrashLimits, FlightMetrics, RecoveryConfig, flight_metrics, tilt_angle
from estimators.registry import ESTIMATORS, make_estimator
from quadfault.errors import ConfigError
from quadfault.io.sample import Sample
from quadfault.model import flight as loop
from quadfault.model.controller import ControllerConfig
from quadfault.model.effects.spec import parse_effect
from quadfault.model.motors import MotorModel
from quadfault.model.plant import Plant
from quadfault.model.relaxed_hover_control import RotorLossDetector
from quadfault.model.scenarios import Scenario
from quadfault.model.sensor_presets import as_sensor_noise
from quadfault.model.vehicle import Vehicle
from quadfault.sim.simulator import SensorNoise, initial_state

#: the estimator names a flight takes (the registry's)
ESTIMATOR_SOURCES = tuple(ESTIMATORS)


@dataclass(frozen=True)
class FlightConfig:
    """Settings of a closed-loop flight.

    Attributes:
        dt: physics step [s].
        control_period: controller period [s] (``None``: every step).
        estimator_every: feed the estimator every k-th sample (1 = every sample, 1 kHz).
        controller: geometric controller options (acceleration feed-forward on by default).
        fault_tolerant: estimate-aware allocation options.
        sensor_noise: the sensors (noise-free by default, as in the paper): a
            :class:`SensorNoise` or what ``as_sensor_noise`` takes (a preset name).
        crash: crash limits (a crash ends the flight).
        recovery: time-to-recover parameters.
        trace_every: keep every k-th step in the returned traces (plots).
    """

    dt: float = 1e-3
    control_period: float | None = None
    estimator_every: int = 1
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    fault_tolerant: FaultTolerantConfig = field(default_factory=FaultTolerantConfig)
    sensor_noise: SensorNoise = field(default_factory=SensorNoise)
    crash: CrashLimits = field(default_factory=CrashLimits)
    recovery: RecoveryConfig = field(default_factory=RecoveryConfig)
    trace_every: int = 10

    def __post_init__(self):
        object.__setattr__(self, "sensor_noise", as_sensor_noise(self.sensor_noise))
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ConfigError(f"dt must be positive [s], got {self.dt!r}")
        if int(self.estimator_every) < 1 or int(self.trace_every) < 1:
            raise ConfigError("estimator_every and trace_every must be >= 1")

    @property
    def control_decimation(self) -> int:
        if self.control_period is None:
            return 1
        k = self.control_period / self.dt
        if k < 1 or abs(k - round(k)) > 1e-9:
            raise ConfigError("control_period must be a whole multiple of dt")
        return int(round(k))


@dataclass(frozen=True)
class Flight:
    """A flown episode: decimated traces (for plots) and its metrics.

    Traces (every ``trace_every`` steps): ``t`` [s], ``p`` / ``p_ref`` [m] (NED),
    ``pos_error`` [m], ``tilt_error`` [deg], ``yaw_rate`` [rad/s], ``f_cmd`` [N],
    ``eta_hat`` (what the controller used), ``eta_true`` (scoring only).
    """

    controller: str
    estimator: str
    scenario: str
    seed: int
    metrics: FlightMetrics
    t: np.ndarray
    p: np.ndarray
    p_ref: np.ndarray
    pos_error: np.ndarray
    tilt_error: np.ndarray
    yaw_rate: np.ndarray
    f_cmd: np.ndarray
    eta_hat: np.ndarray
    eta_true: np.ndarray
    modes: dict = field(default_factory=dict)  # allocation mode -> number of control steps
    #: the relaxed-hover switch: ``{"rotor", "first_seen", "switched"}`` (rotor 0-based,
    #: times [s]; None before a switch), or None for the other controllers
    switch: dict | None = None


class _Tabulated:
    """The efficiency schedule evaluated once on the step grid (same values, faster)."""

    def __init__(self, dt: float, table: np.ndarray):
        self.dt, self.table = dt, np.asarray(table, float)

    def __call__(self, t) -> np.ndarray:
        k = min(int(round(float(t) / self.dt)), len(self.table) - 1)
        return self.table[k]


def fly(
    scenario: Scenario,
    controller: str = "estimate-aware",
    estimator: Any = "irls",
    seed: int = 0,
    *,
    vehicle: Vehicle | None = None,
    effects=(),
    config: FlightConfig | None = None,
    progress_bar=None,
) -> Flight:
    """Fly ``scenario`` with ``controller`` (``"geometric"`` | ``"estimate-aware"``) fed by
    ``estimator`` (a name of :data:`ESTIMATOR_SOURCES` or an ``OnlineEstimator``).

    ``seed`` seeds the one generator of the plant's thrust noise and the sensor noise.
    The controller knows the nominal ``vehicle``; the plant flies the same vehicle with the
    scenario's efficiency schedule and ``effects`` (effect objects or ``--effect`` specs,
    e.g. :data:`quadfault.model.relaxed_hover.ROTOR_LOSS_EFFECTS`). The ``"relaxed-hover"``
    controller's switch times are in ``Flight.switch``.
    """
    cfg = config or FlightConfig()
    veh = vehicle or Vehicle()
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
    rng = np.random.default_rng(seed)
    n = int(round(scenario.duration / cfg.dt))
    if n < 2:
        raise ConfigError(f"scenario duration {scenario.duration} s is shorter than two steps")
    times = cfg.dt * np.arange(n)
    fx = tuple(parse_effect(e) if isinstance(e, str) else e for e in effects or ())
    plant = Plant(veh, MotorModel(scenario.thrust_noise, True), effects=fx, dt=cfg.dt)
    plant.reset()
    # the loop: the sensors without the accelerometer, the commands set here
    flight = loop.Flight(plant, cfg.sensor_noise)
    step_record = flight.records(1)  # one step's accelerometer, for the estimator
    flight.reset(rng)
    eta_table = flight.plan(n, scenario.efficiency)
    efficiency = _Tabulated(cfg.dt, eta_table)
    ft = cfg.fault_tolerant
    if ft.detector is None:  # the rotor-loss switch for the sensors flown
        ft = dataclasses.replace(ft, detector=RotorLossDetector.for_sensors(cfg.sensor_noise))
    ctrl = make_controller(
        controller,
        veh,
        scenario.trajectory,
        cfg.controller,
        ft,
        cfg.dt * cfg.control_decimation,
    )
    est = make_estimator(estimator, veh, schedule=efficiency)  # the schedule: the oracle's
    source = estimator if isinstance(estimator, str) else getattr(est, "name", type(est).__name__)
    est.reset()
    refs = scenario.trajectory(times)
    ffs = ctrl.geometric.feedforward_rates(times) if cfg.controller.angular_feedforward else None
    flight.set_state(initial_state(scenario, 0.0, ctrl.geometric))
    ctrl.reset()
    decim = cfg.control_decimation
    pos_err, tilt, f_hist = np.empty(n), np.empty(n), np.empty((n, 4))
    keep = np.arange(0, n, cfg.trace_every)
    tr_p, tr_eta_hat, tr_eta, tr_wz = (
        np.empty((keep.size, 3)),
        np.empty((keep.size, 4)),
        np.empty((keep.size, 4)),
        np.empty(keep.size),
    )
    eta_hat = np.ones(4)
    f_cmd = np.zeros(4)
    modes: dict = {}
    crash_time = None
    lim = cfg.crash
    cos_tilt = math.cos(math.radians(lim.max_tilt))
    b3d = np.array([0.0, 0.0, 1.0])
    k_end = n
    for k in range(n):
        t = times[k]
        state = flight.state()
        p_ref = refs.position[k]
        e = float(np.linalg.norm(state.p - p_ref)) if state.is_finite() else math.inf
        if (
            not math.isfinite(e)
            or e > lim.max_position_error
            or state.R[2, 2] < cos_tilt
            or state.p[2] > lim.ground_z
        ):
            crash_time, k_end = float(t), k
            break
        flight.sense()
        meas = flight.measured()
        if k % decim == 0:
            ref_k = type(refs)(*(a[k] for a in refs))
            ff_k = None if ffs is None else (ffs[0][k], ffs[1][k])
            step = ctrl.command(t, meas.p, meas.v, meas.R, meas.w, eta_hat, ref_k, ff_k)
            f_cmd = step.f
            b3d = step.out.Rd[:, 2]
            modes[step.mode] = modes.get(step.mode, 0) + 1
        pos_err[k] = e
        tilt[k] = tilt_angle(state.R[:, 2], b3d)
        f_hist[k] = f_cmd
        if k % cfg.trace_every == 0:
            j = k // cfg.trace_every
            tr_p[j], tr_eta_hat[j], tr_wz[j] = state.p, eta_hat, state.w[2]
        flight.step(f_cmd, record=step_record)
        if k % cfg.trace_every == 0:
            tr_eta[k // cfg.trace_every] = eta_table[k]
        if k % cfg.estimator_every == 0:
            accel = step_record.accel[0, 0].copy()
            estimate = est.update(
                Sample(float(t), meas.p, meas.v, meas.R, meas.w, f_cmd.copy(), accel)
            )
            eta_hat = np.asarray(estimate.eta, float)
        if progress_bar is not None and k % 1000 == 999:
            progress_bar.update(1000)
    onsets = [a for _, a, _ in scenario.fault_windows()]
    metrics = flight_metrics(
        times[:k_end],
        pos_err[:k_end],
        tilt[:k_end],
        f_hist[:k_end],
        veh.rotor_max_thrust,
        cfg.dt,
        crash_time,
        onsets,
        cfg.recovery,
    )
    m = int(np.searchsorted(keep, k_end))
    return Flight(
        controller,
        source,
        scenario.name,
        int(seed),
        metrics,
        times[keep[:m]],
        tr_p[:m],
        refs.position[keep[:m]],
        pos_err[keep[:m]],
        tilt[keep[:m]],
        tr_wz[:m],
        f_hist[keep[:m]],
        tr_eta_hat[:m],
        tr_eta[:m],
        modes,
        _switch_record(ctrl),
    )


def _switch_record(ctrl) -> dict | None:
    sw = getattr(ctrl, "switch", None)
    if sw is None:
        return None
    return {"rotor": sw.lost, "first_seen": sw.first_seen, "switched": sw.switched}
