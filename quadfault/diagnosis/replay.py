"""Open-loop replay of a recording's commands through the simulator's plant.

A check of a (calibrated) simulator against a flight it did not see: from recorded states,
the plant -- the nominal vehicle plus the given effects, exactly as ``quadfault simulate``
flies them -- integrates the recorded rotor commands open loop over short horizons, and the
states it reaches are compared with the recorded ones.
"""

from __future__ import annotations

import numpy as np

from quadfault.errors import ConfigError
from quadfault.model.dynamics import RigidBodyState
from quadfault.model.flight import Flight
from quadfault.model.motors import MotorModel
from quadfault.model.plant import Plant
from quadfault.model.rotation import rotation_angle


# the simulator's plant, one step at a time: the only calls into it ----------------------
class _OpenLoop:
    """The plant (nominal motors without noise, efficiency 1, the given effects) flown by the
    one closed loop (:class:`quadfault.model.flight.Flight`) without a controller: the recorded
    command of each row held over that row's interval."""

    def __init__(self, vehicle, effects, dt):
        self.plant = Plant(vehicle, MotorModel(0.0, True), tuple(effects), dt=dt)
        self.flight = Flight(self.plant, record_accel=False)
        self.flight.reset(0)  # noise-free: never drawn from

    def reset(self, state) -> None:
        """Start from ``state``: the effects' memory cleared, the flown vehicle set."""
        self.plant.reset(state)

    def set_state(self, state) -> None:
        self.flight.set_state(state)

    def check(self) -> None:
        """A one-line error if a delay lost history (intervals much shorter than ``dt``)."""
        self.plant.check_effects()

    def step(self, f_cmd, t, dt):
        """One physics step of the command ``f_cmd`` held from ``t`` for ``dt``; the new
        state."""
        self.flight.step_at(f_cmd, t, dt)
        return self.flight.state()


def _plant(vehicle, effects, dt):
    return _OpenLoop(vehicle, effects, dt)


def _warm(plant, state, f_cmd, t, dt) -> None:
    """Advance the effects' memory by one step of command ``f_cmd`` from ``state``."""
    plant.set_state(state)
    plant.step(f_cmd, t, dt)


def _step(plant, f_cmd, t, dt):
    """One physics step of the plant with command ``f_cmd`` held; its new state."""
    return plant.step(f_cmd, t, dt)


def _state(rec, k):
    return RigidBodyState(
        rec.position[k].copy(), rec.velocity[k].copy(), rec.rotation[k].copy(), rec.omega[k].copy()
    )


def replay_errors(
    recording,
    vehicle,
    effects=(),
    horizons=(0.05, 0.1, 0.2, 0.5),
    *,
    starts: int = 40,
    span=None,
    warmup: float = 0.3,
) -> dict:
    """Open-loop prediction errors of the plant ``vehicle`` + ``effects`` on ``recording``.

    From ``starts`` evenly spaced rows inside ``span = (t0, t1)`` [s] (default: the whole
    recording) the plant starts at the recorded state and flies the recorded commands (held
    from row to row, saturated like the nominal motor model) for the longest horizon; effects
    with memory (lag, delay) first run over the ``warmup`` [s] of commands before the start.
    Stretches with a gap (an interval over 2.5 times the median) are skipped.

    Returns ``{"horizons_s": [...], "starts": n, "position_rmse_m": [...],
    "velocity_rmse_m_per_s": [...], "attitude_rmse_deg": [...]}`` (one RMS over the starts per
    horizon).
    """
    if not recording.has_pose:
        raise ConfigError(
            "open-loop replay needs a recording with pose (position, velocity, attitude)"
        )
    t = recording.t
    dt = np.diff(t)
    med = float(np.median(dt))
    steps = [max(1, round(h / med)) for h in horizons]
    nh, nw = max(steps), round(warmup / med)
    t0, t1 = (t[0], t[-1]) if span is None else span
    bad = np.r_[0, np.cumsum(dt > 2.5 * med)]
    k = np.arange(nw, len(t) - nh)
    ok = k[(t[k] >= t0) & (t[k + nh] <= t1) & (bad[k + nh] == bad[k - nw])]
    if len(ok) == 0:
        raise ConfigError(f"no stretch of {nh} rows without gaps to replay in {t0:g}-{t1:g} s")
    rows = ok[np.unique(np.linspace(0, len(ok) - 1, min(starts, len(ok))).astype(int))]
    err = {key: np.zeros((len(rows), len(steps))) for key in ("p", "v", "a")}
    for i, k in enumerate(rows):
        plant = _plant(vehicle, effects, med)
        plant.reset(_state(recording, k - nw))
        for j in range(k - nw, k):  # the effects' memory: commands before the start
            _warm(plant, _state(recording, j), recording.thrust_cmd[j], float(t[j]), float(dt[j]))
        plant.set_state(_state(recording, k))
        for j in range(nh):
            s = _step(plant, recording.thrust_cmd[k + j], float(t[k + j]), float(dt[k + j]))
            for h, n in enumerate(steps):
                if n == j + 1:
                    r = k + n
                    err["p"][i, h] = np.linalg.norm(s.p - recording.position[r])
                    err["v"][i, h] = np.linalg.norm(s.v - recording.velocity[r])
                    err["a"][i, h] = np.degrees(rotation_angle(s.R.T @ recording.rotation[r]))
        plant.check()

    def rms(x):
        return np.sqrt(np.mean(x**2, axis=0)).tolist()

    return {
        "horizons_s": [n * med for n in steps],
        "starts": len(rows),
        "position_rmse_m": rms(err["p"]),
        "velocity_rmse_m_per_s": rms(err["v"]),
        "attitude_rmse_deg": rms(err["a"]),
    }
