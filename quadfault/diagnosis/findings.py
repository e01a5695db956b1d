"""Turn the selection into reported findings: parameters, bounds, folds, frames, text.

Every fitted effect -- accepted, suspect or rejected -- is reported the same way:
``params`` and ``uncertainty`` (one sigma, from the Jacobian), ``bounds`` ``{key: [lo, hi]}``
(the library's bounds in the keys of the fitted parameters; numbers when every element of a
vector has the same bounds, else lists), ``folds`` ``{key: [value of fold 1, ...]}`` (each fold's fit without that fold)
with ``folds_agree`` / ``fold_agreement`` (the fold-agreement rule on them) and
``improvement`` (held-out, nominal model plus this effect alone).

Frames: parameters that are vectors in the world or body frame
(:attr:`~quadfault.model.effects.candidate.Candidate.frames`) are given in the recording's own
frame (``library.public_params(..., frame=)``: NED/FRD, or ENU/FLU for an ENU file) and the
explanation says which. Bounds (``library.public_bounds``) are symmetric for direction
parameters, so they read the same in every frame.
"""

from __future__ import annotations

import numpy as np

from quadfault.diagnosis.crossval import (
    cross_validate,
    fit_at_bound,
    fit_bound_mask,
    fold_agreement,
)
from quadfault.diagnosis.feedback import IV_MIN, IV_UNVERIFIED_GAIN, partly_real
from quadfault.diagnosis.library import (
    EQUIVALENT,
    EXPLANATIONS,
    build_library,
    public_bounds,
    public_params,
)
from quadfault.diagnosis.result import EffectFinding, short
from quadfault.diagnosis.rivals import alone_at_folds, tie_verdict
from quadfault.model.effects.registry import effect_class

FRAME_TEXT = {
    ("world", "NED"): "world frame NED (x north, y east, z down)",
    ("world", "ENU"): "world frame ENU (x east, y north, z up), as the recording",
    ("body", "NED"): "body frame FRD (x forward, y right, z down)",
    ("body", "ENU"): "body frame FLU (x forward, y left, z up), as the recording",
}


def folds_of_params(cand, fold_x, vehicle, selected: dict, frame: str) -> dict:
    """``{key: [value per fold]}`` of the public parameters (in the recording's frame)."""
    out = {}
    zero = np.zeros(cand.size)
    for x in fold_x:
        p, _ = public_params(cand, np.asarray(x, float), zero, vehicle, selected, frame=frame)
        for k, v in p.items():
            out.setdefault(k, []).append(np.asarray(v, dtype=float).tolist())
    return out


def finding(
    cand,
    x,
    sd,
    *,
    vehicle,
    selected: dict,
    frame: str,
    improvement: float,
    explanation: str,
    fold_x=(),
    status: str = "accepted",
    reason: str = "",
    at_bound: bool = False,
    gain: float | None = None,
    bound=None,
    free=None,
) -> EffectFinding:
    """One reported effect (module docstring); the fold-agreement rule
    (:func:`~quadfault.diagnosis.crossval.fold_agreement`) is read from ``fold_x``, with
    ``bound(x)`` the parameters at a bound that matters. A candidate held by direct evidence
    (``pinned``: a time constant from command to measured rotor speed) reports the bounds of
    ``free`` (the same candidate before it was pinned) and ``pinned_by``."""
    frames = dict(cand.frames)
    params, unc = public_params(
        cand, np.asarray(x, float), np.asarray(sd, float), vehicle, selected, frame=frame
    )
    kinds = sorted({frames[k] for k in params if k in frames})
    if kinds:
        explanation += (
            " Directions in the "
            + " and the ".join(
                FRAME_TEXT[(kind, frame if frame == "ENU" else "NED")] for kind in kinds
            )
            + "."
        )
    agree, detail = fold_agreement(cand, x, fold_x, bound) if len(fold_x) else (None, "")
    bounds = public_bounds(cand, np.asarray(x, float))
    pinned_by = {}
    if cand.pinned:
        bounds = public_bounds(free if free is not None else cand)
        pinned_by = {k: "rotor_speed" for k in bounds}
    return EffectFinding(
        cand.name,
        params,
        unc,
        float(improvement),
        explanation,
        bounds=bounds,
        pinned_by=pinned_by,
        folds=folds_of_params(cand, fold_x, vehicle, selected, frame),
        status=status,
        reason=reason,
        at_bound=bool(at_bound),
        improvement_when_added=None if gain is None else float(gain),
        fold_agreement=detail,
        folds_agree=agree,
    )


def base_explanation(name: str) -> str:
    return EXPLANATIONS.get(name, name.replace("_", " "))


def explain_accepted(step, selected_names, params) -> str:
    name = step.candidate.name
    if step.dropped:
        text = (
            base_explanation(name) + f"; held-out residual RMS {100 * step.improvement_step:.1f}% "
            "lower with it than without it (the other accepted effects refitted)."
        )
    else:
        text = (
            base_explanation(name)
            + f"; held-out residual RMS -{100 * step.improvement_step:.1f}% when added."
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


class Findings:
    """The reported findings of a :class:`~quadfault.diagnosis.select.Selection` on one
    recording (its ``replay``, fixed ``scoring`` and cross-validation ``folds``), parameters in the recording's
    ``frame``: :meth:`accepted`, :meth:`suspects` and :meth:`rejected`, each most important
    first (held-out improvement alone)."""

    def __init__(self, replay, scoring, selection, folds, frame: str):
        self.replay, self.scoring, self.selection, self.frame = replay, scoring, selection, frame
        self.folds = folds
        final = selection.final
        self.selected = {c.name: x for c, x in final.terms} if final else {}
        self._free = {}

    def _common(self, c) -> dict:
        if c.pinned and c.name not in self._free:
            self._free[c.name] = build_library(self.replay, (c.name,))[0]
        return dict(
            vehicle=self.replay.vehicle,
            selected=self.selected,
            frame=self.frame,
            free=self._free.get(c.name),
        )

    def alone_cv(self, c, x=None):
        """Held-out result of nominal + ``c`` alone: fitted alone, or from ``x`` (an
        accepted effect's value in the final model, so the fit stays in its basin)."""
        if x is not None:
            return cross_validate(self.replay, [c], self.scoring, [x], self.folds)
        f = self.selection.alone.get(c.name)
        if f is None:
            return None
        return cross_validate(self.replay, [c], self.scoring, None, self.folds, full=f)

    def accepted_alone(self, c, k: int, x, step=None) -> float:
        """The held-out improvement of nominal + the accepted effect ``c`` (``k``-th of the
        final model, at ``x``) alone: the better of its values in the final model fitted
        without each fold (:func:`~quadfault.diagnosis.rivals.alone_at_folds`) and a fit
        alone started from ``x``. When another accepted effect cancels its signal on the
        nominal model (alone it does not improve it), its part beside the rest instead: the
        held-out RMS the final model removes over the model without it (``step``'s gain,
        from :meth:`~quadfault.diagnosis.rivals.Rivals.supported`), in units of the nominal
        RMS."""
        sel, base = self.selection, self.selection.baseline.sse
        if base <= 0:
            return 0.0
        fold_x = [fx[k] for fx in sel.final_cv.fold_x]
        sse = alone_at_folds(self.replay, self.scoring, self.folds, c, fold_x)
        sse = min(sse, self.alone_cv(c, x).sse)
        alone = 1.0 - float(np.sqrt(sse / base))
        if alone > 0.0 or step is None or not step.dropped or step.improvement_step >= 1.0:
            return alone
        final = float(np.sqrt(sel.final_cv.sse / base))
        return max(alone, final * (1.0 / (1.0 - step.improvement_step) - 1.0))

    def improvement(self, cv) -> float:
        """``1 - RMS(held out) / RMS(nominal, held out)`` of ``cv`` (0 without one)."""
        base = self.selection.baseline.sse
        if cv is None or base <= 0:
            return 0.0
        return 1.0 - float(np.sqrt(cv.sse / base))

    def accepted(self) -> list:
        rp, sc, sel = self.replay, self.scoring, self.selection
        out = []
        index = {c.name: k for k, c in enumerate(sel.final.candidates)} if sel.final else {}
        for step in sel.steps:
            c = step.candidate
            k = index[c.name]
            x, sd = sel.final.x[k], sel.final.sd[k]
            params, _ = public_params(c, x, sd, rp.vehicle, self.selected)
            out.append(
                finding(
                    c,
                    x,
                    sd,
                    improvement=self.accepted_alone(c, k, x, step),
                    explanation=explain_accepted(step, self.selected, params),
                    fold_x=[fx[k] for fx in sel.final_cv.fold_x],
                    gain=step.improvement_step,
                    at_bound=fit_at_bound(rp, sc, sel.final, k),
                    bound=lambda xf, k=k: fit_bound_mask(rp, sc, sel.final, k, xf),
                    **self._common(c),
                )
            )
        out.sort(key=lambda e: -e.improvement)
        return out

    def suspects(self) -> list:
        rp, sc = self.replay, self.scoring
        out = []
        for v in self.selection.verdicts.values():
            if v.status != "suspect":
                continue
            c = v.candidate
            j = list(v.fit.candidates).index(c)
            folds = [] if v.cv is None else [fx[j] for fx in v.cv.fold_x]
            out.append(
                finding(
                    c,
                    v.x,
                    v.sd,
                    improvement=self.improvement(self.alone_cv(c)),
                    explanation=f"{base_explanation(c.name)}. {v.reason}.",
                    fold_x=folds,
                    status="suspect",
                    reason=v.reason,
                    at_bound=True,
                    gain=v.gain,
                    bound=lambda xf, f=v.fit, j=j: fit_bound_mask(rp, sc, f, j, xf),
                    **self._common(c),
                )
            )
        out.sort(key=lambda e: -e.improvement)
        return out

    def rejected(self) -> list:
        """Each rejected candidate as fitted alone on the nominal model, or as judged where
        that was within a set fitted after the search (a rival, the final model)."""
        rp, sc = self.replay, self.scoring
        out = []
        for name, v in self.selection.verdicts.items():
            if v.status == "suspect":
                continue
            c = v.candidate
            cv_alone = self.alone_cv(c)
            f = v.fit if v.in_set else self.selection.alone.get(name, v.fit)
            j = list(f.candidates).index(c)
            out.append(
                finding(
                    c,
                    f.x[j],
                    f.sd[j],
                    improvement=self.improvement(cv_alone),
                    explanation=base_explanation(c.name),
                    status="rejected",
                    reason=v.reason,
                    fold_x=(
                        [fx[j] for fx in v.cv.fold_x]
                        if v.in_set and v.cv is not None
                        else []
                        if cv_alone is None
                        else [fx[0] for fx in cv_alone.fold_x]
                    ),
                    at_bound=fit_at_bound(rp, sc, f, j),
                    gain=v.gain,
                    bound=lambda xf, f=f, j=j: fit_bound_mask(rp, sc, f, j, xf),
                    **self._common(c),
                )
            )
        out.sort(key=lambda e: -e.improvement)
        return out

    def tied(self, c, comparison):
        """The ``rejected`` finding of effect ``c`` of a tied rival comparison: its fit in
        its own set, the reason naming the other set."""
        from_set = tie_verdict(c, comparison)
        f = from_set.fit
        j = [o.name for o in f.candidates].index(c.name)
        return finding(
            c,
            f.x[j],
            f.sd[j],
            improvement=self.improvement(self.alone_cv(c, f.x[j])),
            explanation=base_explanation(c.name),
            status="rejected",
            reason=from_set.reason,
            fold_x=[fx[j] for fx in from_set.cv.fold_x],
            at_bound=False,
            **self._common(c),
        )

    def alternative(self, rival_set) -> list:
        """The effects of one explanation (a :class:`~quadfault.diagnosis.rivals.RivalSet`)
        as reported: ``[{"name", "params", "uncertainty", "bounds"}, ...]``."""
        f = rival_set.fit
        selected = {c.name: x for c, x in f.terms}
        return [
            self._effect(c, f.x[j], f.sd[j], selected)
            for j, c in enumerate(f.candidates)
            if c.name in rival_set.names
        ]

    def _effect(self, c, x, sd, selected) -> dict:
        """One effect of an ``indistinguishable`` set as reported: ``{"name", "params",
        "uncertainty", "bounds"}`` at ``x`` (one-sigma ``sd``), beside ``selected``."""
        x = np.asarray(x, dtype=float)
        params, unc = public_params(c, x, sd, self.replay.vehicle, selected, frame=self.frame)
        return {"name": c.name, "params": params, "uncertainty": unc, "bounds": public_bounds(c, x)}

    def indistinguishable(self, comparison) -> dict:
        """The ``indistinguishable`` entry of a tied
        :class:`~quadfault.diagnosis.rivals.RivalComparison`."""
        a, b = comparison.sets
        g = comparison.gain_of(b)
        sets = [self.alternative(a), self.alternative(b)]
        labels = [" + ".join(short(e["name"], e["params"]) for e in one) for one in sets]
        return {
            "names": list(a.names) + list(b.names),
            "sets": sets,
            "held_out": {
                "improvement": g.gain,
                "best_channel": g.best,
                "ci95_low": g.lo,
                "of": " + ".join(b.names),
                "over": " + ".join(a.names),
            },
            "summary": f"{labels[0]} or {labels[1]}",
            "reason": (
                f"this flight cannot tell {' + '.join(a.names)} from {' + '.join(b.names)}: "
                f"fitted in each other's place on the same held-out folds, "
                f"{' + '.join(b.names)} has a held-out gain of {_pct(g.gain)} over "
                f"{' + '.join(a.names)} (95% interval from {_pct(g.lo)}): too small or too "
                "uncertain to decide either way (a set wins with 1% and its interval above "
                "0); one of the two is likely there"
            ),
            "separate_by": comparison.separate_by,
        }

    def closed_loop(self, skip=()) -> dict | None:
        """The ``indistinguishable`` entry of the effects the closed loop hides: each rejected
        only by the instrumental-variable check, after a significant held-out gain over the
        model before it, with a slope that still shows real signal
        (:func:`~quadfault.diagnosis.feedback.partly_real`). One of them is likely there,
        smaller than fitted (the loop inflated each fit); this flight cannot say which nor
        how large. None when there is none. ``skip``: names reported elsewhere."""
        hidden = [
            v
            for name, v in sorted(self.selection.verdicts.items())
            if name not in skip
            and v.status == "rejected"
            and v.gain is not None
            and v.gain > 0.0
            and partly_real(v.iv, v.iv_se)
        ]
        if not hidden:
            return None
        hidden.sort(key=lambda v: -v.gain)
        sets = []
        for v in hidden:
            c = v.candidate
            # sized by the slope: the part of the fitted departure from nominal that is real
            x, x0 = np.asarray(v.x, float), np.asarray(c.x0, float)
            sized = x0 + v.iv * (x - x0)
            sd = np.hypot(v.iv * np.asarray(v.sd, float), v.iv_se * np.abs(x - x0))
            entry = self._effect(c, sized, sd, self.selected)
            entry["as_fitted"], _ = public_params(
                c, x, np.asarray(v.sd, float), self.replay.vehicle, self.selected, frame=self.frame
            )
            sets.append([entry])
        names = [v.candidate.name for v in hidden]
        slopes = ", ".join(f"{v.candidate.name} {v.iv:.2f} +- {v.iv_se:.2f}" for v in hidden)
        return {
            "names": names,
            "sets": sets,
            "held_out": {
                "improvement": {v.candidate.name: float(v.gain) for v in hidden},
                "iv_slope": {v.candidate.name: float(v.iv) for v in hidden},
                "iv_se": {v.candidate.name: float(v.iv_se) for v in hidden},
            },
            "summary": " or ".join(short(one[0]["name"], one[0]["params"]) for one in sets),
            "reason": (
                f"the closed loop hides {' or '.join(names)}: each improves the held-out fit "
                f"over the flight ({', '.join(_pct(v.gain) for v in hidden)}), but the "
                "controller's reaction to its own disturbances inflates the fit, and only "
                f"part of the fitted signal is real (instrumental-variable slope {slopes}; 1 "
                f"when all of it is, {IV_MIN} needed to accept); one of them is likely there, "
                "smaller than as fitted (each set gives its fitted departure from nominal "
                "scaled by its slope, and `as_fitted`), and this flight cannot say which"
            ),
            "separate_by": (
                "open-loop excitation (steps or a chirp added to the commands), measured rotor "
                "speeds, or faster command logging (a lag or delay against an inertia)"
            ),
        }


def _pct(v) -> str:
    return f"{round(v, 3) + 0.0:+.1%}"
