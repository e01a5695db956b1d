"""The two beliefs that estimate nothing: the nominal belief and the labelled truth oracle.

* :class:`NominalBelief` (``"none"``): always eta = 1 with a fixed prior uncertainty
  (:data:`NOMINAL_PRIOR_SD`), the "no estimator" baseline of the environments;
* :class:`TruthOracle` (``"truth"``): the explicitly labelled oracle that reads the episode's
  true efficiency schedule (bound with :meth:`TruthOracle.bind`), the only way truth reaches
  an observation.

Both implement :class:`estimators.base.OnlineEstimator` and are registered in
:mod:`estimators.registry`.
"""

from __future__ import annotations

import numpy as np

from estimators.base import Estimate, EstimateSeries, Sample, samples
from quadfault.errors import ConfigError
from quadfault.model.vehicle import Vehicle

#: the uncertainty the "none" belief reports for every motor [-]
NOMINAL_PRIOR_SD = 0.25


def _series(est, recording) -> EstimateSeries:
    est.reset()
    rows = [est.update(s) for s in samples(recording)]
    return EstimateSeries(
        t=np.array([r.t for r in rows]),
        eta=np.array([r.eta for r in rows]),
        sd=np.array([r.sd for r in rows]),
        status=np.array([r.status for r in rows]),
        estimator=est.name,
    )


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
        return _series(self, recording)


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
        return _series(self, recording)


__all__ = ["NOMINAL_PRIOR_SD", "NominalBelief", "TruthOracle"]
