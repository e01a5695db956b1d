"""Scenario suites for evaluating agents.

A suite is a named tuple of :class:`SuiteEntry`; ``entry.scenario(seed)`` builds the scenario
for one evaluation seed (fixed scenarios ignore the seed, which then only seeds the thrust
noise; random ones draw the faults from ``numpy.random.default_rng(seed)``).

=============  ===========================================================================
suite          scenarios
=============  ===========================================================================
``paper``      ``abrupt`` and ``combined`` (the paper's 80 s circle, four 50 % faults)
``quick``      ``abrupt`` and ``combined`` shortened to 20 s (the fault windows scale),
               and ``single_0.3``
``severe``     ``single_0.3``: one motor at eta = 0.3 from 2 s on, circle, 10 s;
               ``hover_0.3``: the same at hover
``random``     three random scenarios per seed (faults, degradation, noise, trajectory)
``smoke``      ``abrupt`` shortened to 4 s (tests)
=============  ===========================================================================
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from quadfault.errors import ConfigError
from quadfault.model.scenarios import (
    AbruptFault,
    ConstantEfficiency,
    EfficiencySchedule,
    Scenario,
    named_scenario,
    random_scenario,
)
from quadfault.model.trajectory import Circle, Hover

#: Severity of the single-motor survival scenario (eta of the failed motor).
SEVERE_LEVEL = 0.3
SEVERE_ONSET = 2.0  # [s]


@dataclass(frozen=True)
class SuiteEntry:
    """One scenario of a suite: ``build(seed) -> Scenario``."""

    name: str
    build: Callable[[int], Scenario]

    def scenario(self, seed: int) -> Scenario:
        return self.build(seed).replace(name=self.name)


def single_motor_failure(
    level: float = SEVERE_LEVEL,
    duration: float = 10.0,
    motor: int = 1,
    onset: float = SEVERE_ONSET,
    hover: bool = False,
    thrust_noise: float = 0.07,
) -> Scenario:
    """One motor drops to ``level`` at ``onset`` [s] and stays there (circle or hover)."""
    traj = Hover() if hover else Circle()
    sched = EfficiencySchedule(ConstantEfficiency(), (AbruptFault(motor, onset, level=level),))
    return Scenario(f"single_{level:g}", duration, sched, traj, thrust_noise=thrust_noise)


def _named(name: str, duration: float | None = None):
    return lambda seed: named_scenario(name, duration)


def _random(index: int, duration: float = 10.0):
    def build(seed: int) -> Scenario:
        rng = np.random.default_rng([seed, index])
        return random_scenario(rng, duration, n_faults=(1, 2))

    return build


SUITES: dict[str, tuple[SuiteEntry, ...]] = {
    "paper": (SuiteEntry("abrupt", _named("abrupt")), SuiteEntry("combined", _named("combined"))),
    "quick": (
        SuiteEntry("abrupt_20s", _named("abrupt", 20.0)),
        SuiteEntry("combined_20s", _named("combined", 20.0)),
        SuiteEntry("single_0.3", lambda seed: single_motor_failure()),
    ),
    "severe": (
        SuiteEntry("single_0.3", lambda seed: single_motor_failure()),
        SuiteEntry("hover_0.3", lambda seed: single_motor_failure(hover=True)),
    ),
    "random": tuple(SuiteEntry(f"random_{i}", _random(i)) for i in range(3)),
    "smoke": (SuiteEntry("abrupt_4s", _named("abrupt", 4.0)),),
}


def get_suite(name: str, scenarios: list[str] | None = None) -> tuple[SuiteEntry, ...]:
    """Suite ``name``, optionally restricted to some of its scenario names."""
    if name not in SUITES:
        raise ConfigError(f"unknown suite {name!r}; choose from {', '.join(SUITES)}")
    suite = SUITES[name]
    if scenarios:
        known = {e.name for e in suite}
        missing = [s for s in scenarios if s not in known]
        if missing:
            raise ConfigError(
                f"suite {name!r} has no scenario {', '.join(missing)}; it has "
                f"{', '.join(sorted(known))}"
            )
        suite = tuple(e for e in suite if e.name in scenarios)
    return suite
