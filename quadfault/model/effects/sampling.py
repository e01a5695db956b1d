"""Domain randomisation: the physics of each episode drawn from ranges or from a fitted model.

:class:`PhysicsDraws` is what an environment holds: the ``quadfault simulate --effect`` specs
of its ``effects`` keyword, where any value may be a range ``a:b`` drawn uniformly at every
reset (e.g. ``["drag=0.1:0.5", "motor_lag=0.01:0.05", "wind=-2:2,-2:2,0"]``), and optionally
a diagnosis' fitted model (:func:`quadfault.model.effects.model.from_diagnosis`, the loader
``quadfault simulate --model`` uses) whose parameters are either flown as fitted or, with
``uncertainty=True``, drawn from their reported one-sigma uncertainty
(:meth:`~quadfault.model.effects.model.DiagnosedModel.sample`). :meth:`PhysicsDraws.draw` takes
the episode's generator and returns the effects in canonical order; :func:`describe` says
what was drawn (``info["effects"]``).

Draw order on the generator (what makes a single env and its vector twin equal): the
model's parameters (in the model's canonical order, each parameter's normals in its
reported order), then every spec in the order given, each ``a:b`` value in the order it is
written. Mass, inertia and delay (latency) are effects too (``mass=0.8:1.2``,
``inertia=0.9:1.1,0.9:1.1,0.8:1.2``, ``delay=0:0.02``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadfault.errors import ConfigError
from quadfault.model.effects.model import DiagnosedModel, from_diagnosis
from quadfault.model.effects.spec import canonical_order, parse_effect


class _Edge:
    """A stand-in generator whose ``uniform(lo, hi)`` returns one end of the range: parsing a
    spec at both ends checks every value of its ranges (the effects' bounds are intervals)."""

    def __init__(self, high: bool):
        self.high = high

    def uniform(self, lo, hi):
        return float(hi if self.high else lo)


def _specs(effects) -> tuple:
    if effects is None:
        return ()
    if isinstance(effects, str):
        effects = (effects,)
    if not isinstance(effects, (list, tuple)) or not all(isinstance(s, str) for s in effects):
        raise ConfigError(
            f"effects must be a list of 'NAME=VALUES' strings (the quadfault "
            f"simulate --effect syntax), got {effects!r}"
        )
    return tuple(effects)


@dataclass(frozen=True)
class PhysicsDraws:
    """The randomised physics of an environment's episodes.

    Attributes:
        specs: ``--effect`` specs, values or ranges ``a:b`` (uniform draws at each reset).
        model: a fitted model (:class:`~quadfault.model.effects.model.DiagnosedModel`) or None.
        uncertainty: draw the model's parameters from their reported uncertainty at each
            reset (False: fly the fitted values).
    """

    specs: tuple = ()
    model: DiagnosedModel | None = None
    uncertainty: bool = False

    @classmethod
    def of(cls, effects=None, model=None, uncertainty: bool = False) -> PhysicsDraws | None:
        """Checked draws from an env's keywords (``effects``: a list of specs; ``model``: a
        diagnosis JSON path, its parsed object or a loaded model; ``uncertainty``), or None
        when there is nothing to draw (the nominal physics). Bad input: a one-line
        :class:`~quadfault.errors.ConfigError`."""
        specs = _specs(effects)
        if not isinstance(uncertainty, (bool, np.bool_)):
            raise ConfigError(f"model_uncertainty must be True or False, got {uncertainty!r}")
        if uncertainty and model is None:
            raise ConfigError("model_uncertainty=True needs a model (model='diagnosis.json')")
        if model is not None and not isinstance(model, DiagnosedModel):
            model = from_diagnosis(model)
        if not specs and model is None:
            return None
        out = cls(specs, model, bool(uncertainty))
        for edge in (_Edge(False), _Edge(True)):  # every value of every range is valid
            out._effects(edge)
        return out

    @property
    def vehicle(self):
        """The nominal vehicle of the model (None without one)."""
        return None if self.model is None else self.model.vehicle

    def _effects(self, rng) -> tuple:
        effects = []
        if self.model is not None:
            effects += list(
                self.model.sample(rng)
                if self.uncertainty and not isinstance(rng, _Edge)
                else self.model.effects
            )
        effects += [parse_effect(s, rng) for s in self.specs]
        names = [e.name for e in effects]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ConfigError(f"effect {twice[0]} given twice (in model and effects, or twice)")
        return canonical_order(effects)

    def draw(self, rng: np.random.Generator) -> tuple:
        """One episode's effects (canonical order), drawn from ``rng``."""
        return self._effects(rng)


def describe(effects) -> list:
    """What was drawn: ``[{"name", "params"}, ...]`` (the keys of the effects' ``params()``,
    as a recording's meta and the diagnosis report them)."""
    return [e.describe() for e in effects]


__all__ = ["PhysicsDraws", "describe"]
