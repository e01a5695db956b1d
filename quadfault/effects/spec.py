"""The effect registry and the ``quadfault simulate --effect`` syntax."""

from __future__ import annotations

import math

from quadfault.effects.registry import EFFECT_NAMES, EFFECTS
from quadfault.errors import ConfigError


def _one(key):
    return lambda v: {key: v[0]}


def _all(key):
    return lambda v: {key: tuple(v)}


def _rate_damping(v):
    if len(v) in (1, 3):
        return {"linear": tuple(v)}
    if len(v) == 2:
        return {"linear": v[0], "quadratic": v[1]}
    return {"linear": tuple(v[:3]), "quadratic": tuple(v[3:])}


#: name -> (allowed counts of positional values, values -> constructor keywords, syntax)
POSITIONAL = {
    "motor_efficiency": ((1, 4), _all("eta"), "ETA or ETA1,ETA2,ETA3,ETA4 [-]"),
    "thrust_scale": ((1,), _one("scale"), "SCALE [-]"),
    "drag": ((1, 3), _all("k"), "K or KX,KY,KZ [N s/m]"),
    "motor_lag": ((1,), _one("tau"), "TAU [s]"),
    "delay": ((1,), _one("delay"), "DELAY [s]"),
    "wind": ((3,), _all("velocity"), "VX,VY,VZ [m/s]"),
    "ground_effect": ((1,), _one("rotor_radius"), "RADIUS [m]"),
    "com_offset": ((2,), _all("offset"), "RX,RY [m]"),
    "inertia": ((1, 3), _all("scale"), "S or SX,SY,SZ [-]"),
    "blade_flapping": ((1, 2), lambda v: {"k_force": v[0], "k_moment": v[1] if len(v) > 1 else 0.0},
                       "K_FORCE[,K_MOMENT] [s/m, s]"),
    "rotor_inertia": ((1,), _one("kappa"), "KAPPA [m s]"),
    "battery_thrust": ((1,), _one("exponent"), "EXPONENT [-]"),
    "thrust_curve": ((3,), _all("curve"), "A,B,C (f' = A + B f + C f^2) [N, -, 1/N]"),
    "mass": ((1,), _one("scale"), "SCALE [-]"),
    "rate_damping": ((1, 2, 3, 6), _rate_damping,
                     "D1 | D1,D2 | D1X,D1Y,D1Z | D1X,D1Y,D1Z,D2X,D2Y,D2Z [N m s/rad, N m s^2/rad^2]"),
}
#: keyword options of each ``--effect`` spec -> their type
KEYWORDS = {
    "wind": {"gust": float, "gust_tau": float, "k": float, "seed": int},
    "ground_effect": {"ground_z": float},
    "battery_thrust": {"v_start": float, "v_end": float, "duration": float, "v_ref": float},
}


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
        raise ConfigError(f"effect {name}: the range {tok!r} needs a random generator (it is "
                          "drawn when an environment resets)")
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
    allowed = KEYWORDS.get(name, {})
    for tok in (s.strip() for s in rest.split(",")):
        if "=" in tok:
            key, _, val = tok.partition("=")
            if key not in allowed:
                raise ConfigError(f"effect {name}: unknown option {key!r} "
                                  f"(options: {', '.join(allowed) or 'none'})")
            if allowed[key] is int:
                try:
                    kwargs[key] = int(val)
                except ValueError:
                    raise ConfigError(f"effect {name}: option {key} needs an integer, "
                                      f"got {val!r}") from None
            else:
                kwargs[key] = _value(val, f"{name} option {key}", rng)
            continue
        values.append(_value(tok, name, rng))
    counts, build, syntax = POSITIONAL[name]
    if len(values) not in counts:
        raise ConfigError(f"effect {name} expects {' or '.join(map(str, counts))} value(s) "
                          f"({name}={syntax}), got {len(values)} in {spec!r}")
    if "k" in kwargs:
        kwargs["k"] = (kwargs["k"],) * 3
    return EFFECTS[name](**build(values), **kwargs)


def canonical_order(effects) -> tuple:
    """``effects`` sorted into the canonical chain (command -> thrust -> wrench -> body; the
    order within a stage kept), so a model means the same physics as the diagnosis' library."""
    return tuple(sorted(effects, key=lambda e: getattr(e, "order", 0)))
