"""The registry of effects: one table names every effect; codes and lookups derive from it.

:data:`TABLE` lists the effect classes, one module each (``quadfault/model/effects/<name>.py``:
the parameters, the kernels, the packing into the compiled chain, the diagnosis' candidate,
what a recording needs). An effect's code is its row in the table, never written by hand;
the compiled (numba) chain reads each effect's kernels and declared layout from its module
(:mod:`quadfault.model.effects.chain`). The order of the rows is the order of the diagnosis'
library. Everything that needs to know the effects -- the ``--effect`` parser, the diagnosis
JSON loader, the compiled chain, the diagnosis' library and its identifiability gate -- reads
them from here:

* :func:`names` -- the canonical names, in table order;
* :func:`effect_class` -- the class of a name (a one-line :class:`~quadfault.errors.ConfigError`
  for an unknown one);
* :func:`identifiability` -- what a recording needs for the effect to be identifiable
  (:class:`~quadfault.model.effects.base.Identifiability`: channel groups that must be present,
  alternatives, the lowest command rate, the time-scale parameter the samples must resolve,
  channels that show it directly, the excitation it needs, a note for users);
* :func:`code` -- the effect's code.

Example::

    from quadfault.model.effects.registry import identifiability
    need = identifiability("motor_lag")
    need.channels, need.min_command_rate, need.timescale, need.direct   # (), 20.0, 'tau_s', ...
"""

from __future__ import annotations

from quadfault.errors import ConfigError
from quadfault.model.effects.base import Identifiability
from quadfault.model.effects.battery_thrust import BatteryThrust
from quadfault.model.effects.blade_flapping import BladeFlapping
from quadfault.model.effects.com_offset import ComOffset
from quadfault.model.effects.delay import Delay
from quadfault.model.effects.drag import Drag
from quadfault.model.effects.ground_effect import GroundEffect
from quadfault.model.effects.inertia import Inertia
from quadfault.model.effects.mass import Mass
from quadfault.model.effects.motor_efficiency import MotorEfficiency
from quadfault.model.effects.motor_lag import MotorLag
from quadfault.model.effects.rate_damping import RateDamping
from quadfault.model.effects.rotor_inertia import RotorInertia
from quadfault.model.effects.thrust_curve import ThrustCurve
from quadfault.model.effects.thrust_scale import ThrustScale
from quadfault.model.effects.wind import Wind

#: every effect, one row each; an effect's code is its row
TABLE = (
    MotorEfficiency,
    ThrustScale,
    GroundEffect,
    Delay,
    MotorLag,
    Drag,
    Wind,
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
        raise ConfigError(
            f"unknown effect {name!r}; choose from {', '.join(EFFECT_NAMES)}"
        ) from None


def code(name: str) -> int:
    """The effect's code: its row in :data:`TABLE`."""
    return TABLE.index(effect_class(name))


def identifiability(name: str) -> Identifiability:
    """What a recording needs for effect ``name`` to be identifiable."""
    return effect_class(name).identifiability


def equivalence_classes() -> dict:
    """``{name: class}`` of the effects the data cannot always tell apart (each effect's
    ``equivalent``; docs/effects.md, "What the data cannot tell apart")."""
    return {cls.name: cls.equivalent for cls in TABLE if cls.equivalent is not None}


__all__ = [
    "TABLE",
    "EFFECTS",
    "EFFECT_NAMES",
    "names",
    "effect_class",
    "code",
    "identifiability",
    "equivalence_classes",
]
