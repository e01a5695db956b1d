"""The diagnosis model: mask -> replay -> residuals -> library fit -> selection -> result.

``Diagnosis(config).fit(recording, vehicle=None) -> DiagnosisResult``.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from quadfault.diagnosis.crossval import folds_of
from quadfault.diagnosis.findings import Findings
from quadfault.diagnosis.identifiability import (
    assumptions,
    evidence,
    gate,
    pin_to_rotor_speeds,
    without_pose,
)
from quadfault.diagnosis.library import build_library, predict
from quadfault.diagnosis.locate import locate
from quadfault.diagnosis.phases import excluded_fraction, flight_phases
from quadfault.diagnosis.prediction import HORIZONS, open_loop_errors
from quadfault.diagnosis.residuals import prepare
from quadfault.diagnosis.result import DiagnosisResult
from quadfault.diagnosis.rivals import Rivals
from quadfault.diagnosis.scores import fixed_scoring
from quadfault.diagnosis.select import ForwardSelection, SelectionSettings
from quadfault.errors import ConfigError, QuadfaultError, RecordingError
from quadfault.io.recording import Recording, recording_sidecar
from quadfault.model.effects.mass import Mass
from quadfault.model.effects.motor_efficiency import MotorEfficiency, healthy_pattern
from quadfault.model.effects.registry import EFFECT_NAMES
from quadfault.model.effects.thrust_scale import ThrustScale

#: a located interval whose nominal residual RMS reaches this many noise scales for at least
#: ``STRONG_SECONDS`` makes the verdict ``mismatch`` even when nothing in the library explains
#: it (see :func:`_unexplained`)
STRONG_INTERVAL, STRONG_SECONDS = 3.0, 0.5


@dataclass(frozen=True)
class DiagnosisConfig:
    """Diagnosis settings.

    Attributes:
        block_seconds: smoothing block length [s] (block means, see ``residuals``).
        gap_factor: an interval longer than this times the median spacing is a gap.
        folds: contiguous time folds of the cross-validation.
        max_effects: most effects accepted.
        min_improvement: least held-out RMS reduction (relative to the current model) for
            accepting an effect [-].
        bic_margin: least BIC decrease for accepting an effect.
        screen_top: most single candidates cross-validated per step (in BIC order).
        pair_top: pairs among this many best single candidates are tried per step.
        effects: restrict the library to these names (None: all).
        horizons: open-loop prediction horizons [s].
        saturate: clip commands to [0, max_thrust] as the nominal motor model does.
        internal_step: faster logs are merged to about this step [s] (see ``residuals``).
        mask: exclude what is not free flight (:mod:`~quadfault.diagnosis.phases`).
        baseline_eta: the relative rotor efficiencies of one or more flights of the healthy
            vehicle (their diagnoses' ``motor_efficiency`` ``eta``): 4 numbers, or one row of
            4 per flight. ``motor_efficiency`` is then reported relative to their mean and
            accepted only where a rotor departs from it by more than 5 % and by more than 3
            times the healthy flights' flight-to-flight spread (:mod:`~quadfault.diagnosis.
            rotors`; one flight alone cannot tell a weak rotor from the vehicle's own
            imbalance). Stored as a tuple of 4-tuples. None: no baseline.
    """

    block_seconds: float = 0.02
    gap_factor: float = 2.5
    folds: int = 5
    max_effects: int = 3
    min_improvement: float = 0.05
    bic_margin: float = 10.0
    screen_top: int = 3
    pair_top: int = 3
    effects: tuple | None = None
    horizons: tuple = HORIZONS
    saturate: bool = True
    internal_step: float = 0.004
    mask: bool = True
    baseline_eta: tuple | None = None

    def __post_init__(self):
        if self.baseline_eta is not None:
            try:
                b = np.asarray(self.baseline_eta, dtype=float)
            except (TypeError, ValueError):
                b = np.zeros(0)
            if (
                b.ndim not in (1, 2)
                or b.shape[-1] != 4
                or b.size == 0
                or not np.all(np.isfinite(b) & (b > 0))
            ):
                raise ConfigError(
                    f"baseline_eta must be 4 positive numbers (or one row of 4 "
                    f"per healthy flight), got {self.baseline_eta!r}"
                )
            object.__setattr__(
                self,
                "baseline_eta",
                tuple(tuple(float(v) for v in row) for row in b.reshape(-1, 4)),
            )
        if not (0 < self.block_seconds <= 1.0):
            raise ConfigError(f"block_seconds must be in (0, 1] s, got {self.block_seconds!r}")
        if not (self.gap_factor > 1):
            raise ConfigError("gap_factor must be > 1")
        if not (2 <= self.folds <= 20):
            raise ConfigError(f"folds must be in [2, 20], got {self.folds!r}")
        if not (0 <= self.max_effects <= 9):
            raise ConfigError("max_effects must be in [0, 9]")
        if not (0 <= self.pair_top <= 9):
            raise ConfigError("pair_top must be in [0, 9]")
        if self.effects is not None:
            bad = [e for e in self.effects if e not in EFFECT_NAMES]
            if bad:
                raise ConfigError(
                    f"unknown effect {bad[0]!r}; choose from {', '.join(EFFECT_NAMES)}"
                )
        if not self.horizons or not all(h > 0 for h in self.horizons):
            raise ConfigError("horizons must be positive [s]")


def _unexplained(rp, sc, base_res, where) -> bool:
    """A mismatch no library effect explains: a strong localised interval (its nominal
    residual at least ``STRONG_INTERVAL`` noise scales, lasting ``STRONG_SECONDS`` but less
    than half the scored flight), or a nominal residual beyond ``STRONG_INTERVAL`` noise scales
    over the whole flight (weighted RMS) where the locate step finds intervals."""
    scored = float(np.sum(rp.block_dur[sc.rows]))
    for w in where:
        if w.excess >= STRONG_INTERVAL and STRONG_SECONDS <= w.t1 - w.t0 < 0.5 * scored:
            return True
    z = sc.normalised(base_res) / np.sqrt(sc.weight)  # in noise units
    return bool(where) and float(np.sqrt(np.mean(z * z))) > STRONG_INTERVAL


def _indistinguishable(verdicts, order) -> tuple:
    """``({"names": [effect, timing effect], "reason"}, ...)``: the rejected effects this log
    cannot tell from a motor lag or delay shorter than it resolves
    (:mod:`~quadfault.diagnosis.resolution`), in the order of ``order``."""
    out = []
    for name in order:
        v = verdicts.get(name)
        if v is None or v.status != "rejected" or v.like is None:
            continue
        out.append(
            {
                "names": [name, v.like.name],
                "reason": (
                    f"this log cannot tell {name} from {v.like.describe()}: "
                    f"on held-out data {name} adds too little to that time "
                    "constant (its entry in rejected gives the figures), and the "
                    "log is too slow to confirm the time constant itself; one of "
                    "the two is likely there, and faster commands or measured "
                    "rotor speeds would tell which"
                ),
            }
        )
    return tuple(out)


def _valid_pose(rec, ev) -> tuple:
    """``(recording, spans)``: the recording without a pose that is mostly invalid (an IMU
    log then), and the spans [s] where the log flags its velocity or position invalid (left
    out of the diagnosis)."""
    if not ev.invalid:
        return rec, []
    if not ev.pose_valid:
        if rec.accel is None:
            raise RecordingError(
                rec.path or "recording",
                f"velocity flagged invalid over "
                f"{100 * ev.invalid_fraction:.0f}% of the log and no "
                "accelerometer to diagnose from instead",
                key="invalid",
            )
        return without_pose(rec), []
    why = "velocity or position flagged invalid by the log"
    return rec, [(a, b, why) for k in ("velocity", "position") for a, b in ev.invalid.get(k, ())]


#: effects that measure the thrust constant's scale (a common factor): not fitted when the
#: importer's thrust calibration is biased by time that is not free flight
CALIBRATED = (ThrustScale.name, Mass.name)
#: the fraction of the calibration segment that may be not free flight
CALIBRATION_TOLERANCE = 0.05


def _calibration_inside(rp) -> float:
    """The fraction of the importer's calibration segment that is not free flight."""
    if not rp.excluded or not rp.masked:
        return 0.0
    a, b = rp.excluded[0]
    return excluded_fraction([s for s in rp.masked if s[1] > a and s[0] < b], a, b)


def _calibration_bias(rp) -> str:
    """Why ``thrust_scale`` and ``mass`` are not fitted on ``rp`` ("" when they are): the
    importer's thrust calibration includes time that is not free flight (ground, spool-up),
    so its thrust constant carries that bias and a common factor would only measure it."""
    inside = _calibration_inside(rp)
    if inside < CALIBRATION_TOLERANCE:
        return ""
    return (
        f"{100 * inside:.0f}% of the importer's thrust calibration segment is not free "
        "flight: its thrust constant is biased by it, so a common thrust factor or mass "
        "would measure that bias (import again with --calibration T0,T1 in the air)"
    )


def _calibration_note(rp) -> str:
    """What of the importer's calibration segment is not free flight (its thrust constant
    then carries ground or impact forces; ``thrust_scale`` and ``mass`` are not fitted)."""
    inside = _calibration_inside(rp)
    if inside < CALIBRATION_TOLERANCE:
        return ""
    return (
        f"{100 * inside:.0f}% of the importer's calibration segment is not free flight: "
        "its thrust constant is biased by it; thrust_scale and mass are not fitted"
    )


def _scoring_dict(rp, sc, recording, mask_note="") -> dict:
    t0, t1 = float(recording.t[0]), float(recording.t[-1])
    spans = [{"t0": a, "t1": b, "reason": why} for a, b, why in rp.masked]
    spans += [
        {"t0": a, "t1": b, "reason": "calibration segment of the importer (fitted on, not scored)"}
        for a, b in rp.excluded
    ]
    spans.sort(key=lambda s: s["t0"])
    out = {
        "excluded": spans,
        "excluded_fraction": excluded_fraction([(s["t0"], s["t1"]) for s in spans], t0, t1),
        "masked_fraction": excluded_fraction(rp.masked, t0, t1),
        "scored_blocks": int(sc.rows.sum()),
        "blocks": int(rp.n_blocks),
        "weights": "fixed before any fit: noise scale per channel from the measured channel "
        "and the nominal residual; each measured quantity weighs as 3 channels; "
        "residuals winsorised at 5 robust sd of the nominal residual",
    }
    if rp.has_rotor:
        out["rotor_thrust_coefficient"] = {"value": rp.rotor_k, "source": rp.rotor_k_source}
    notes = [n for n in (mask_note, rp.scoring_note, _calibration_note(rp)) if n]
    if notes:
        out["note"] = "; ".join(notes)
    if _calibration_bias(rp):
        out["not_accepted"] = (
            "thrust_scale and mass not fitted: the importer's thrust calibration is "
            f"{100 * _calibration_inside(rp):.0f}% not free flight"
        )
    return out


class Diagnosis:
    """Model-mismatch diagnosis (library + optimizer + model, PySINDy-like)."""

    def __init__(self, config: DiagnosisConfig | None = None, efficiency_estimate=None):
        """``efficiency_estimate(recording) -> {"estimator": name, "eta": [4], ...}``: the
        online estimator's motor efficiencies over the flight, run by a caller that may
        import the estimators (the ``quadfault diagnose`` command); shown beside a
        weak-rotor hypothesis (``DiagnosisResult.estimator``). None: not shown."""
        self.config = config or DiagnosisConfig()
        self.efficiency_estimate = efficiency_estimate

    def fit(self, recording: Recording, vehicle=None, progress=None) -> DiagnosisResult:
        """Diagnose ``recording`` against ``vehicle`` (default: the recording's own).

        BLAS runs single-threaded inside: the diagnosis multiplies many small matrices, for
        which a multi-threaded BLAS spends more CPU spinning than computing (about 2x the CPU
        time measured with ``benchmarks/bench_diagnosis.py``)."""
        with threadpool_limits(limits=1, user_api="blas"):
            return self._fit(recording, vehicle, progress)

    def _fit(self, recording: Recording, vehicle, progress) -> DiagnosisResult:
        t_start = time.perf_counter()
        cfg = self.config
        rec = recording.without_truth() if isinstance(recording, Recording) else recording
        ev = evidence(rec)
        rec, invalid = _valid_pose(rec, ev)
        replay, mask_note = self._replay(rec, vehicle, invalid)
        library, not_identifiable = self._library(replay, ev)
        nominal_residual = replay.measured - predict(replay, [])
        scoring = fixed_scoring(replay, nominal_residual, replay.scored)
        library = pin_to_rotor_speeds(replay, library, scoring)
        settings = SelectionSettings(
            cfg.folds,
            cfg.max_effects,
            cfg.min_improvement,
            cfg.bic_margin,
            cfg.screen_top,
            cfg.pair_top,
        )
        selection = ForwardSelection(replay, library, scoring, settings, progress).run()
        folds = folds_of(replay.n_blocks, cfg.folds)
        rivals = Rivals(
            replay,
            scoring,
            folds,
            library if cfg.effects is None else self._rival_library(replay, ev, scoring),
            cfg.min_improvement,
            allowed=None if cfg.effects is None else [c.name for c in library],
        )
        selection, comparisons = rivals.compare(rivals.within_bounds(selection))
        selection = rivals.within_bounds(selection)
        in_model = {c.name for c in selection.final.candidates} if selection.final else set()
        ties = [
            c
            for c in comparisons
            if c.outcome == "tie" and set(c.held.names + c.rival.names) & in_model
        ]
        contested = {n for c in ties for n in c.held.names + c.rival.names}
        selection = rivals.within_bounds(rivals.supported(selection, keep=contested))
        frame = rec.frame if rec.frame in ("NED", "ENU") else "NED"
        found = Findings(replay, scoring, selection, folds, frame)
        accepted = found.accepted()
        effects = [e for e in accepted if e.name not in contested]
        suspect = found.suspects()
        rejected = [e for e in found.rejected() if e.name not in contested]
        rejected += [
            found.tied(c, comp)
            for comp in ties
            for c, _ in comp.held.fit.terms
            if c.name in comp.held.names
        ]
        rejected += [
            found.tied(c, comp)
            for comp in ties
            for c, _ in comp.rival.fit.terms
            if c.name in comp.rival.names
        ]
        rejected.sort(key=lambda e: -e.improvement)
        alike = tuple(found.indistinguishable(c) for c in ties)
        alike += _indistinguishable(selection.verdicts, [e.name for e in rejected])
        if selection.unattributed is not None:  # a time constant the log cannot resolve
            alike += (selection.unattributed.entry(),)
        reported = {n for a in alike for n in a["names"]} | {e.name for e in accepted}
        hidden = found.closed_loop(skip=reported)
        if hidden is not None:  # effects the closed loop inflates (partly real)
            alike += (hidden,)
            rejected = [
                dataclasses.replace(
                    e,
                    reason=e.reason + "; part of its signal is real, the closed loop inflates "
                    "its fit: see indistinguishable",
                )
                if e.name in hidden["names"]
                else e
                for e in rejected
            ]
        cross_check = self._estimator_check(rec, effects, alike)
        table, model_ci = scoring.channel_table(
            selection.baseline.residual, selection.final_cv.residual, replay.block_dur[scoring.rows]
        )
        model_imp = scoring.improvement(selection.baseline.residual, selection.final_cv.residual)
        where, regimes = locate(replay, nominal_residual, scoring.noise)
        unexplained = _unexplained(replay, scoring, nominal_residual, where)
        verdict = "mismatch" if effects or suspect or alike or unexplained else "consistent"
        prediction = self._prediction(rec, replay, selection, folds)
        series = {
            "block_t": replay.block_t,
            "baseline": selection.baseline.residual,
            "model": selection.final_cv.residual,
            "channels": replay.channels,
            "regimes": regimes,
            "replay": replay,
            "prediction": prediction,
            "scored": scoring.rows,
            "masked": replay.masked,
            "calibration": replay.excluded,
        }
        side = recording_sidecar(rec, frame=frame)
        return DiagnosisResult(
            verdict=verdict,
            baseline_rmse={ch: v["rmse_before"] for ch, v in table.items()},
            model_rmse={ch: v["rmse_after"] for ch, v in table.items()},
            model_improvement=float(model_imp),
            effects=tuple(effects),
            untestable=tuple(n["name"] for n in not_identifiable),
            not_identifiable=tuple(not_identifiable),
            assumptions=assumptions(ev, [e.name for e in effects]),
            evidence=ev.to_dict(),
            where=tuple(where),
            regimes=tuple(regimes),
            prediction={k: v for k, v in prediction.items() if not k.startswith("_")},
            channels=replay.channels,
            scale=tuple(float(s) for s in scoring.noise),
            seconds=float(time.perf_counter() - t_start),
            scoring=_scoring_dict(replay, scoring, rec, mask_note),
            suspect=tuple(suspect),
            rejected=tuple(rejected),
            indistinguishable=alike,
            channel_scores=table,
            model_ci95=tuple(model_ci),
            weights=tuple(float(w) for w in scoring.weight),
            vehicle=side["vehicle"],
            frame=frame,
            gravity=float(side["gravity"]),
            estimator=cross_check,
            series=series,
        )

    def _with_baseline(self, library: list) -> list:
        """``library`` with the weak rotor measured against the healthy flights
        (``baseline_eta``), when there are some."""
        cfg = self.config
        if cfg.baseline_eta is None:
            return library
        eta, spread = healthy_pattern(cfg.baseline_eta)
        return [
            dataclasses.replace(
                c, baseline=eta, spread=spread, baseline_flights=len(cfg.baseline_eta)
            )
            if c.name == MotorEfficiency.name
            else c
            for c in library
        ]

    def _rival_library(self, replay, ev, scoring) -> list:
        """The whole library for this recording (gated and pinned like the search's): the
        rivals of an effect the user asked for may be effects the user left out; the weak
        rotor is the search's (against the healthy flights when given)."""
        library = self._with_baseline(build_library(replay, None))
        library, _ = gate([c for c in library if not c.untestable_reason(replay)], ev)
        return pin_to_rotor_speeds(replay, library, scoring)

    def _estimator_check(self, rec, effects, alike) -> dict:
        """The online estimator's efficiencies of this flight beside a weak-rotor
        hypothesis (accepted or in an ``indistinguishable`` entry), from the callable the
        caller passed in (``efficiency_estimate``); ``{}`` without one or without such a
        hypothesis."""
        hypotheses = [e.params for e in effects if e.name == MotorEfficiency.name]
        hypotheses += [
            e["params"]
            for entry in alike
            for one in entry.get("sets", ())
            for e in one
            if e["name"] == MotorEfficiency.name
        ]
        if not hypotheses or self.efficiency_estimate is None:
            return {}
        try:
            out = dict(self.efficiency_estimate(rec))
        except QuadfaultError as exc:
            return {"error": str(exc)}
        eta = np.asarray(out["eta"], dtype=float)
        weakest = int(np.argmin(eta))
        named = int(np.argmin(hypotheses[0]["eta"]))
        out.update(
            weakest_rotor=weakest + 1,
            diagnosis_weakest_rotor=named + 1,
            agrees=bool(weakest == named),
        )
        return out

    def _replay(self, rec, vehicle, invalid) -> tuple:
        """``(replay, note)``: the recording replayed through the nominal model with what is
        not free flight excluded (:mod:`~quadfault.diagnosis.phases`), and the note saying
        why nothing was excluded where the mask would leave too little."""
        cfg = self.config
        kw = dict(
            block_seconds=cfg.block_seconds,
            gap_factor=cfg.gap_factor,
            saturate=cfg.saturate,
            internal_step=cfg.internal_step,
        )
        replay = prepare(rec, vehicle, exclude=invalid, **kw)
        spans = flight_phases(replay) if cfg.mask else []
        if not spans:
            return replay, ""
        try:
            return prepare(rec, vehicle, exclude=invalid + [s.as_tuple() for s in spans], **kw), ""
        except RecordingError:  # too little would be left: keep everything, say so
            frac = excluded_fraction(
                [s.as_tuple() for s in spans], float(rec.t[0]), float(rec.t[-1])
            )
            why = "; ".join(sorted({s.reason for s in spans}))
            return replay, (
                f"nothing excluded: what does not look like free flight "
                f"({why}; {100 * frac:.0f}% of the recording) would leave "
                "too few blocks"
            )

    def _library(self, replay, ev) -> tuple:
        """``(candidates to fit, not_identifiable)``: the library for this recording, and
        what it cannot reveal, in the library's order, each with its reason (the gate's,
        else what the effect itself lacks)."""
        cfg = self.config
        library = self._with_baseline(build_library(replay, cfg.effects))
        lacks = {c.name: c.untestable_reason(replay) for c in library}
        biased = _calibration_bias(replay)
        if biased:  # a common thrust factor would only measure the calibration's bias
            lacks.update({n: biased for n in CALIBRATED if n in lacks})
            library = [c for c in library if c.name not in CALIBRATED]
        library, gated = gate(library, ev)
        gated = {n["name"]: n["reason"] for n in gated}
        not_identifiable = [
            {"name": n, "reason": gated.get(n) or why}
            for n, why in lacks.items()
            if n in gated or why
        ]
        return library, not_identifiable

    def _prediction(self, rec, replay, selection, folds) -> dict:
        """Held-out open-loop errors: each start predicted by the final model fitted
        without its fold (:mod:`~quadfault.diagnosis.prediction`)."""
        fold_of_block = np.zeros(replay.n_blocks, dtype=int)
        for i, idx in enumerate(folds):
            fold_of_block[idx] = i
        cands = list(selection.final.candidates) if selection.final else []
        fold_terms = (
            [list(zip(cands, fx)) for fx in selection.final_cv.fold_x]
            if cands
            else [[] for _ in folds]
        )
        return open_loop_errors(rec, replay, fold_terms, fold_of_block, self.config.horizons)
