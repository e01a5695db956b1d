"""The effect chain of the closed loop: the built-in effects of every vehicle, compiled.

Per vehicle ``i`` the effects are a list of entries -- a code (which effect: its row in the
registry, :mod:`quadfault.effects.registry`), the column of its first parameter and of its
first memory slot -- over one row of numbers each (:class:`EffectRows`; built by
:mod:`quadfault.effects.rows` from each effect's ``pack``). The closed loop
(:func:`quadfault.closed_loop.fly_vehicle`) calls the chain once per physics step,
:func:`step_effects` (inlined into the loop, so the rows' arrays are taken once per step
and no call passes them: every array a compiled call takes costs reference counting), which
does the two points of the effect protocol:

* the thrust stage (:func:`thrust_effects`), on the thrusts the motor model produced (in
  the order of the entries, each one's output the next one's input);
* the step's wrench terms (:func:`wrench_terms`): the numbers the RK stages need, so that
  :func:`effects_wrench` gives at every stage of the RKMK4 step the sum of the wrench
  entries' external force (world) [N] and moment (body) [N m] from numbers alone; a step
  without wrench entries skips the stages' call (:func:`has_wrench`).

Each entry runs the kernels of its effect's module (``thrust_step``, ``wrench_term``,
``wrench_stage``; each documents its parameters and memory), picked by code in dispatchers
generated from the registry (:mod:`quadfault.effects.dispatch`). This module's functions are
those of every registered effect; :func:`chain_for` gives the chain of only some effects
(the same functions, compiling less).

Random numbers: a wind's gusts draw three standard normals per step, after the motors'
draws, from the vehicle's generator (the loop's), or from the wind's own seeded generator
(``streams[i]``) when it has a seed.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

import quadfault.effects.dispatch as dispatch
import quadfault.effects.registry as registry
from quadfault.effects.dispatch import NO_TERMS, TERM, WRENCH_TERMS

#: effect name -> code of its entry (body effects -- mass, inertia -- have none: they set
#: the flown vehicle's mass and inertia)
CODES = {cls.name: k for k, cls in enumerate(registry.TABLE)
         if dispatch.has_thrust(cls) or dispatch.has_term(cls)}


class EffectRows(NamedTuple):
    """The compiled effects of N vehicles (row ``i`` = vehicle ``i``; see the module
    docstring). ``memory`` is updated in place by the loop."""

    code: np.ndarray  # (N, E) int64: entry codes in chain order, -1 after the last
    param: np.ndarray  # (N, E) int64: column of each entry's first parameter
    mem: np.ndarray  # (N, E) int64: column of each entry's first memory slot
    params: np.ndarray  # (N, P) parameters
    memory: np.ndarray  # (N, Q) memory (zeros: a flight's start)
    streams: object  # typed list of N generators: a seeded wind's own (else never drawn)


def chain_for(names=None):
    """The compiled chain (a module with ``thrust_effects``, ``wrench_terms``,
    ``step_effects``, ``has_wrench``, ``effects_wrench``) of the effects ``names`` (default:
    every registered effect); rows with other effects must not fly under it."""
    table = registry.TABLE if names is None else tuple(registry.effect_class(n) for n in names)
    return dispatch.compiled(table, [registry.TABLE.index(cls) for cls in table])


_ALL = chain_for()
thrust_effects = _ALL.thrust_effects
wrench_terms = _ALL.wrench_terms
step_effects = _ALL.step_effects
has_wrench = _ALL.has_wrench
effects_wrench = _ALL.effects_wrench

__all__ = ["CODES", "EffectRows", "WRENCH_TERMS", "TERM", "NO_TERMS", "chain_for",
           "thrust_effects", "wrench_terms", "step_effects", "has_wrench", "effects_wrench"]
