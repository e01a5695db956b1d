"""Where an episode's scenario comes from: a name, a ``Scenario``, or a generator drawn from at
every reset with the env's generator (``"random"``, ``"track"``, ``"rotor_loss"``)."""

from __future__ import annotations

import numpy as np

from quadfault.errors import ConfigError
from quadfault.model.scenarios import SCENARIO_NAMES, Scenario, named_scenario, random_scenario
from quadfault.model.task_scenarios import rotor_loss_scenario, track_scenario

#: scenario generators drawn from at every reset (``scenario=`` one of these)
GENERATORS = ("random", "track", "rotor_loss")
#: keywords of ``scenario_options`` per generator (``quadfault.model.task_scenarios``)
SCENARIO_OPTIONS = {
    "track": ("speed", "curvature", "yaw_rate", "altitude", "degradation", "level", "onset"),
    "rotor_loss": ("level", "onset", "altitude"),
}
#: the generator behind each name that takes ``scenario_options``
_DRAWS = {"track": track_scenario, "rotor_loss": rotor_loss_scenario}


def check_scenario_options(options, scenario) -> dict:
    """Validate ``scenario_options`` (keywords of the ``track`` / ``rotor_loss`` generators;
    None: their defaults) by drawing one scenario with them."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise ConfigError(f"scenario_options must be a dict, got {options!r}")
    if scenario not in SCENARIO_OPTIONS:
        raise ConfigError(
            f"scenario_options applies to scenario 'track' or 'rotor_loss', not {scenario!r}"
        )
    unknown = sorted(set(options) - set(SCENARIO_OPTIONS[scenario]))
    if unknown:
        raise ConfigError(
            f"scenario_options has unknown keys {unknown} for {scenario!r}; "
            f"choose from {', '.join(SCENARIO_OPTIONS[scenario])}"
        )
    try:
        _DRAWS[scenario](np.random.default_rng(0), **options)  # ranges checked once, here
    except TypeError as err:
        raise ConfigError(f"scenario_options: {err}") from None
    return dict(options)


def make_scenario(
    spec,
    rng: np.random.Generator,
    *,
    duration: float,
    dt: float,
    vehicle,
    random_trajectory: str,
    random_faults: dict,
    scenario_options: dict,
    thrust_noise: float | None,
) -> Scenario:
    """The scenario of an episode: ``spec`` a ``Scenario`` (kept, with its own duration), a
    name of ``SCENARIO_NAMES`` or a generator of :data:`GENERATORS` (drawn from ``rng``);
    ``thrust_noise`` (not None) overrides the scenario's sigma_f."""
    if isinstance(spec, Scenario):
        sc = spec
    elif spec == "random":
        sc = random_scenario(rng, duration, trajectory=random_trajectory, **random_faults)
    elif spec in _DRAWS:
        sc = _DRAWS[spec](rng, duration, vehicle=vehicle, **scenario_options)
    elif isinstance(spec, str) and spec in SCENARIO_NAMES:
        sc = named_scenario(spec, duration, dt)
    else:
        raise ConfigError(
            f"options['scenario'] must be a scenario name, one of {GENERATORS} or "
            f"a Scenario, got {spec!r}"
        )
    if thrust_noise is not None:
        sc = sc.replace(thrust_noise=thrust_noise)
    return sc


def fault_dict(f) -> dict:
    """An abrupt fault as the dict of ``info["faults"]`` / ``info["fault_events"]``."""
    return {"motor": f.motor, "onset": f.onset, "end": f.end, "level": f.level, "ramp": f.ramp}
