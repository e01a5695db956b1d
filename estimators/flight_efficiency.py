"""Per-flight motor efficiency from the IRLS estimator, for imported real logs.

:func:`irls_efficiency` runs :class:`~estimators.irls.SlidingWindowIRLS` offline over a
flight and takes the median of its ``ok`` estimates while airborne
(:func:`quadfault.diagnosis.flight_analysis.airborne`): the estimator's cross-check of the
diagnosis' ``motor_efficiency`` effect
(:func:`quadfault.diagnosis.flight_analysis.efficiency_fit`).
"""

from __future__ import annotations

import numpy as np

from estimators.base import STATUS_OK
from estimators.irls import IRLSConfig, SlidingWindowIRLS
from quadfault.diagnosis.flight_analysis import MIN_HEIGHT, airborne
from quadfault.io.recording import Recording


def irls_efficiency(
    rec: Recording, min_height: float | None = MIN_HEIGHT, eta_max: float = 1.6
) -> tuple:
    """Median IRLS efficiency per rotor over the airborne ``ok`` estimates of ``rec``.

    The upper bound is raised from the paper's 1 to ``eta_max``: on a real flight the
    nominal thrust curve is only calibrated on average, so some rotors are above it.
    ``min_height`` [m] above the first sample counts as airborne (None: any height).
    Returns ``(eta tuple, number of estimates used)``.
    """
    rec = rec.without_truth()
    est = SlidingWindowIRLS(rec.vehicle, IRLSConfig(eta_max=eta_max)).run(rec)
    ok = (est.status == STATUS_OK) & airborne(rec, est.t, min_height)
    if not ok.any():
        return (float("nan"),) * rec.thrust_cmd.shape[1], 0
    return tuple(float(x) for x in np.median(est.eta[ok], axis=0)), int(ok.sum())


__all__ = ["irls_efficiency"]
