"""Flight metrics: tracking RMSE, crash, peak attitude error, energy, time to recover.

Definitions (all computed from the flown trace; truth is used only for *scoring*):

* **tracking RMSE** [m]: ``sqrt(mean |p - p_ref|^2)`` over the whole flight (up to a crash).
* **crash**: the flight is stopped and counted as crashed when the state becomes non-finite,
  the position error exceeds ``CrashLimits.max_position_error``, the tilt (angle between
  body z and world z) exceeds ``max_tilt``, or the vehicle goes below ``ground_z`` (NED).
* **peak attitude error** [deg]: the largest angle between the body z-axis ``b3`` and the
  desired ``b3d`` of eq. (9) -- the *tilt* error; heading is excluded because a
  fault-tolerant controller may give yaw up on purpose.
* **energy** [N s]: ``sum_k sum_i clip(f_cmd_i, 0, f_max) dt``, the commanded thrust
  integrated over time (an actuator-effort proxy; a weak motor driven hard costs energy
  even though it produces little thrust).
* **time to recover** [s], per fault onset ``t_f`` (scenario fault windows): the pre-fault
  level is the RMS position error over ``[t_f - pre_window, t_f)``; the threshold is
  ``max(ratio * level, floor)`` (ratio 1.5, floor 0.05 m). The recovery time is the time
  from ``t_f`` until the error is below the threshold and stays there for ``hold`` seconds
  (0 if it never leaves it), searched until the next onset or the end; ``inf`` if never.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadfault.errors import ConfigError


@dataclass(frozen=True)
class CrashLimits:
    """When a flight counts as crashed.

    Attributes:
        max_position_error: [m].
        max_tilt: [deg] angle between body z and world z.
        ground_z: world NED z of the ground [m]; ``p_z > ground_z`` is a crash
            (``math.inf`` disables it).

    The defaults equal the environment's ``TerminationLimits`` (5 m, 80 deg, altitude 0).
    """

    max_position_error: float = 5.0
    max_tilt: float = 80.0
    ground_z: float = 0.0

    def __post_init__(self):
        if not (self.max_position_error > 0 and 0 < self.max_tilt <= 180):
            raise ConfigError("crash limits: max_position_error > 0 and max_tilt in (0, 180]")


@dataclass(frozen=True)
class RecoveryConfig:
    """Parameters of the time-to-recover metric (see module docstring)."""

    ratio: float = 1.5
    floor: float = 0.05  # [m]
    pre_window: float = 2.0  # [s]
    hold: float = 0.5  # [s]


@dataclass(frozen=True)
class FlightMetrics:
    """Scores of one flight (see module docstring for the definitions)."""

    rmse: float  # [m]
    crashed: bool
    crash_time: float | None  # [s]
    peak_attitude_error: float  # [deg]
    energy: float  # [N s]
    recovery_times: tuple  # [s] per fault onset (inf = never)
    duration: float  # flown time [s]

    @property
    def mean_recovery(self) -> float:
        """Mean over the faults (nan without faults, inf if one never recovered)."""
        return float(np.mean(self.recovery_times)) if self.recovery_times else math.nan

    def to_dict(self) -> dict:
        def num(x):
            return None if x is None or not math.isfinite(x) else float(x)

        return {
            "rmse": num(self.rmse),
            "crashed": self.crashed,
            "crash_time": num(self.crash_time),
            "peak_attitude_error_deg": num(self.peak_attitude_error),
            "energy": num(self.energy),
            "recovery_times": [num(x) for x in self.recovery_times],
            "duration": self.duration,
        }


def tilt_angle(b3, b3d) -> np.ndarray:
    """Angle [deg] between unit vectors ``b3`` and ``b3d`` (``(..., 3)``)."""
    c = np.clip(np.sum(np.asarray(b3) * np.asarray(b3d), axis=-1), -1.0, 1.0)
    return np.degrees(np.arccos(c))


def recovery_times(t, pos_error, onsets, config: RecoveryConfig | None = None) -> tuple:
    """Time to recover [s] after each onset (see module docstring)."""
    cfg = config or RecoveryConfig()
    t = np.asarray(t, float)
    e = np.asarray(pos_error, float)
    onsets = sorted(float(x) for x in onsets)
    out = []
    for j, tf in enumerate(onsets):
        if tf <= t[0] or tf >= t[-1]:
            continue
        pre = (t >= tf - cfg.pre_window) & (t < tf)
        level = float(np.sqrt(np.mean(e[pre] ** 2))) if pre.any() else 0.0
        thr = max(cfg.ratio * level, cfg.floor)
        t_end = onsets[j + 1] if j + 1 < len(onsets) else t[-1]
        win = (t >= tf) & (t <= t_end)
        tw, ew = t[win], e[win]
        above = np.nonzero(ew >= thr)[0]
        if above.size == 0:
            out.append(0.0)
            continue
        last = above[-1]
        if last + 1 >= tw.size or tw[-1] - tw[last + 1] < cfg.hold - 1e-9:
            out.append(math.inf)  # still above, or not back long enough before the window ends
        else:
            out.append(float(tw[last + 1] - tf))
    return tuple(out)


def flight_metrics(
    t,
    pos_error,
    tilt_error,
    f_cmd,
    f_max,
    dt,
    crash_time,
    onsets,
    recovery: RecoveryConfig | None = None,
) -> FlightMetrics:
    """Scores from the per-step traces (``pos_error`` = |p - p_ref| [m], ``tilt_error`` [deg],
    ``f_cmd`` ``(n, 4)`` [N])."""
    e = np.asarray(pos_error, float)
    rmse = float(np.sqrt(np.mean(e**2))) if e.size else math.nan
    energy = float(np.sum(np.clip(f_cmd, 0.0, f_max)) * dt)
    peak = float(np.max(tilt_error)) if len(tilt_error) else math.nan
    rec = recovery_times(t, e, onsets, recovery) if len(t) > 1 else ()
    duration = float(t[-1] - t[0] + dt) if len(t) else 0.0
    return FlightMetrics(rmse, crash_time is not None, crash_time, peak, energy, rec, duration)


def held_after_loss(
    t: np.ndarray,
    pos_error: np.ndarray,
    onset: float,
    duration: float,
    radius: float = 1.0,
    settle: float = 2.0,
) -> bool:
    """Whether a flight held its hover point through a rotor loss: it lasted to
    ``duration`` [s] and the position error stayed within ``radius`` [m] from ``settle``
    [s] after the ``onset`` [s] to the end (the complete-loss task's success)."""
    t, e = np.asarray(t, float), np.asarray(pos_error, float)
    if t.size == 0 or t[-1] < duration - 0.05:  # crashed before the end
        return False
    late = e[t >= onset + settle]
    return bool(late.size and np.all(late <= radius))
