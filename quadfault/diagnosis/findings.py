"""Turn the selection into reported findings: parameters, bounds, folds, frames, text.

Every fitted effect -- accepted, suspect or rejected -- is reported the same way:
``params`` and ``uncertainty`` (one sigma, from the Jacobian), ``bounds`` ``{key: [lo, hi]}``
(the library's bounds through the same mapping as the parameters, the same shape as each
parameter), ``folds`` ``{key: [value of fold 1, ...]}`` (each fold's fit without that fold)
with ``folds_agree`` / ``fold_agreement`` (the fold-agreement rule on them) and
``improvement`` (held-out, nominal model plus this effect alone).

Frames: parameters that are vectors in the world or body frame
(:attr:`~quadfault.diagnosis.library.Candidate.frames`) are given in the recording's own
frame -- NED/FRD, or ENU/FLU for an ENU file (``x_ENU = y_NED, y_ENU = x_NED, z_ENU =
-z_NED``; ``x_FLU = x_FRD, y_FLU = -y_FRD, z_FLU = -z_FRD``) -- and the explanation says so.
"""

from __future__ import annotations

import numpy as np

from quadfault.diagnosis.crossval import fold_agreement
from quadfault.diagnosis.library import EXPLANATIONS, public_params
from quadfault.diagnosis.result import EffectFinding

FRAME_TEXT = {("world", "NED"): "world frame NED (x north, y east, z down)",
              ("world", "ENU"): "world frame ENU (x east, y north, z up), as the recording",
              ("body", "NED"): "body frame FRD (x forward, y right, z down)",
              ("body", "ENU"): "body frame FLU (x forward, y left, z up), as the recording"}


def to_frame(value, kind: str, frame: str):
    """A world/body vector (2 or 3 components, NED/FRD) in the recording's ``frame``."""
    v = np.asarray(value, dtype=float)
    if frame != "ENU" or v.ndim != 1 or len(v) not in (2, 3):
        return value
    if kind == "world":
        out = np.r_[v[1], v[0], -v[2]] if len(v) == 3 else np.r_[v[1], v[0]]
    else:
        out = v * np.array([1.0, -1.0, -1.0])[: len(v)]
    return out.tolist()


def _framed(d: dict, frames: dict, frame: str, sd=False) -> dict:
    out = {}
    for k, v in d.items():
        if k in frames:
            v = to_frame(v, frames[k], frame)
            if sd:
                v = np.abs(v).tolist()
        out[k] = v
    return out


def bounds_of(cand, vehicle, selected: dict, frame: str) -> dict:
    """``{key: [lo, hi]}`` of every public parameter of ``cand`` (``lo``/``hi`` shaped like the
    parameter; in the recording's frame)."""
    frames = dict(cand.frames)
    zero = np.zeros(cand.size)
    lo, _ = public_params(cand, np.asarray(cand.lower, float), zero, vehicle, selected)
    hi, _ = public_params(cand, np.asarray(cand.upper, float), zero, vehicle, selected)
    out = {}
    for k in lo:
        a, b = lo[k], hi[k]
        if k in frames:
            a, b = to_frame(a, frames[k], frame), to_frame(b, frames[k], frame)
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        pair = np.minimum(a, b), np.maximum(a, b)
        out[k] = [x.tolist() if x.ndim else float(x) for x in pair]
    return out


def folds_of_params(cand, fold_x, vehicle, selected: dict, frame: str) -> dict:
    """``{key: [value per fold]}`` of the public parameters."""
    frames = dict(cand.frames)
    out = {}
    zero = np.zeros(cand.size)
    for x in fold_x:
        p, _ = public_params(cand, np.asarray(x, float), zero, vehicle, selected)
        for k, v in _framed(p, frames, frame).items():
            out.setdefault(k, []).append(np.asarray(v, dtype=float).tolist())
    return out


def finding(cand, x, sd, *, vehicle, selected: dict, frame: str, improvement: float,
            explanation: str, fold_x=(), status: str = "accepted", reason: str = "",
            at_bound: bool = False, gain: float | None = None) -> EffectFinding:
    """One reported effect (module docstring); the fold-agreement rule
    (:func:`~quadfault.diagnosis.crossval.fold_agreement`) is read from ``fold_x``."""
    frames = dict(cand.frames)
    params, unc = public_params(cand, np.asarray(x, float), np.asarray(sd, float), vehicle,
                                selected)
    params = _framed(params, frames, frame)
    unc = _framed(unc, frames, frame, sd=True)
    kinds = sorted({frames[k] for k in params if k in frames})
    if kinds:
        explanation += " Directions in the " + " and the ".join(
            FRAME_TEXT[(kind, frame if frame == "ENU" else "NED")] for kind in kinds) + "."
    agree, detail = fold_agreement(cand, x, fold_x) if len(fold_x) else (None, "")
    return EffectFinding(cand.name, params, unc, float(improvement), explanation,
                         bounds=bounds_of(cand, vehicle, selected, frame),
                         folds=folds_of_params(cand, fold_x, vehicle, selected, frame),
                         status=status, reason=reason, at_bound=bool(at_bound),
                         improvement_when_added=None if gain is None else float(gain),
                         fold_agreement=detail, folds_agree=agree)


def base_explanation(name: str) -> str:
    return EXPLANATIONS.get(name, name.replace("_", " "))
