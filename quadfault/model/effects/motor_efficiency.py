"""``motor_efficiency``: per-rotor thrust loss, ``f_i' = eta_i f_i`` (paper eq. 13)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadfault.errors import ConfigError
from quadfault.jit import jit
from quadfault.layout import ROTORS, fields
from quadfault.model.effects.base import Compiled, Identifiability, vector
from quadfault.model.effects.candidate import Candidate
from quadfault.model.effects.kernels import replaced
from quadfault.model.effects.thrust_scale import ThrustScale

#: the chain entry's parameters: one efficiency per rotor
PARAMETERS = fields("MotorEfficiencyParameters", ("eta", ROTORS))


@jit(inline="always")
def thrust_step(x, q, f, t, dt, p, gen, streams, i):
    """The chain's entry: each rotor's thrust times its ``eta``."""
    out = f
    for r in range(len(f)):
        out = replaced(out, r, f[r] * x[PARAMETERS.eta + r])
    return out


@dataclass(frozen=True)
class MotorEfficiency(Compiled):
    """Per-rotor thrust factor ``eta`` [-] (1 = nominal; paper eq. 13)."""

    eta: tuple = (1.0, 1.0, 1.0, 1.0)
    name: ClassVar[str] = "motor_efficiency"
    order: ClassVar[int] = 2
    identifiability: ClassVar[Identifiability] = Identifiability(
        note="a per-rotor loss shows as the unequal rotor split that keeps the moments "
        "balanced; a loss common to all rotors is a thrust_scale; told from the "
        "vehicle's own imbalance (CoM offset, yaw trim) only where the rotors' commands "
        "vary relative to each other, or against flights of the healthy vehicle"
    )
    explanation: ClassVar[str] = (
        "rotor thrusts are eta_i times the commanded ones (per-rotor thrust loss)"
    )
    equivalent: ClassVar[str] = "thrust"
    values: ClassVar[tuple] = (1, 4)
    syntax: ClassVar[str] = "ETA or ETA1,ETA2,ETA3,ETA4 [-]"
    example: ClassVar[str] = "motor_efficiency=1,1,0.8,1"
    parameter: ClassVar[tuple] = ("eta", "eta")

    def __post_init__(self):
        eta = vector(self.eta, 4, "motor_efficiency eta")
        if not all(0.0 <= e <= 2.0 for e in eta):
            raise ConfigError(f"motor_efficiency eta must be in [0, 2], got {eta}")
        object.__setattr__(self, "eta", eta)

    @classmethod
    def fit_note(cls, params, selected):
        if "baseline_eta" in params:
            text = (
                " eta is relative to the healthy vehicle's flights (baseline_eta, their "
                "mean over baseline_flights; baseline_spread their flight-to-flight "
                "spread) and to the median rotor; eta_flight is this flight's own."
            )
            if params.get("baseline_flights") == 1:
                text += (
                    " With one healthy flight the flight-to-flight spread is unknown "
                    "(--baseline takes several)."
                )
        else:
            text = (
                " eta is relative to the median rotor (a factor common to every rotor is "
                "thrust_scale's or thrust_curve's); one flight cannot tell a weak rotor "
                "from the vehicle's own imbalance: compare with a flight of the healthy "
                "vehicle (--baseline)."
            )
        if "eta_absolute" in params:
            text += " eta_absolute: thrust calibrated by the measured rotor speeds."
        return text

    def parameters(self, n_rotors, dt, yaw_signs=None):
        if len(self.eta) != n_rotors:
            raise ConfigError(
                f"motor_efficiency has {len(self.eta)} rotors, the vehicle {n_rotors}"
            )
        return {"eta": self.eta}

    @classmethod
    def candidate(cls, ctx):
        one4, rp = (1.0,) * 4, ctx.rp
        return EfficiencyCandidate(
            cls.name,
            ("eta1 [-]", "eta2 [-]", "eta3 [-]", "eta4 [-]"),
            (0.2,) * 4,
            (1.5,) * 4,
            one4,
            (one4,),
            "thrust",
            cls.order,
            affine=True,
            excludes=(ThrustScale.name,),
            absolute=rp.has_rotor and rp.rotor_k_source == "sidecar",
        )


#: a rotor departs from the healthy baseline when it is this far from it [-], or this many
#: flight-to-flight spreads of the healthy flights (when there are several)
BASELINE_TOLERANCE, BASELINE_Z = 0.05, 3.0


def healthy_pattern(flights) -> tuple[tuple, tuple]:
    """``(eta, spread)`` of the healthy vehicle from the relative rotor efficiencies of one or
    more of its flights (rows of 4): their geometric mean relative to its median rotor, and
    per rotor the flight-to-flight standard deviation of ``log eta`` relative to that mean
    (each flight relative to its own median rotor); ``()`` for one flight."""
    L = np.log(np.asarray(flights, dtype=float).reshape(-1, 4))
    mean = L.mean(axis=0)
    mean -= np.median(mean)
    if len(L) < 2:
        return tuple(np.exp(mean).tolist()), ()
    dev = L - mean
    dev -= np.median(dev, axis=1, keepdims=True)
    return tuple(np.exp(mean).tolist()), tuple(
        np.sqrt(np.sum(dev**2, axis=0) / (len(L) - 1)).tolist()
    )


@dataclass(frozen=True)
class EfficiencyCandidate(Candidate):
    """Per-rotor thrust factors ``eta``, reported relative to the median rotor: a factor
    common to every rotor is a calibration (``thrust_scale``, ``thrust_curve``), not damage.
    With ``absolute`` (thrust calibrated independently, e.g. measured rotor speeds with a
    known thrust coefficient) the fitted factors are also given as ``eta_absolute``. With a
    ``baseline`` (the healthy vehicle's relative eta, :func:`healthy_pattern` of
    ``baseline_flights`` flights, with their flight-to-flight ``spread``) ``eta`` is relative
    to it."""

    absolute: bool = False
    baseline: tuple = ()
    spread: tuple = ()
    baseline_flights: int = 0
    keys: ClassVar[tuple] = (("eta", 0, 4),)

    def tolerance(self) -> np.ndarray:
        """How far each rotor may be from the baseline and still match it [-]:
        ``BASELINE_TOLERANCE``, or ``BASELINE_Z`` flight-to-flight spreads when larger."""
        spread = np.asarray(self.spread or (0.0,) * 4, dtype=float)
        return np.maximum(BASELINE_TOLERANCE, BASELINE_Z * spread)

    def thrust(self, x, rp, f, t, dt):
        return f * np.asarray(x, dtype=float)[None, :]

    def relative(self, x) -> np.ndarray:
        """``eta`` as reported: relative to the median rotor, and with a ``baseline`` (a
        healthy flight's relative eta) relative to it."""
        x = np.asarray(x, dtype=float)
        if self.baseline:
            x = x / np.asarray(self.baseline, dtype=float)
        return x / max(float(np.median(x)), 1e-9)

    def public_bounds(self, x=None):
        """The bounds of ``eta`` in its reported units: relative to the median rotor of the
        fit ``x`` (and to the baseline), like ``eta``; ``eta_absolute`` and ``eta_flight``
        in theirs."""
        out = super().public_bounds()
        if x is None:
            return out
        x = np.asarray(x, dtype=float)
        lo, hi = np.asarray(self.lower, dtype=float), np.asarray(self.upper, dtype=float)
        scale = self.relative(x) / np.maximum(x, 1e-12)  # reported eta per fitted eta
        out["eta"] = [(lo * scale).tolist(), (hi * scale).tolist()]
        if self.baseline:
            flight = 1.0 / max(float(np.median(x)), 1e-9)
            out["eta_flight"] = [float(lo[0] * flight), float(hi[0] * flight)]
        if self.absolute:
            out["eta_absolute"] = [float(lo[0]), float(hi[0])]
        return out

    def public(self, x, sd, ctx):
        x, sd = np.asarray(x, dtype=float), np.asarray(sd, dtype=float)
        rel = self.relative(x)
        params, unc = {"eta": rel.tolist()}, {"eta": (sd * rel / np.maximum(x, 1e-9)).tolist()}
        if self.baseline:
            flight = x / max(float(np.median(x)), 1e-9)
            params["eta_flight"], unc["eta_flight"] = flight.tolist(), (sd * flight / x).tolist()
            params["baseline_eta"] = list(self.baseline)
            params["baseline_flights"] = int(self.baseline_flights)
            if self.spread:
                params["baseline_spread"] = list(self.spread)
        if self.absolute:
            params["eta_absolute"], unc["eta_absolute"] = x.tolist(), sd.tolist()
        return params, unc
