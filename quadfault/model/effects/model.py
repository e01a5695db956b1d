"""The fitted model as a simulator: load a diagnosis (``quadfault-diagnosis/2``).

:func:`from_diagnosis` is the one loader of a diagnosis JSON used by ``quadfault simulate
--model`` and by the environments: the nominal vehicle the diagnosis started from plus the
accepted effects with their fitted parameters (and their reported one-sigma uncertainty and
bounds, so a caller can draw parameters with :meth:`DiagnosedModel.sample`).

Fields read (everything else is ignored):

* ``format`` -- must be ``"quadfault-diagnosis/2"``;
* ``vehicle`` -- the recording sidecar's vehicle object (docs/formats.md: ``mass``,
  ``inertia``, ``allocation`` or ``arm`` + ``torque_coefficient``, optional ``max_thrust``,
  ``thrust_curve`` / ``thrust_coefficient`` for ``u`` commands), in the recording's frame;
* ``frame`` -- ``"NED"`` (default) or ``"ENU"``: the frame of ``vehicle`` and of the effects'
  direction parameters (world ``force_N``, ``air_velocity_m_per_s``; body ``offset_m``);
* ``gravity`` [m/s^2] -- top level or in ``vehicle`` (default 9.81);
* ``effects`` -- a list of ``{"name", "params", "uncertainty"?, "bounds"?}``; ``params`` use
  the keys of the effect classes' ``params()`` (docs/formats.md, diagnosis results).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quadfault.errors import ConfigError, QuadfaultError
from quadfault.model.effects.spec import EFFECTS, canonical_order
from quadfault.model.effects.thrust_curve import IDENTITY_CURVE, ThrustCurve
from quadfault.model.sidecar import vehicle_from_sidecar

FORMAT = "quadfault-diagnosis/2"
#: direction parameters: world vectors (3) and in-plane body vectors (2)
WORLD_VECTORS = ("force_N", "air_velocity_m_per_s")
BODY_VECTORS = ("offset_m",)


def frame_vectors(params: dict, frame: str, magnitude: bool = False) -> dict:
    """Direction parameters of a reported effect between NED / FRD and ``frame`` (for
    ``"ENU"``: world ENU, body FLU; the map is an involution, so the same call converts both
    ways). ``magnitude``: values are one-sigma uncertainties (kept non-negative)."""
    out = dict(params)
    if frame == "NED":
        return out
    for key in WORLD_VECTORS:
        if key in out and out[key] is not None:
            x, y, z = (float(c) for c in out[key])
            out[key] = [y, x, -z]
    for key in BODY_VECTORS:
        if key in out and out[key] is not None:
            x, y = (float(c) for c in out[key])
            out[key] = [x, -y]
    if magnitude:
        for key in WORLD_VECTORS + BODY_VECTORS:
            if key in out and out[key] is not None:
                out[key] = [abs(v) for v in out[key]]
    return out


@dataclass(frozen=True)
class FittedEffect:
    """One accepted effect of a diagnosis (parameters in NED / FRD).

    Attributes:
        name: canonical effect name.
        params, uncertainty, bounds: as reported (one-sigma ``uncertainty``; ``bounds``
            ``{"key": [lo, hi]}``), direction parameters converted to NED / FRD.
        effect: the plant effect with the fitted parameters.
    """

    name: str
    params: dict
    uncertainty: dict
    bounds: dict
    effect: object


@dataclass(frozen=True)
class DiagnosedModel:
    """The nominal vehicle plus the accepted effects of a diagnosis.

    Attributes:
        vehicle: the nominal vehicle (FRD) -- what the controller and recordings know.
        thrust_curve: the nominal ``(a, b, c)`` command-to-thrust curve for ``u`` commands,
            or None (commands are thrusts in newtons).
        fitted: the accepted effects (:class:`FittedEffect`), in canonical order.
        frame: the frame of the diagnosed recording (``"NED"`` or ``"ENU"``).
        source: where it was loaded from.
    """

    vehicle: object
    thrust_curve: tuple | None
    fitted: tuple
    frame: str = "NED"
    source: str = ""

    @property
    def effects(self) -> tuple:
        """The plant effects with the fitted parameters (canonical order)."""
        return tuple(f.effect for f in self.fitted)

    def sample(self, rng: np.random.Generator) -> tuple:
        """Plant effects with every reported parameter drawn from a normal distribution of
        its reported value and one-sigma uncertainty, clipped to its reported bounds
        (parameters without uncertainty keep their value)."""
        out = []
        for fe in self.fitted:
            params = dict(fe.params)
            for key, sd in fe.uncertainty.items():
                if key not in params or sd is None:
                    continue
                x = np.asarray(params[key], dtype=float)
                s = np.nan_to_num(np.asarray(sd, dtype=float), nan=0.0)
                draw = x + np.abs(s) * rng.standard_normal(x.shape)
                if key in fe.bounds:
                    lo, hi = fe.bounds[key]
                    draw = np.clip(draw, lo, hi)
                params[key] = draw.tolist()
            out.append(EFFECTS[fe.name].from_params(params))
        return tuple(out)


def _fail(where, key, message):
    raise ConfigError(f"{where}, key '{key}': {message}" if key else f"{where}: {message}")


def _load(source) -> tuple[dict, str]:
    if isinstance(source, dict):
        return source, "diagnosis"
    path = Path(source)
    if not path.is_file():
        raise ConfigError(f"{path}: diagnosis JSON not found")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not UTF-8 text") from None
    except json.JSONDecodeError as exc:
        raise ConfigError(
            f"{path}: invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}"
        ) from None
    except RecursionError:
        raise ConfigError(f"{path}: invalid JSON: nested too deeply") from None
    if not isinstance(doc, dict):
        raise ConfigError(f"{path}: a diagnosis must be a JSON object")
    return doc, str(path)


def _vehicle(doc: dict, where: str, frame: str):
    vd = doc.get("vehicle")
    if not isinstance(vd, dict):
        _fail(
            where,
            "vehicle",
            "missing or not an object (the diagnosis' nominal vehicle, "
            "written by quadfault diagnose)",
        )
    gravity = doc.get("gravity", vd.get("gravity", 9.81))
    has_u = "thrust_curve" in vd or "thrust_coefficient" in vd
    try:
        return vehicle_from_sidecar(
            where, {"vehicle": vd, "frame": frame, "gravity": gravity}, has_u
        )
    except QuadfaultError as exc:
        raise ConfigError(str(exc)) from None


def _number_tree(value):
    """Whether ``value`` is a finite number or a (nested) list of them."""
    if isinstance(value, bool):
        return False
    if isinstance(value, (int, float)):
        return bool(np.isfinite(value))
    if isinstance(value, list):
        return all(_number_tree(v) for v in value)
    return False


def _fitted(entry, k: int, where: str, frame: str, curve) -> FittedEffect:
    key = f"effects[{k}]"
    if not isinstance(entry, dict):
        _fail(where, key, 'must be an object {"name", "params", ...}')
    name = entry.get("name")
    if name not in EFFECTS:
        _fail(where, f"{key}.name", f"unknown effect {name!r}; choose from {', '.join(EFFECTS)}")
    parts = {}
    for part in ("params", "uncertainty", "bounds"):
        value = entry.get(part, {} if part != "params" else None)
        if value is None and part != "params":
            value = {}
        if not isinstance(value, dict):
            _fail(where, f"{key}.{part}", "missing or not an object")
        parts[part] = value
    for pkey, value in parts["params"].items():
        if not (_number_tree(value) or isinstance(value, str) or value is None):
            _fail(where, f"{key}.params.{pkey}", f"must be numbers, got {value!r}")
    params = frame_vectors(parts["params"], frame)
    unc = frame_vectors(parts["uncertainty"], frame, magnitude=True)
    unc = {p: [abs(x) for x in v] if isinstance(v, list) else v for p, v in unc.items()}
    bounds = {p: v for p, v in parts["bounds"].items() if isinstance(v, list) and len(v) == 2}
    if name == ThrustCurve.name and "nominal_curve" not in params:
        params["nominal_curve"] = list(curve or IDENTITY_CURVE)
    try:
        effect = EFFECTS[name].from_params(params)
    except (QuadfaultError, TypeError, ValueError) as exc:
        _fail(where, f"{key}.params", str(exc))
    return FittedEffect(name, params, unc, bounds, effect)


def from_diagnosis(source) -> DiagnosedModel:
    """The nominal vehicle and the accepted effects of a diagnosis JSON (a path or the parsed
    object). Raises a one-line :class:`~quadfault.errors.ConfigError` naming the file and the
    key for a malformed or wrong-format document."""
    doc, where = _load(source)
    fmt = doc.get("format")
    if fmt != FORMAT:
        hint = " (written by an older quadfault diagnose: run it again)" if fmt is None else ""
        _fail(where, "format", f"expected {FORMAT!r}, got {fmt!r}{hint}")
    frame = doc.get("frame", "NED")
    if frame not in ("NED", "ENU"):
        _fail(where, "frame", f"must be 'NED' or 'ENU', got {frame!r}")
    vehicle, curve = _vehicle(doc, where, frame)
    effects = doc.get("effects")
    if not isinstance(effects, list):
        _fail(where, "effects", "missing or not a list")
    fitted = [_fitted(e, k, where, frame, curve) for k, e in enumerate(effects)]
    names = [f.name for f in fitted]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        _fail(where, "effects", f"effect {min(dup)!r} appears twice")
    order = {id(e): k for k, e in enumerate(canonical_order([f.effect for f in fitted]))}
    fitted.sort(key=lambda f: order[id(f.effect)])
    return DiagnosedModel(vehicle, curve, tuple(fitted), frame, where)
