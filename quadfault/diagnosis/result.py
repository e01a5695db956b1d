"""The diagnosis result record and its JSON form (CONTRACT.md sec. 4)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class EffectFinding:
    """One accepted effect.

    Attributes:
        name: canonical effect name.
        params: physical parameters (units in the keys).
        uncertainty: one-sigma uncertainty of ``params`` (same keys).
        improvement: held-out residual RMS reduction of nominal + this effect alone [0..1].
        explanation: one or two sentences, including effects it cannot be told apart from.
    """

    name: str
    params: dict
    uncertainty: dict
    improvement: float
    explanation: str


@dataclass(frozen=True)
class Interval:
    channel: str
    t0: float  # [s]
    t1: float  # [s]
    note: str


@dataclass(frozen=True)
class DiagnosisResult:
    """Outcome of :meth:`quadfault.diagnosis.Diagnosis.fit`.

    Attributes:
        verdict: ``"mismatch"`` or ``"consistent"``.
        baseline_rmse: held-out residual RMS of the nominal model per channel (channel units).
        model_rmse: held-out residual RMS of nominal + accepted effects per channel.
        model_improvement: 1 - RMS(after)/RMS(before), all channels (normalised), held out.
        effects: accepted effects, most important first.
        untestable: effects this recording cannot reveal.
        where: intervals where the nominal model disagrees.
        regimes: per disagreeing channel, the regime variable that explains it best.
        prediction: open-loop multi-step prediction errors before/after (pose logs).
        channels, scale: channel names and their noise scales (normalisation).
        scoring: which blocks held-out scores use (``scored_blocks`` of ``blocks``;
            ``excluded_s``: calibration segments [s] fitted on but not scored).
        series: arrays for plots (times, residuals before/after, regime variables).
    """

    verdict: str
    baseline_rmse: dict
    model_rmse: dict
    model_improvement: float
    effects: tuple = ()
    untestable: tuple = ()
    where: tuple = ()
    regimes: tuple = ()
    prediction: dict = field(default_factory=dict)
    channels: tuple = ()
    scale: tuple = ()
    seconds: float = 0.0
    scoring: dict = field(default_factory=dict)
    series: dict = field(default_factory=dict, repr=False, compare=False)

    def to_dict(self) -> dict:
        """The contract's JSON object (plus extra informative fields)."""
        return _clean({
            "verdict": self.verdict,
            "baseline": {"rmse": dict(self.baseline_rmse)},
            "untestable": list(self.untestable),
            "where": [{"channel": w.channel, "t0": w.t0, "t1": w.t1, "note": w.note}
                      for w in self.where],
            "effects": [{"name": e.name, "params": e.params, "uncertainty": e.uncertainty,
                         "improvement": e.improvement, "explanation": e.explanation}
                        for e in self.effects],
            "model": {"rmse": dict(self.model_rmse), "improvement": self.model_improvement},
            "regimes": list(self.regimes),
            "prediction": dict(self.prediction),
            "normalisation": dict(zip(self.channels, self.scale)),
            "seconds": self.seconds,
            "scoring": dict(self.scoring),
        })

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n"

    @property
    def effect_names(self) -> list[str]:
        return [e.name for e in self.effects]


def _clean(obj):
    """numpy -> Python, non-finite floats -> None (the JSON stays strict)."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj
