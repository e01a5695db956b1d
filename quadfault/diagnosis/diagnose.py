"""The diagnosis model: mask -> replay -> residuals -> library fit -> selection -> result.

``Diagnosis(config).fit(recording, vehicle=None) -> DiagnosisResult``.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from quadfault.diagnosis.crossval import cross_validate, fit_at_bound, fit_bound_mask, folds_of
from quadfault.diagnosis.feedback import IV_MIN, IV_UNVERIFIED_GAIN
from quadfault.diagnosis.findings import base_explanation, finding
from quadfault.diagnosis.identifiability import (
    assumptions,
    evidence,
    gate,
    pin_to_rotor_speeds,
    without_pose,
)
from quadfault.diagnosis.library import EQUIVALENT, build_library, predict, public_params
from quadfault.diagnosis.locate import locate
from quadfault.diagnosis.phases import excluded_fraction, flight_phases
from quadfault.diagnosis.prediction import HORIZONS, open_loop_errors
from quadfault.diagnosis.residuals import prepare
from quadfault.diagnosis.result import DiagnosisResult
from quadfault.diagnosis.scores import fixed_scoring
from quadfault.diagnosis.select import select
from quadfault.errors import ConfigError, RecordingError
from quadfault.io.recording import Recording, recording_sidecar
from quadfault.model.effects.motor_efficiency import MotorEfficiency, healthy_pattern
from quadfault.model.effects.registry import EFFECT_NAMES, effect_class

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


def _explain(step, selected_names, params) -> str:
    name = step.candidate.name
    text = (
        base_explanation(name) + f"; held-out residual RMS -{100 * step.improvement_step:.0f}% "
        "when added."
    )
    text += effect_class(name).fit_note(params, selected_names)
    kind = EQUIVALENT.get(name)
    mates = [n for n, k in EQUIVALENT.items() if k == kind and n != name]
    ratio = step.rivals.get(mates[0]) if len(mates) == 1 else None
    if ratio is not None and ratio < 1.1:  # a class of two (timing): the rival's fit
        a, b = sorted((name, mates[0]))
        text += (
            f" {mates[0]} fits almost as well (in-sample SSE ratio {ratio:.2f}): the data "
            f"cannot separate {a} from {b} (one {kind} class)."
        )
    if step.iv is not None and np.isfinite(step.iv):
        text += (
            f" Instrumental-variable check (instrument: the fitted signal with each "
            f"block's inputs frozen at its start, blind to feedback on the block's own "
            f"noise): slope {step.iv:.2f} (1 = all real, 0 = feedback bias; accepted "
            f"when >= {IV_MIN} and significantly above 0)."
        )
    elif step.iv is not None:
        text += (
            " The instrumental-variable check could not vouch for this signal (no "
            "predictable part), so it was accepted only on a held-out gain of at least "
            f"{IV_UNVERIFIED_GAIN:.0%}."
        )
    if step.agreement:
        text += f" Fold agreement: {step.agreement}."
    if step.candidate.pinned:
        text += (
            " Its time constant comes from command to measured rotor speed directly (the "
            "rotor channels alone); the other channels only decided that it is there."
        )
    return text


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


def _calibration_note(rp) -> str:
    """What of the importer's calibration segment is not free flight (its thrust constant
    then carries ground or impact forces; ``thrust_scale`` or ``thrust_curve`` absorb it)."""
    if not rp.excluded or not rp.masked:
        return ""
    a, b = rp.excluded[0]
    inside = excluded_fraction([s for s in rp.masked if s[1] > a and s[0] < b], a, b)
    if inside < 0.05:
        return ""
    return (
        f"{100 * inside:.0f}% of the importer's calibration segment is not free flight: "
        "its thrust constant is biased by it (a common factor that thrust_scale or "
        "thrust_curve takes up)"
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
    return out


class Diagnosis:
    """Model-mismatch diagnosis (library + optimizer + model, PySINDy-like)."""

    def __init__(self, config: DiagnosisConfig | None = None):
        self.config = config or DiagnosisConfig()

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
        kw = dict(
            block_seconds=cfg.block_seconds,
            gap_factor=cfg.gap_factor,
            saturate=cfg.saturate,
            internal_step=cfg.internal_step,
        )
        ev = evidence(rec)
        rec, invalid = _valid_pose(rec, ev)
        rp = prepare(rec, vehicle, exclude=invalid, **kw)
        mask_note = ""
        if cfg.mask:
            spans = flight_phases(rp)
            if spans:
                try:
                    rp = prepare(
                        rec, vehicle, exclude=invalid + [s.as_tuple() for s in spans], **kw
                    )
                except RecordingError:  # too little would be left: keep everything, say so
                    frac = excluded_fraction(
                        [s.as_tuple() for s in spans], float(rec.t[0]), float(rec.t[-1])
                    )
                    why = "; ".join(sorted({s.reason for s in spans}))
                    mask_note = (
                        f"nothing excluded: what does not look like free flight "
                        f"({why}; {100 * frac:.0f}% of the recording) would leave "
                        "too few blocks"
                    )
        library = build_library(rp, cfg.effects)
        if cfg.baseline_eta is not None:
            eta, spread = healthy_pattern(cfg.baseline_eta)
            library = [
                dataclasses.replace(
                    c, baseline=eta, spread=spread, baseline_flights=len(cfg.baseline_eta)
                )
                if c.name == MotorEfficiency.name
                else c
                for c in library
            ]
        lacks = {c.name: c.untestable_reason(rp) for c in library}
        library, gated = gate(library, ev)
        # one list of what this recording cannot reveal, in the library's order, each with
        # its reason (the gate's, else what the effect itself lacks); untestable: the names
        gated = {n["name"]: n["reason"] for n in gated}
        not_identifiable = [
            {"name": n, "reason": gated.get(n) or why}
            for n, why in lacks.items()
            if n in gated or why
        ]
        untestable = [n["name"] for n in not_identifiable]
        base_res = rp.measured - predict(rp, [])
        sc = fixed_scoring(rp, base_res, rp.scored)
        library = pin_to_rotor_speeds(rp, library, sc)
        sel = select(
            rp,
            library,
            sc,
            folds=cfg.folds,
            max_effects=cfg.max_effects,
            min_improvement=cfg.min_improvement,
            bic_margin=cfg.bic_margin,
            screen_top=cfg.screen_top,
            pair_top=cfg.pair_top,
            progress=progress,
        )
        fl = folds_of(rp.n_blocks, cfg.folds)
        frame = rec.frame if rec.frame in ("NED", "ENU") else "NED"
        selected = (
            {s.candidate.name: x for s, x in zip(sel.steps, sel.final.x)} if sel.final else {}
        )

        def alone_cv(c, x=None):
            """Held-out result of nominal + ``c`` alone: fitted alone, or from ``x`` (an
            accepted effect's value in the final model, so the fit stays in its basin)."""
            if x is not None:
                return cross_validate(rp, [c], sc, [x], fl)
            f = sel.alone.get(c.name)
            return None if f is None else cross_validate(rp, [c], sc, None, fl, full=f)

        def improvement(cv):
            if cv is None or sel.baseline.sse <= 0:
                return 0.0
            return 1.0 - float(np.sqrt(cv.sse / sel.baseline.sse))

        common = dict(vehicle=rp.vehicle, selected=selected, frame=frame)
        effects = []
        for k, step in enumerate(sel.steps):
            c = step.candidate
            x, sd = sel.final.x[k], sel.final.sd[k]
            params, _ = public_params(c, x, sd, rp.vehicle, selected)
            effects.append(
                finding(
                    c,
                    x,
                    sd,
                    improvement=improvement(alone_cv(c, x)),
                    explanation=_explain(step, selected, params),
                    fold_x=[fx[k] for fx in sel.final_cv.fold_x],
                    gain=step.improvement_step,
                    at_bound=fit_at_bound(rp, sc, sel.final, k),
                    bound=lambda xf, k=k: fit_bound_mask(rp, sc, sel.final, k, xf),
                    **common,
                )
            )
        effects.sort(key=lambda e: -e.improvement)
        suspect, rejected = [], []
        for name, v in sel.verdicts.items():
            c = v.candidate
            cv_alone = alone_cv(c)
            if v.status == "suspect":
                j = list(v.fit.candidates).index(c)
                folds = [] if v.cv is None else [fx[j] for fx in v.cv.fold_x]
                suspect.append(
                    finding(
                        c,
                        v.x,
                        v.sd,
                        improvement=improvement(cv_alone),
                        explanation=f"{base_explanation(c.name)}. {v.reason}.",
                        fold_x=folds,
                        status="suspect",
                        reason=v.reason,
                        at_bound=True,
                        gain=v.gain,
                        bound=lambda xf, f=v.fit, j=j: fit_bound_mask(rp, sc, f, j, xf),
                        **common,
                    )
                )
            else:
                f = sel.alone.get(name, v.fit)
                j = list(f.candidates).index(c)
                rejected.append(
                    finding(
                        c,
                        f.x[j],
                        f.sd[j],
                        improvement=improvement(cv_alone),
                        explanation=base_explanation(c.name),
                        status="rejected",
                        reason=v.reason,
                        fold_x=[] if cv_alone is None else [fx[0] for fx in cv_alone.fold_x],
                        at_bound=fit_at_bound(rp, sc, f, j),
                        gain=v.gain,
                        bound=lambda xf, f=f, j=j: fit_bound_mask(rp, sc, f, j, xf),
                        **common,
                    )
                )
        suspect.sort(key=lambda e: -e.improvement)
        rejected.sort(key=lambda e: -e.improvement)
        alike = _indistinguishable(sel.verdicts, [e.name for e in rejected])
        if sel.unattributed is not None:  # a time constant the log cannot resolve is missing
            alike += (sel.unattributed.entry(),)
        table, model_ci = sc.channel_table(
            sel.baseline.residual, sel.final_cv.residual, rp.block_dur[sc.rows]
        )
        model_imp = sc.improvement(sel.baseline.residual, sel.final_cv.residual)
        where, regimes = locate(rp, base_res, sc.noise)
        verdict = (
            "mismatch"
            if effects or suspect or alike or _unexplained(rp, sc, base_res, where)
            else "consistent"
        )
        fold_of_block = np.zeros(rp.n_blocks, dtype=int)
        for i, idx in enumerate(fl):
            fold_of_block[idx] = i
        cands = [s.candidate for s in sel.steps]
        fold_terms = (
            [list(zip(cands, fx)) for fx in sel.final_cv.fold_x] if cands else [[] for _ in fl]
        )
        prediction = open_loop_errors(rec, rp, fold_terms, fold_of_block, cfg.horizons)
        series = {
            "block_t": rp.block_t,
            "baseline": sel.baseline.residual,
            "model": sel.final_cv.residual,
            "channels": rp.channels,
            "regimes": regimes,
            "replay": rp,
            "prediction": prediction,
            "scored": sc.rows,
            "masked": rp.masked,
            "calibration": rp.excluded,
        }
        side = recording_sidecar(rec, frame=frame)
        rmse_b = {ch: v["rmse_before"] for ch, v in table.items()}
        rmse_a = {ch: v["rmse_after"] for ch, v in table.items()}
        return DiagnosisResult(
            verdict=verdict,
            baseline_rmse=rmse_b,
            model_rmse=rmse_a,
            model_improvement=float(model_imp),
            effects=tuple(effects),
            untestable=tuple(untestable),
            not_identifiable=tuple(not_identifiable),
            assumptions=assumptions(ev, [e.name for e in effects]),
            evidence=ev.to_dict(),
            where=tuple(where),
            regimes=tuple(regimes),
            prediction={k: v for k, v in prediction.items() if not k.startswith("_")},
            channels=rp.channels,
            scale=tuple(float(s) for s in sc.noise),
            seconds=float(time.perf_counter() - t_start),
            scoring=_scoring_dict(rp, sc, rec, mask_note),
            suspect=tuple(suspect),
            rejected=tuple(rejected),
            indistinguishable=alike,
            channel_scores=table,
            model_ci95=tuple(model_ci),
            weights=tuple(float(w) for w in sc.weight),
            vehicle=side["vehicle"],
            frame=frame,
            gravity=float(side["gravity"]),
            series=series,
        )
