"""The diagnosis result record and its JSON form (docs/formats.md)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from quadfault.model.effects.com_offset import ComOffset
from quadfault.model.effects.motor_efficiency import MotorEfficiency

FORMAT = "quadfault-diagnosis/2"


@dataclass(frozen=True)
class EffectFinding:
    """One fitted effect (accepted, suspect or rejected).

    Attributes:
        name: canonical effect name.
        params: physical parameters (units in the keys; directions in the recording's frame).
        uncertainty: one-sigma uncertainty of ``params`` (same keys).
        improvement: held-out residual RMS reduction of nominal + this effect alone [-]
            (may be negative for a rejected candidate).
        explanation: one or two sentences, including effects it cannot be told apart from.
        bounds: ``{key: [lo, hi]}`` the fit was confined to (shaped like each parameter).
        folds: ``{key: [value per fold]}``: the fit without each cross-validation fold.
        status: ``"accepted"``, ``"suspect"`` or ``"rejected"``.
        reason: why a suspect or rejected effect was not accepted.
        at_bound: a parameter sits at (or within 2 % of the span of) a bound.
        improvement_when_added: held-out RMS reduction when it was added to (or tested on
            top of) the model before it, or None.
        fold_agreement: the fold-agreement rule's reading of ``folds``, or "".
        folds_agree: whether the folds pass that rule (None without folds).
        pinned_by: ``{key: source}`` for parameters fixed by other data (``"rotor_speed"``:
            a time constant from command to measured rotor speed); ``bounds`` are then the
            effect's own range, not the window that holds the value.
    """

    name: str
    params: dict
    uncertainty: dict
    improvement: float
    explanation: str
    bounds: dict = field(default_factory=dict)
    folds: dict = field(default_factory=dict)
    status: str = "accepted"
    reason: str = ""
    at_bound: bool = False
    improvement_when_added: float | None = None
    fold_agreement: str = ""
    folds_agree: bool | None = None
    pinned_by: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        out = {
            "name": self.name,
            "params": self.params,
            "uncertainty": self.uncertainty,
            "improvement": self.improvement,
            "explanation": self.explanation,
            "bounds": self.bounds,
            "folds": self.folds,
            "at_bound": self.at_bound,
        }
        if self.status != "accepted":
            out["reason"] = self.reason
        if self.improvement_when_added is not None:
            out["improvement_when_added"] = self.improvement_when_added
        if self.fold_agreement:
            out["fold_agreement"] = self.fold_agreement
            out["folds_agree"] = self.folds_agree
        if self.pinned_by:
            out["pinned_by"] = dict(self.pinned_by)
        return out


@dataclass(frozen=True)
class Interval:
    channel: str
    t0: float  # [s]
    t1: float  # [s]
    note: str
    excess: float = 0.0  # RMS of the nominal residual over the interval / noise scale


@dataclass(frozen=True)
class DiagnosisResult:
    """Outcome of :meth:`quadfault.diagnosis.Diagnosis.fit`.

    Attributes:
        verdict: ``"mismatch"`` or ``"consistent"``.
        baseline_rmse: held-out residual RMS of the nominal model per channel (channel units).
        model_rmse: held-out residual RMS of nominal + accepted effects per channel.
        model_improvement: 1 - RMS(after)/RMS(before), all channels (weighted), held out.
        effects: accepted effects, most important first.
        untestable: the names of ``not_identifiable``, in the same order.
        not_identifiable: ``({"name", "reason"}, ...)``: candidates left out before any fit
            because the log lacks the evidence (channels, rates, a usable command curve) they
            need (:mod:`~quadfault.diagnosis.identifiability`).
        evidence: what the log carries (rates of the commands, samples and rotor speeds
            [Hz], the shortest time constant the commands resolve [s], which channels).
        assumptions: which results depend on an assumed mass or inertia (empty when none is
            assumed): ``{"assumed", "depends", "independent", "note"}``.
        where: intervals where the nominal model disagrees.
        regimes: per disagreeing channel, the regime variable that explains it best.
        prediction: open-loop multi-step prediction errors (held out), per horizon.
        channels, scale: channel names and their noise scales.
        suspect: effects that improved the fit only with a parameter at a bound.
        rejected: candidates fitted and not accepted, with the reason.
        indistinguishable: ``({"names": [a, b], "reason"}, ...)``: effects this log cannot
            tell apart and so names neither (a rejected effect that adds nothing to a motor
            lag or delay shorter than the log resolves,
            :mod:`~quadfault.diagnosis.resolution`).
        channel_scores: ``{channel: {"rmse_before", "rmse_after", "improvement", "ci95"}}``.
        model_ci95: 95 % interval of ``model_improvement``.
        weights: relative weight of each channel in pooled scores.
        scoring: what held-out scores use (``excluded`` spans with reasons,
            ``excluded_fraction``, blocks, weights, ...).
        vehicle: the sidecar's vehicle object the diagnosis started from (recording's frame);
            frame, gravity: the recording's world frame and gravity.
        estimator: beside a weak-rotor hypothesis, the online estimator's efficiencies of
            the same flight (``{"estimator", "eta", "weakest_rotor",
            "diagnosis_weakest_rotor", "agrees", ...}``), ``{}`` otherwise.
        series: arrays for plots (times, residuals before/after, regime variables).
    """

    verdict: str
    baseline_rmse: dict
    model_rmse: dict
    model_improvement: float
    effects: tuple = ()
    untestable: tuple = ()
    not_identifiable: tuple = ()
    assumptions: dict = field(default_factory=dict)
    evidence: dict = field(default_factory=dict)
    where: tuple = ()
    regimes: tuple = ()
    prediction: dict = field(default_factory=dict)
    channels: tuple = ()
    scale: tuple = ()
    seconds: float = 0.0
    scoring: dict = field(default_factory=dict)
    suspect: tuple = ()
    rejected: tuple = ()
    indistinguishable: tuple = ()
    channel_scores: dict = field(default_factory=dict)
    model_ci95: tuple = ()
    weights: tuple = ()
    vehicle: dict = field(default_factory=dict)
    frame: str = "NED"
    gravity: float = 9.81
    estimator: dict = field(default_factory=dict)
    series: dict = field(default_factory=dict, repr=False, compare=False)

    def to_dict(self) -> dict:
        """The contract's JSON object (plus extra informative fields)."""
        return _clean(
            {
                "format": FORMAT,
                "verdict": self.verdict,
                "baseline": {"rmse": dict(self.baseline_rmse)},
                "untestable": list(self.untestable),
                "not_identifiable": [dict(n) for n in self.not_identifiable],
                "assumptions": dict(self.assumptions),
                "evidence": dict(self.evidence),
                "where": [
                    {"channel": w.channel, "t0": w.t0, "t1": w.t1, "note": w.note}
                    for w in self.where
                ],
                "effects": [e.to_dict() for e in self.effects],
                "suspect": [e.to_dict() for e in self.suspect],
                "rejected": [e.to_dict() for e in self.rejected],
                "indistinguishable": [dict(n) for n in self.indistinguishable],
                "model": {
                    "rmse": dict(self.model_rmse),
                    "improvement": self.model_improvement,
                    "ci95": list(self.model_ci95),
                    "channels": dict(self.channel_scores),
                },
                "regimes": list(self.regimes),
                "prediction": dict(self.prediction),
                "normalisation": dict(zip(self.channels, self.scale)),
                "weights": dict(zip(self.channels, self.weights)),
                "seconds": self.seconds,
                "scoring": dict(self.scoring),
                "vehicle": dict(self.vehicle),
                "frame": self.frame,
                "gravity": self.gravity,
                **({"estimator": dict(self.estimator)} if self.estimator else {}),
            }
        )

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n"

    @property
    def effect_names(self) -> list[str]:
        return [e.name for e in self.effects]

    def summary(self) -> str:
        """The one-line summary (printed by ``quadfault diagnose``, first in report.md): the
        same figures as the JSON -- every accepted effect with its fitted value and its
        held-out improvement alone, the rivals this flight cannot tell apart with theirs,
        the fraction not scored, the model's held-out improvement."""
        names = (
            ", ".join(f"{short(e.name, e.params)} ({percent(e.improvement)})" for e in self.effects)
            or "none"
        )
        parts = [f"{self.verdict}: effects {names}"]
        for n in self.indistinguishable:
            if "summary" in n:
                parts.append(f"{n['summary']}: this flight cannot tell them apart")
            else:
                parts.append("indistinguishable in this log: " + " or ".join(n["names"]))
        if self.estimator.get("eta"):
            est = self.estimator
            k = est["weakest_rotor"]
            word = "agrees" if est["agrees"] else "disagrees"
            parts.append(
                f"online {est['estimator']} estimate: rotor {k} at {est['eta'][k - 1]:.2f} ({word})"
            )
        if self.suspect:
            parts.append("suspect (at a bound): " + ", ".join(e.name for e in self.suspect))
        if self.scoring.get("not_accepted"):
            parts.append(self.scoring["not_accepted"])
        if self.not_identifiable:
            parts.append(
                "not identifiable from this log: "
                + ", ".join(n["name"] for n in self.not_identifiable)
            )
        frac = self.scoring.get("excluded_fraction", 0.0)
        if frac:
            parts.append(f"{100 * frac:.1f}% not scored (see scoring.excluded)")
        parts.append(f"held-out improvement {100 * self.model_improvement:.1f}%")
        return "; ".join(parts)


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


def percent(v: float) -> str:
    """A held-out improvement on the summary line: whole percent, one decimal below 10 %."""
    return f"{100 * v:.0f}%" if abs(v) >= 0.1 else f"{100 * v:.1f}%"


def _num(v) -> str:
    if isinstance(v, (list, tuple)):
        return "(" + ", ".join(_num(x) for x in v) + ")"
    return f"{v:.3g}"


def short(name: str, params: dict) -> str:
    """An effect and its fitted value in a few words (the one-line summary): ``weak rotor 3
    (0.70)``, ``com_offset (13, -2) mm``, ``motor_lag 0.043 s``, ``thrust_scale 0.94``."""
    if name == MotorEfficiency.name:
        eta = np.asarray(params.get("eta", ()), dtype=float)
        if eta.size:
            k = int(np.argmin(eta))
            return f"weak rotor {k + 1} ({eta[k]:.2f})"
    if name == ComOffset.name and "offset_m" in params:
        mm = [round(1000 * v) for v in params["offset_m"]]
        return f"com_offset ({', '.join(f'{v:g}' for v in mm)}) mm"
    if not params:
        return name
    key, value = next(iter(params.items()))
    unit = " s" if key.endswith("_s") and not key.endswith("per_s") else ""
    if isinstance(value, (int, float, list, tuple)):
        return f"{name} {_num(value)}{unit}"
    return name
