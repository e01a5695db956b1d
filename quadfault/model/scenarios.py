"""Motor-efficiency scenarios: battery degradation, abrupt faults, constant levels.

Profiles are small frozen dataclasses evaluated at a time (or an array of times) and
composed by :class:`EfficiencySchedule`: a base profile, then faults applied in order
(by default a fault *overrides* the efficiency of its motor, as in the reference code).

Named scenarios (:func:`named_scenario`) follow the reference schedule
(``seed-matlab-facts.md`` section 2): 80 s; battery voltage 12 V -> 11 V linearly;
``eta = eta0 exp(xi (V - V0))`` with xi = 0.25, eta0 = 1; motor k at eta = 0.5 from sample
``m_k * round(N/12)`` for ``round(N/24)`` samples (m = 1, 4, 7, 10), i.e. 6.667 s,
26.668 s, 46.669 s and 66.670 s for 3.333 s each at 1 kHz.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from quadfault.errors import ConfigError
from quadfault.model.trajectory import Circle, Hover, Lissajous, Trajectory

N_MOTORS = 4


class EfficiencyProfile(Protocol):
    def __call__(self, t) -> np.ndarray:
        """Efficiency ``(..., 4)`` at time(s) ``t`` [s]."""


def _times(t) -> np.ndarray:
    return np.asarray(t, dtype=float)


def at_times(fn, times) -> np.ndarray | tuple:
    """``fn`` (a function of time: an efficiency schedule, a trajectory) on a 1-D array of
    ``times`` [s]: one vectorised call when ``fn`` takes arrays, else one call per time.
    Returns its array (or tuple of arrays) with a leading axis of ``len(times)``."""
    times = np.asarray(times, dtype=float)
    try:
        out = fn(times)
        parts = out if isinstance(out, tuple) else (out,)
        if all(np.ndim(a) >= 2 and np.shape(a)[0] == len(times) for a in parts):
            return out
    except (TypeError, ValueError, IndexError):
        pass
    each = [fn(float(t)) for t in times]
    if isinstance(each[0], tuple):
        return type(each[0])(
            *(np.array([np.asarray(e[j], dtype=float) for e in each]) for j in range(len(each[0])))
        )
    return np.array([np.asarray(e, dtype=float) for e in each])


@dataclass(frozen=True)
class ConstantEfficiency:
    """Fixed per-motor efficiency."""

    levels: tuple = (1.0, 1.0, 1.0, 1.0)

    def __post_init__(self):
        lv = tuple(float(x) for x in self.levels)
        if len(lv) != N_MOTORS or any(not (0.0 <= x <= 1.5) for x in lv):
            raise ConfigError(
                f"efficiency levels must be 4 values in [0, 1.5], got {self.levels!r}"
            )
        object.__setattr__(self, "levels", lv)

    def __call__(self, t) -> np.ndarray:
        t = _times(t)
        return np.broadcast_to(np.asarray(self.levels), t.shape + (N_MOTORS,)).copy()


@dataclass(frozen=True)
class LinearVoltage:
    """Battery voltage falling linearly from ``v_start`` to ``v_end`` over ``duration`` [s]."""

    v_start: float = 12.0
    v_end: float = 11.0
    duration: float = 80.0

    def __call__(self, t) -> np.ndarray:
        frac = np.clip(_times(t) / self.duration, 0.0, 1.0)
        return self.v_start + (self.v_end - self.v_start) * frac


@dataclass(frozen=True)
class VoltageDegradation:
    """``eta_i(t) = eta0_i exp(xi (V(t) - V0))`` (paper Sec. IV-A), V0 = V(0) by default."""

    voltage: LinearVoltage = field(default_factory=LinearVoltage)
    xi: float = 0.25  # voltage sensitivity [1/V]
    eta0: tuple = (1.0, 1.0, 1.0, 1.0)
    v0: float | None = None

    def __call__(self, t) -> np.ndarray:
        v0 = self.voltage.v_start if self.v0 is None else self.v0
        scale = np.exp(self.xi * (self.voltage(t) - v0))
        return scale[..., None] * np.asarray(self.eta0, dtype=float)


@dataclass(frozen=True)
class AbruptFault:
    """Motor ``motor`` (1-based) at efficiency ``level`` on ``[onset, onset + duration]`` [s].

    ``ramp`` > 0 [s] makes the change progressive (linear) instead of a step.
    ``mode`` ``"override"`` sets the efficiency (reference code); ``"multiply"`` scales it.
    """

    motor: int
    onset: float
    duration: float = math.inf
    level: float = 0.5
    ramp: float = 0.0
    mode: str = "override"

    def __post_init__(self):
        if self.motor not in (1, 2, 3, 4):
            raise ConfigError(f"fault motor must be 1..4, got {self.motor!r}")
        if not (0.0 <= self.level <= 1.5):
            raise ConfigError(f"fault level must be in [0, 1.5], got {self.level!r}")
        if self.duration < 0 or self.ramp < 0:
            raise ConfigError("fault duration and ramp must be >= 0")
        if self.mode not in ("override", "multiply"):
            raise ConfigError(f"fault mode must be 'override' or 'multiply', got {self.mode!r}")

    @property
    def end(self) -> float:
        return self.onset + self.duration

    def active(self, t) -> np.ndarray:
        t = _times(t)
        tol = 1e-9
        return (t >= self.onset - tol) & (t <= self.end + tol)

    def apply(self, t, eta: np.ndarray) -> np.ndarray:
        t = _times(t)
        act = self.active(t)
        if self.ramp > 0:
            frac = np.clip((t - self.onset) / self.ramp, 0.0, 1.0)
        else:
            frac = np.ones_like(t)
        i = self.motor - 1
        base = eta[..., i]
        target = self.level if self.mode == "override" else base * self.level
        new = base + frac * (target - base)
        eta = eta.copy()
        eta[..., i] = np.where(act, new, base)
        return eta


@dataclass(frozen=True)
class EfficiencySchedule:
    """A base profile followed by faults applied in order."""

    base: EfficiencyProfile = field(default_factory=ConstantEfficiency)
    faults: tuple = ()

    def __call__(self, t) -> np.ndarray:
        eta = np.asarray(self.base(t), dtype=float)
        for fault in self.faults:
            eta = fault.apply(t, eta)
        return eta

    def fault_windows(self) -> list[tuple[int, float, float]]:
        """``[(motor, t_start, t_end), ...]`` of the abrupt faults (for scoring)."""
        return [(f.motor, f.onset, f.end) for f in self.faults]


def reference_fault_schedule(duration: float = 80.0, dt: float = 1e-3, level: float = 0.5):
    """The reference code's four fault windows (motor k at multiple m_k = 1, 4, 7, 10)."""
    n = int(round(duration / dt))
    div12, div24 = round(n / 12), round(n / 24)
    return tuple(
        AbruptFault(motor=k + 1, onset=m * div12 * dt, duration=div24 * dt, level=level)
        for k, m in enumerate((1, 4, 7, 10))
    )


@dataclass(frozen=True)
class Scenario:
    """Everything that defines a flight except the vehicle and the random seed.

    Attributes:
        name: identifier.
        duration: flight time [s].
        efficiency: efficiency schedule of the true motors.
        trajectory: reference trajectory for the controller.
        thrust_noise: sigma_f of the multiplicative thrust noise.
        voltage: battery voltage profile (recorded as ``vbat``), or None.
        ground_altitude: altitude ``-p_z`` of the ground [m] (NED), or None (no ground): a
            simulated flight that goes below it ends there (:func:`quadfault.sim.simulator.flight_end`).
    """

    name: str
    duration: float
    efficiency: EfficiencySchedule
    trajectory: Trajectory
    thrust_noise: float = 0.07
    voltage: LinearVoltage | None = None
    ground_altitude: float | None = 0.0

    def replace(self, **changes) -> Scenario:
        return replace(self, **changes)

    def fault_windows(self):
        return self.efficiency.fault_windows()


SCENARIO_NAMES = (
    "nominal",
    "degradation",
    "abrupt",
    "combined",
    "clipping",
    "hover",
    "hover_fault",
    "lissajous",
)
#: the paper's fault scenarios: flown without an upper thrust limit, as in the paper (its rotors at
#: eta = 0.5 on the circle need more than thrust-to-weight 2)
PAPER_SCENARIOS = ("degradation", "abrupt", "combined")

#: The clipping scenario: a circle twice as fast (centripetal 4.7 m/s^2) and faults to 0.6, so
#: with the default f_max (thrust-to-weight 2) the weak motor's command saturates in part of
#: its fault window (0-36 % of the samples over seeds 0-2) while the plain geometric controller
#: stays in control (max tracking error ~0.2 m). Deeper faults (0.5) on this circle make the
#: plain controller lose the vehicle once the weak motor stays saturated.
CLIPPING_FREQUENCY = 0.2  # [Hz] circle frequency
CLIPPING_LEVEL = 0.6  # efficiency of the faulted motor


def named_scenario(name: str, duration: float | None = None, dt: float = 1e-3) -> Scenario:
    """A named scenario. ``duration`` defaults to 80 s (the reference schedule)."""
    if name not in SCENARIO_NAMES:
        raise ConfigError(f"unknown scenario {name!r}; choose from {', '.join(SCENARIO_NAMES)}")
    T = 80.0 if duration is None else float(duration)
    if not (T > 0 and math.isfinite(T)):
        raise ConfigError(f"duration must be positive [s], got {duration!r}")
    circle = Circle()
    voltage = LinearVoltage(duration=T)
    # Fault windows scale with the duration, like the reference's round(N/12) arithmetic.
    faults = reference_fault_schedule(T, dt)
    if name == "nominal":
        return Scenario(name, T, EfficiencySchedule(), circle)
    if name == "degradation":
        return Scenario(
            name, T, EfficiencySchedule(VoltageDegradation(voltage)), circle, voltage=voltage
        )
    if name == "abrupt":
        return Scenario(name, T, EfficiencySchedule(ConstantEfficiency(), faults), circle)
    if name == "combined":
        return Scenario(
            name,
            T,
            EfficiencySchedule(VoltageDegradation(voltage), faults),
            circle,
            voltage=voltage,
        )
    if name == "clipping":
        deep = tuple(replace(f, level=CLIPPING_LEVEL) for f in faults)
        return Scenario(
            name,
            T,
            EfficiencySchedule(ConstantEfficiency(), deep),
            Circle(frequency=CLIPPING_FREQUENCY),
        )
    if name == "hover":
        return Scenario(name, T, EfficiencySchedule(), Hover())
    if name == "hover_fault":
        return Scenario(
            name,
            T,
            EfficiencySchedule(
                ConstantEfficiency(), (AbruptFault(motor=1, onset=0.3 * T, level=0.5),)
            ),
            Hover(),
        )
    # lissajous: a figure-eight that excites all axes, with a single fault
    return Scenario(
        name,
        T,
        EfficiencySchedule(ConstantEfficiency(), (AbruptFault(motor=2, onset=0.5 * T, level=0.6),)),
        Lissajous(),
    )


def random_scenario(
    rng: np.random.Generator,
    duration: float = 20.0,
    *,
    n_faults: tuple = (0, 2),
    severity: tuple = (0.3, 0.9),
    degradation_prob: float = 0.5,
    xi_range: tuple = (0.1, 0.4),
    thrust_noise: tuple = (0.0, 0.1),
    trajectory: str = "random",
    ramp_prob: float = 0.25,
) -> Scenario:
    """A seeded random scenario: motors, onsets, severities, degradation rate and noise."""
    if duration <= 0:
        raise ConfigError("duration must be positive")
    k = int(rng.integers(n_faults[0], n_faults[1] + 1))
    faults = []
    for _ in range(k):
        onset = float(rng.uniform(0.1, 0.8) * duration)
        faults.append(
            AbruptFault(
                motor=int(rng.integers(1, 5)),
                onset=onset,
                duration=float(rng.choice([math.inf, rng.uniform(0.1, 0.5) * duration])),
                level=float(rng.uniform(*severity)),
                ramp=float(rng.uniform(0.0, 2.0)) if rng.random() < ramp_prob else 0.0,
            )
        )
    voltage = None
    base: EfficiencyProfile
    if rng.random() < degradation_prob:
        voltage = LinearVoltage(12.0, float(rng.uniform(10.5, 11.8)), duration)
        base = VoltageDegradation(voltage, xi=float(rng.uniform(*xi_range)))
    else:
        base = ConstantEfficiency()
    if trajectory == "random":
        trajectory = str(rng.choice(["circle", "hover", "lissajous"]))
    traj: Trajectory
    if trajectory == "circle":
        traj = Circle(radius=float(rng.uniform(1.0, 3.0)), frequency=float(rng.uniform(0.05, 0.15)))
    elif trajectory == "hover":
        traj = Hover()
    elif trajectory == "lissajous":
        traj = Lissajous(
            amplitude=(float(rng.uniform(0.5, 2.0)), float(rng.uniform(0.5, 2.0)), 0.2)
        )
    else:
        raise ConfigError(f"unknown trajectory {trajectory!r}")
    return Scenario(
        "random",
        float(duration),
        EfficiencySchedule(base, tuple(faults)),
        traj,
        thrust_noise=float(rng.uniform(*thrust_noise)),
        voltage=voltage,
    )
