"""``thrust_scale``: every rotor produces a common factor of the commanded thrust,
``f_i' = s f_i``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from quadfault.jit import jit
from quadfault.layout import fields
from quadfault.model.effects.base import Compiled, Identifiability, number
from quadfault.model.effects.candidate import Candidate
from quadfault.model.effects.kernels import scaled

#: the chain entry's parameters
PARAMETERS = fields("ThrustScaleParameters", "scale")


@jit(inline="always")
def thrust_step(x, q, f, t, dt, p, gen, streams, i):
    """The chain's entry: every thrust times ``scale``."""
    return scaled(f, x[PARAMETERS.scale])


@dataclass(frozen=True)
class ThrustScale(Compiled):
    """Common thrust factor ``scale`` [-] of all rotors."""

    scale: float = 1.0
    name: ClassVar[str] = "thrust_scale"
    order: ClassVar[int] = 2
    identifiability: ClassVar[Identifiability] = Identifiability(
        scales_with=("mass",), note="shows in the vertical acceleration for the commanded thrust"
    )
    explanation: ClassVar[str] = "all rotors produce a common factor of the commanded thrust"
    equivalent: ClassVar[str] = "thrust"
    syntax: ClassVar[str] = "SCALE [-]"
    example: ClassVar[str] = "thrust_scale=0.9"
    parameter: ClassVar[tuple] = ("scale", "scale")

    def __post_init__(self):
        number(self.scale, "thrust_scale", 0.0, 3.0, open_lo=True)

    @classmethod
    def fit_note(cls, params, selected):
        return " Indistinguishable from motor_efficiency with equal eta (one class)."

    @classmethod
    def candidate(cls, ctx):
        return ScaleCandidate(
            cls.name,
            ("scale [-]",),
            (0.5,),
            (1.5,),
            (1.0,),
            ((1.0,),),
            "thrust",
            cls.order,
            affine=True,
        )


@dataclass(frozen=True)
class ScaleCandidate(Candidate):
    keys: ClassVar[tuple] = (("scale", 0, 1),)

    def thrust(self, x, rp, f, t, dt):
        return f * float(x[0])
