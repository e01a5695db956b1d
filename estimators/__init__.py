"""Online motor-efficiency estimators: the paper's sliding-window IRLS and an EKF baseline.

Both implement :class:`estimators.base.OnlineEstimator`.
"""

from estimators.base import Estimate, EstimateSeries, OnlineEstimator, Sample

__all__ = ["Estimate", "EstimateSeries", "OnlineEstimator", "Sample"]
