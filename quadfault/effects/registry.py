"""The registry of effects: one table names every effect; codes and lookups derive from it.

:data:`TABLE` lists the effect classes in the order of their codes (an effect's code is its
position in the table: never written by hand). Everything that needs to know the effects --
the ``--effect`` parser, the diagnosis JSON loader, the compiled chain, the diagnosis'
library and its identifiability gate -- reads them from here:

* :func:`names` -- the canonical names, in table order;
* :func:`effect_class` -- the class of a name (a one-line :class:`~quadfault.errors.ConfigError`
  for an unknown one);
* :func:`identifiability` -- what a recording needs for the effect to be identifiable
  (:class:`~quadfault.effects.base.Identifiability`: channel groups that must be present,
  alternatives, the lowest command rate, the time-scale parameter the samples must resolve,
  channels that show it directly, the excitation it needs, a note for users);
* :func:`code` -- the effect's code.

Example::

    from quadfault.effects.registry import identifiability
    need = identifiability("motor_lag")
    need.channels, need.min_command_rate, need.timescale, need.direct   # (), 20.0, 'tau_s', ...
"""

from __future__ import annotations

from quadfault.effects.base import Identifiability
from quadfault.effects.body import Inertia, Mass
from quadfault.effects.thrust import (
    BatteryThrust,
    Delay,
    GroundEffect,
    MotorEfficiency,
    MotorLag,
    ThrustCurve,
    ThrustScale,
)
from quadfault.effects.wrench import BladeFlapping, ComOffset, Drag, RateDamping, RotorInertia, Wind
from quadfault.errors import ConfigError

#: every effect, one row each; an effect's code is its row
TABLE = (
    MotorEfficiency,
    ThrustScale,
    Drag,
    MotorLag,
    Delay,
    Wind,
    GroundEffect,
    ComOffset,
    Inertia,
    BladeFlapping,
    RotorInertia,
    BatteryThrust,
    ThrustCurve,
    Mass,
    RateDamping,
)
#: name -> class, in table order
EFFECTS = {cls.name: cls for cls in TABLE}
EFFECT_NAMES = tuple(EFFECTS)


def names() -> tuple:
    """The canonical effect names, in table order."""
    return EFFECT_NAMES


def effect_class(name: str) -> type:
    """The effect class named ``name``."""
    try:
        return EFFECTS[name]
    except (KeyError, TypeError):
        raise ConfigError(f"unknown effect {name!r}; choose from {', '.join(EFFECT_NAMES)}") \
            from None


def code(name: str) -> int:
    """The effect's code: its row in :data:`TABLE`."""
    return TABLE.index(effect_class(name))


def identifiability(name: str) -> Identifiability:
    """What a recording needs for effect ``name`` to be identifiable."""
    return effect_class(name).identifiability


__all__ = ["TABLE", "EFFECTS", "EFFECT_NAMES", "names", "effect_class", "code",
           "identifiability"]
