"""The diagnosis model: replay -> residuals -> locate -> library fit -> selection -> result.

``Diagnosis(config).fit(recording, vehicle=None) -> DiagnosisResult``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from quadfault.diagnosis.library import EXPLANATIONS, build_library, predict, public_params
from quadfault.diagnosis.residuals import noise_scale, prepare
from quadfault.diagnosis.result import DiagnosisResult, EffectFinding
from quadfault.diagnosis.select import (
    IV_MIN,
    IV_UNVERIFIED_GAIN,
    cross_validate,
    folds_of,
    scored_rows,
    select,
)
from quadfault.effects import EFFECT_NAMES
from quadfault.errors import ConfigError
from quadfault.recording import Recording


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
        screen_top: most candidates cross-validated per step (in BIC order).
        effects: restrict the library to these names (None: all).
        horizon: open-loop prediction horizon [s].
        saturate: clip commands to [0, max_thrust] as the nominal motor model does.
        internal_step: faster logs are merged to about this step [s] (see ``residuals``).
    """

    block_seconds: float = 0.02
    gap_factor: float = 2.5
    folds: int = 5
    max_effects: int = 3
    min_improvement: float = 0.05
    bic_margin: float = 10.0
    screen_top: int = 3
    effects: tuple | None = None
    horizon: float = 0.5
    saturate: bool = True
    internal_step: float = 0.004

    def __post_init__(self):
        if not (0 < self.block_seconds <= 1.0):
            raise ConfigError(f"block_seconds must be in (0, 1] s, got {self.block_seconds!r}")
        if not (self.gap_factor > 1):
            raise ConfigError("gap_factor must be > 1")
        if not (2 <= self.folds <= 20):
            raise ConfigError(f"folds must be in [2, 20], got {self.folds!r}")
        if not (0 <= self.max_effects <= 9):
            raise ConfigError("max_effects must be in [0, 9]")
        if self.effects is not None:
            bad = [e for e in self.effects if e not in EFFECT_NAMES]
            if bad:
                raise ConfigError(f"unknown effect {bad[0]!r}; choose from {', '.join(EFFECT_NAMES)}")
        if not (self.horizon > 0):
            raise ConfigError("horizon must be positive [s]")


def _rms(x, axis=None):
    return np.sqrt(np.mean(np.square(x), axis=axis))


def _explain(step, selected_names, params) -> str:
    name = step.candidate.name
    text = EXPLANATIONS[name] + f"; held-out residual RMS -{100 * step.improvement_step:.0f}% " \
                                "when added."
    partners = {"thrust_scale": "motor_efficiency", "motor_efficiency": "thrust_scale",
                "delay": "motor_lag", "motor_lag": "delay"}
    other = partners.get(name)
    ratio = step.rivals.get(other)
    if name == "thrust_scale":
        text += " Indistinguishable from motor_efficiency with equal eta (one class)."
    elif name == "motor_efficiency":
        eta = np.asarray(params["eta"])
        if np.ptp(eta) < 0.02:
            text += " The rotors are about equal: the same as thrust_scale (one class)."
    if other in ("delay", "motor_lag") and ratio is not None and ratio < 1.1:
        text += (f" {other} fits almost as well (in-sample SSE ratio {ratio:.2f}): the data "
                 "cannot separate delay from motor_lag (one timing class).")
    if name == "wind" and "drag" not in selected_names:
        text += " Force in the world frame; no drag identified, so no air velocity."
    if name == "wind" and "drag" in selected_names:
        text += " Air velocity = force / drag coefficient (horizontal mean of kx, ky)."
    if step.iv is not None and np.isfinite(step.iv):
        text += (f" Instrumental-variable check (instrument: the fitted signal with each "
                 f"block's inputs frozen at its start, blind to feedback on the block's own "
                 f"noise): slope {step.iv:.2f} (1 = all real, 0 = feedback bias; accepted "
                 f"when >= {IV_MIN} and significantly above 0).")
    elif step.iv is not None:
        text += (" The instrumental-variable check could not vouch for this signal (no "
                 "predictable part), so it was accepted only on a held-out gain of at least "
                 f"{IV_UNVERIFIED_GAIN:.0%}.")
    if name == "ground_effect":
        text += " Height above the ground is taken as -z of the recording (ground at z = 0)."
    return text


def _scoring(rp, rows) -> dict:
    out = {"scored_blocks": int(rows.sum()), "blocks": int(rp.n_blocks),
           "excluded_s": [list(seg) for seg in rp.excluded]}
    if rp.excluded:
        out["note"] = ("meta.calibration.segment: the importer fitted constants on these rows; "
                       "they are used for fitting but not for any held-out score")
    elif rp.scoring_note:
        out["note"] = rp.scoring_note
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
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):
            return self._fit(recording, vehicle, progress)

    def _fit(self, recording: Recording, vehicle, progress) -> DiagnosisResult:
        from quadfault.diagnosis.locate import locate
        from quadfault.diagnosis.prediction import open_loop_errors

        t_start = time.perf_counter()
        cfg = self.config
        rec = recording.without_truth() if isinstance(recording, Recording) else recording
        rp = prepare(rec, vehicle, block_seconds=cfg.block_seconds, gap_factor=cfg.gap_factor,
                     saturate=cfg.saturate, internal_step=cfg.internal_step)
        library = build_library(rp, cfg.effects)
        untestable = [c.name for c in library if not c.testable(rp)]
        base_res = rp.measured - predict(rp, [])
        scale = noise_scale(rp, base_res)
        kw = dict(folds=cfg.folds, max_effects=cfg.max_effects,
                  min_improvement=cfg.min_improvement, bic_margin=cfg.bic_margin,
                  screen_top=cfg.screen_top, progress=progress)
        sel = select(rp, library, scale, **kw)
        if sel.final is not None:
            # the first noise scale contains the effects' own fast content: re-estimate it from
            # what the selected model leaves and select again if it changed materially
            scale2 = noise_scale(rp, rp.measured - predict(rp, sel.final.terms))
            if np.any(np.abs(np.log(scale2 / scale)) > np.log(1.3)):
                scale = scale2
                sel = select(rp, library, scale, **kw)
        rows = scored_rows(rp)  # held-out scores never use calibration blocks
        before = _rms(sel.baseline.residual[rows] / scale)
        fl = folds_of(rp.n_blocks, cfg.folds)
        selected = {s.candidate.name: x for s, x in zip(sel.steps, sel.final.x)} if sel.final else {}
        findings = []
        for k, step in enumerate(sel.steps):
            c = step.candidate
            x, sd = sel.final.x[k], sel.final.sd[k]
            if k == 0:
                alone = step.cv
            else:
                alone = cross_validate(rp, [c], scale, [x], fl)
            imp = 1.0 - _rms(alone.residual[rows] / scale) / before
            params, unc = public_params(c, x, sd, rp.vehicle, selected)
            findings.append((imp, EffectFinding(c.name, params, unc, float(imp),
                                                _explain(step, selected, params))))
        findings.sort(key=lambda item: -item[0])
        after = _rms(sel.final_cv.residual[rows] / scale)
        model_imp = 1.0 - after / before if before > 0 else 0.0
        terms = sel.final.terms if sel.final else []
        where, regimes = locate(rp, base_res, scale)
        unexplained = before > 3.0 and not findings and len(where) > 0
        verdict = "mismatch" if findings or unexplained else "consistent"
        prediction = open_loop_errors(rec, rp, terms, cfg.horizon) if rp.has_pose else {}
        series = {"block_t": rp.block_t, "baseline": sel.baseline.residual,
                  "model": sel.final_cv.residual, "channels": rp.channels, "regimes": regimes,
                  "replay": rp, "prediction": prediction}
        return DiagnosisResult(
            verdict=verdict,
            baseline_rmse=dict(zip(rp.channels, map(float, _rms(sel.baseline.residual[rows], 0)))),
            model_rmse=dict(zip(rp.channels, map(float, _rms(sel.final_cv.residual[rows], 0)))),
            model_improvement=float(model_imp),
            effects=tuple(f for _, f in findings),
            untestable=tuple(untestable),
            where=tuple(where),
            regimes=tuple(r for r in regimes),
            prediction={k: v for k, v in prediction.items() if not k.startswith("_")},
            channels=rp.channels,
            scale=tuple(float(s) for s in scale),
            seconds=float(time.perf_counter() - t_start),
            scoring=_scoring(rp, rows),
            series=series,
        )
