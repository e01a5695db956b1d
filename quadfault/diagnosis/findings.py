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

from quadfault.diagnosis.crossval import fold_agreement
from quadfault.diagnosis.library import EXPLANATIONS, public_bounds, public_params
from quadfault.diagnosis.result import EffectFinding

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
) -> EffectFinding:
    """One reported effect (module docstring); the fold-agreement rule
    (:func:`~quadfault.diagnosis.crossval.fold_agreement`) is read from ``fold_x``, with
    ``bound(x)`` the parameters at a bound that matters."""
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
    return EffectFinding(
        cand.name,
        params,
        unc,
        float(improvement),
        explanation,
        bounds=public_bounds(cand),
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
