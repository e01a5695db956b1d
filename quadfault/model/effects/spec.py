"""The ``quadfault simulate --effect`` syntax: ``NAME=V1[,V2...][,key=value...]``.

Each effect class says what its values mean (``values``, ``syntax``, ``options`` and
``from_values``); the names come from the registry (:mod:`quadfault.model.effects.registry`).
"""

from __future__ import annotations

import math

from quadfault.errors import ConfigError
from quadfault.model.effects.registry import EFFECT_NAMES, EFFECTS


def _value(tok: str, name: str, rng):
    """A number, or ``a:b`` -- a uniform draw from ``rng`` (environments draw at reset)."""
    lo, sep, hi = tok.partition(":")
    try:
        vals = [float(lo)] + ([float(hi)] if sep else [])
    except ValueError:
        raise ConfigError(f"effect {name}: not a number: {tok!r}") from None
    if not all(math.isfinite(v) for v in vals):
        raise ConfigError(f"effect {name}: values must be finite, got {tok!r}")
    if not sep:
        return vals[0]
    if rng is None:
        raise ConfigError(
            f"effect {name}: the range {tok!r} needs a random generator (it is "
            "drawn when an environment resets)"
        )
    if vals[0] > vals[1]:
        raise ConfigError(f"effect {name}: range {tok!r} needs low <= high")
    return float(rng.uniform(vals[0], vals[1]))


def parse_effect(spec: str, rng=None):
    """An effect from ``NAME=V1[,V2...][,key=value...]``, e.g. ``drag=0.3``,
    ``wind=2,0,0,gust=0.5``, ``motor_efficiency=1,1,0.7,1``, ``blade_flapping=0.05,0.002``.

    A value ``a:b`` is drawn uniformly from ``rng`` (a ``numpy.random.Generator``)."""
    if not isinstance(spec, str) or "=" not in spec:
        raise ConfigError(f"--effect expects NAME=VALUES, got {spec!r}")
    name, _, rest = spec.partition("=")
    name = name.strip().replace("-", "_")
    if name not in EFFECTS:
        raise ConfigError(f"unknown effect {name!r}; choose from {', '.join(EFFECT_NAMES)}")
    values, kwargs = [], {}
    cls = EFFECTS[name]
    allowed = cls.options
    for tok in (s.strip() for s in rest.split(",")):
        if "=" in tok:
            key, _, val = tok.partition("=")
            if key not in allowed:
                raise ConfigError(
                    f"effect {name}: unknown option {key!r} "
                    f"(options: {', '.join(allowed) or 'none'})"
                )
            if allowed[key] is int:
                try:
                    kwargs[key] = int(val)
                except ValueError:
                    raise ConfigError(
                        f"effect {name}: option {key} needs an integer, got {val!r}"
                    ) from None
            else:
                kwargs[key] = _value(val, f"{name} option {key}", rng)
            continue
        values.append(_value(tok, name, rng))
    if len(values) not in cls.values:
        raise ConfigError(
            f"effect {name} expects {' or '.join(map(str, cls.values))} value(s) "
            f"({name}={cls.syntax}), got {len(values)} in {spec!r}"
        )
    return cls.from_values(values, kwargs)


def canonical_order(effects) -> tuple:
    """``effects`` sorted into the canonical chain (command -> thrust -> wrench -> body; the
    order within a stage kept), so a model means the same physics as the diagnosis' library."""
    return tuple(sorted(effects, key=lambda e: getattr(e, "order", 0)))
