"""The estimator's part of the environment's observation and ``info``.

Estimators are chosen by name through the one registry (:mod:`estimators.registry`,
:func:`make_estimator`): ``"irls"``, ``"ekf"`` (and every other registered estimator), the
nominal belief ``"none"`` and the labelled oracle ``"truth"`` (the only way truth reaches an
observation; :mod:`estimators.baselines`). Every estimator gets the *nominal* vehicle and
measurement samples only. This module turns an estimate into the observation's and ``info``'s
fields.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from estimators.base import STATUS_OK, Estimate
from estimators.baselines import NOMINAL_PRIOR_SD, NominalBelief, TruthOracle
from estimators.irls_config import IRLSDiagnostics
from estimators.registry import ESTIMATORS, estimator_class, make_estimator
from quad_fault_env.observation import SD_MAX

#: the names the environments accept (the registry's)
ESTIMATOR_NAMES = tuple(ESTIMATORS)


def _registry_row(estimator):
    """The registry's row of ``estimator`` (by its ``name``), or None for an unregistered
    object."""
    return ESTIMATORS.get(getattr(estimator, "name", None))


def is_stateless(estimator) -> bool:
    """Whether ``estimator``'s estimate depends on the newest sample only: the registry's
    nominal belief and oracle (an estimator object that is not registered: False)."""
    row = _registry_row(estimator)
    return row is not None and row.role in ("nominal", "oracle")


def reads_truth(estimator) -> bool:
    """Whether ``estimator`` reads the episode's true efficiency schedule (the registry's
    oracle: the env binds the schedule with ``estimator.bind``)."""
    row = _registry_row(estimator)
    return row is not None and "truth" in row.needs


def estimate_sd(estimate: Estimate, n: int) -> np.ndarray | None:
    """The estimate's sd as a float array, or None when the estimator reports none."""
    if estimate.sd is None:
        return None
    sd = np.asarray(estimate.sd, dtype=float)
    return sd if sd.shape == (n,) else None


def diagnostics_dict(diagnostics):
    """An estimate's diagnostics as a plain dict (field -> value) when it is a dataclass, so
    ``info`` holds only dicts, arrays and scalars (Gymnasium compares infos field by field)."""
    if dataclasses.is_dataclass(diagnostics) and not isinstance(diagnostics, type):
        return {f.name: getattr(diagnostics, f.name) for f in dataclasses.fields(diagnostics)}
    return diagnostics


def diagnostics_template(estimator) -> dict:
    """The ``info["estimator_diagnostics"]`` of ``estimator`` before its first estimate: the
    keys and value types every later one has (a vector env batches info values by their first
    type and shape). The IRLS: the fields of :class:`estimators.irls_config.IRLSDiagnostics`
    with ``weights`` NaN over the window's segments; estimators without diagnostics: ``{}``."""
    config = getattr(estimator, "config", None)
    if getattr(estimator, "name", None) == "irls" and hasattr(config, "window"):
        return diagnostics_dict(
            IRLSDiagnostics("warmup", weights=np.full(config.window - 1, np.nan))
        )
    return {}


def _fixed_diagnostics(diagnostics, template: dict) -> dict:
    """``diagnostics`` as a dict with the template's keys: a value the estimate lacks (None,
    or an array of another shape) is the template's."""
    d = diagnostics_dict(diagnostics)
    if not template:
        return dict(d) if isinstance(d, dict) else {}
    d = d if isinstance(d, dict) else {}
    out = {}
    for key, default in template.items():
        value = d.get(key)
        if value is None or (isinstance(default, np.ndarray) and np.shape(value) != default.shape):
            value = default.copy() if isinstance(default, np.ndarray) else default
        out[key] = value
    return out


def estimate_info(estimate: Estimate, estimator, n: int, template: dict) -> dict:
    """The estimator's fields of ``info``, with the same keys, types and shapes at every reset
    and step (``gym.make_vec`` batches them): ``eta_hat`` (n,), ``eta_sd`` (n,) (the
    observation's value: :data:`~quad_fault_env.observation.SD_MAX` where the estimator reports
    no uncertainty), ``estimator`` (name), ``estimator_status`` (str) and
    ``estimator_diagnostics`` (a dict with the keys of ``template``,
    :func:`diagnostics_template`)."""
    sd = estimate_sd(estimate, n)
    return {
        "eta_hat": np.array(estimate.eta, dtype=float),
        "eta_sd": np.full(n, SD_MAX) if sd is None else sd.copy(),
        "estimator": getattr(estimator, "name", type(estimator).__name__),
        "estimator_status": str(estimate.status),
        "estimator_diagnostics": _fixed_diagnostics(estimate.diagnostics, template),
    }


__all__ = [
    "make_estimator",
    "estimator_class",
    "NominalBelief",
    "TruthOracle",
    "ESTIMATOR_NAMES",
    "NOMINAL_PRIOR_SD",
    "STATUS_OK",
    "estimate_sd",
    "is_stateless",
    "reads_truth",
    "diagnostics_dict",
    "diagnostics_template",
    "estimate_info",
]
