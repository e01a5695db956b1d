"""Which efficiency estimator fills the observation: a factory and the two trivial ones.

``make_estimator(name, vehicle, **kw)``:

* ``"irls"`` -- :class:`estimators.irls.SlidingWindowIRLS` (the paper's estimator);
* ``"ekf"``  -- :class:`estimators.ekf.MotorEfficiencyEKF` (the baseline);
* ``"truth"`` -- :class:`TruthOracle`, the explicitly labelled oracle that reads the true
  efficiency schedule (the only way truth reaches an observation);
* ``"none"`` -- :class:`NominalBelief`, always eta = 1 with a fixed prior uncertainty.

The real estimators are imported lazily, by name, so the environment works without them.
Every estimator gets the *nominal* vehicle and measurement samples only.
"""

from __future__ import annotations

import dataclasses
import importlib

import numpy as np

from estimators.base import STATUS_OK, Estimate, EstimateSeries, Sample, samples
from quad_fault_env.observation import SD_MAX
from quadfault.errors import ConfigError
from quadfault.vehicle import Vehicle

#: name -> ("module:Class") of the estimators that live in the ``estimators`` package.
ESTIMATOR_CLASSES = {
    "irls": "estimators.irls:SlidingWindowIRLS",
    "ekf": "estimators.ekf:MotorEfficiencyEKF",
}
ESTIMATOR_NAMES = ("irls", "ekf", "truth", "none")

#: the uncertainty the "none" belief reports for every motor [-]
NOMINAL_PRIOR_SD = 0.25


def _series(est, recording, progress=False) -> EstimateSeries:
    est.reset()
    rows = [est.update(s) for s in samples(recording)]
    return EstimateSeries(t=np.array([r.t for r in rows]), eta=np.array([r.eta for r in rows]),
                          sd=np.array([r.sd for r in rows]),
                          status=np.array([r.status for r in rows]), estimator=est.name)


class NominalBelief:
    """The "no estimator" belief: eta = 1 for every motor, sd = :data:`NOMINAL_PRIOR_SD`."""

    name = "none"

    def __init__(self, vehicle: Vehicle):
        self.n = vehicle.n_rotors

    def reset(self, eta0=None) -> None:
        pass

    def update(self, sample: Sample) -> Estimate:
        return Estimate(float(sample.t), np.ones(self.n), np.full(self.n, NOMINAL_PRIOR_SD))

    def run(self, recording, progress: bool = False) -> EstimateSeries:
        return _series(self, recording, progress)


class TruthOracle:
    """The labelled oracle: the true efficiency schedule evaluated at the sample time.

    The environment binds the episode's schedule with :meth:`bind`; sd is 0.
    """

    name = "truth"

    def __init__(self, vehicle: Vehicle, schedule=None):
        self.n = vehicle.n_rotors
        self.schedule = schedule

    def bind(self, schedule) -> None:
        """Use ``schedule`` (``t -> (4,)`` true efficiency) from now on."""
        self.schedule = schedule

    def reset(self, eta0=None) -> None:
        pass

    def update(self, sample: Sample) -> Estimate:
        if self.schedule is None:
            raise ConfigError("the truth oracle has no efficiency schedule bound (call bind)")
        eta = np.asarray(self.schedule(float(sample.t)), dtype=float)
        return Estimate(float(sample.t), eta, np.zeros(self.n))

    def run(self, recording, progress: bool = False) -> EstimateSeries:
        return _series(self, recording, progress)


def estimator_class(name: str):
    """The class of a lazily imported estimator (``"irls"`` or ``"ekf"``)."""
    module_name, cls_name = ESTIMATOR_CLASSES[name].split(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name != module_name:
            raise
        raise ConfigError(f"estimator {name!r} is not available: module {module_name} "
                          "is not installed in this checkout") from None
    try:
        return getattr(module, cls_name)
    except AttributeError:
        raise ConfigError(f"estimator {name!r}: {module_name} has no {cls_name}") from None


def make_estimator(name, vehicle: Vehicle, **kwargs):
    """An online estimator by name (see the module docstring), or ``name`` itself when it is
    already an estimator object (anything with ``reset`` and ``update``).

    ``kwargs`` go to the estimator's constructor (``config=...`` for IRLS / EKF,
    ``schedule=...`` for the oracle).
    """
    if not isinstance(name, str):
        if callable(getattr(name, "update", None)) and callable(getattr(name, "reset", None)):
            return name
        raise ConfigError(f"estimator must be one of {ESTIMATOR_NAMES} or an object with "
                          f"reset() and update(sample), got {name!r}")
    if name == "none":
        return NominalBelief(vehicle)
    if name == "truth":
        return TruthOracle(vehicle, **kwargs)
    if name in ESTIMATOR_CLASSES:
        return estimator_class(name)(vehicle, **kwargs)
    raise ConfigError(f"unknown estimator {name!r}; choose from {', '.join(ESTIMATOR_NAMES)}")


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
        from estimators.irls_config import IRLSDiagnostics

        return diagnostics_dict(IRLSDiagnostics("warmup",
                                                weights=np.full(config.window - 1, np.nan)))
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
        if value is None or (isinstance(default, np.ndarray)
                             and np.shape(value) != default.shape):
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


__all__ = ["make_estimator", "estimator_class", "NominalBelief", "TruthOracle", "ESTIMATOR_NAMES",
           "NOMINAL_PRIOR_SD", "STATUS_OK", "estimate_sd", "diagnostics_dict",
           "diagnostics_template", "estimate_info"]
