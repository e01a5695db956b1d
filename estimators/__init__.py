"""Online motor-efficiency estimators: the paper's sliding-window IRLS and an EKF baseline.

Both implement :class:`estimators.base.OnlineEstimator`.
"""

from estimators.base import Estimate, EstimateSeries, OnlineEstimator, Sample
from estimators.ipm import IPMSettings
from estimators.irls import IRLSConfig, IRLSDiagnostics, SlidingWindowIRLS

__all__ = [
    "Estimate",
    "EstimateSeries",
    "IPMSettings",
    "IRLSConfig",
    "IRLSDiagnostics",
    "OnlineEstimator",
    "Sample",
    "SlidingWindowIRLS",
]
