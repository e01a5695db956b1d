"""Agents: the geometric baseline, the estimate-aware fault-tolerant controller, SB3 training
and estimator-in-the-loop evaluation (see ``docs/agents.md``).

Modules:

* :mod:`quadfault.model.allocation` -- estimate-aware, saturation-aware thrust allocation;
* :mod:`agents.fault_tolerant` -- :class:`GeometricBaseline`, :class:`EstimateAwareController`;
* :mod:`agents.rollout` -- :func:`fly`, a closed-loop flight with an estimator in the loop;
* :mod:`agents.metrics` -- tracking RMSE, crash, peak attitude error, energy, time to recover;
* :mod:`agents.policies` -- :class:`GeometricPolicy` with SB3's ``predict`` interface;
* :mod:`agents.env_rollout` -- flights of policies through the Gymnasium environment;
* :mod:`agents.suite` -- scenario suites; :mod:`agents.evaluate` -- ``quadfault evaluate``;
* :mod:`agents.train` -- ``quadfault train`` (PPO / SAC, needs the ``rl`` extra).
"""

from agents.fault_tolerant import EstimateAwareController, FaultTolerantConfig, GeometricBaseline
from agents.metrics import FlightMetrics
from agents.rollout import Flight, FlightConfig, fly
from quadfault.model.allocation import AllocationConfig, EstimateAwareAllocator

__all__ = [
    "AllocationConfig",
    "EstimateAwareAllocator",
    "EstimateAwareController",
    "FaultTolerantConfig",
    "GeometricBaseline",
    "Flight",
    "FlightConfig",
    "FlightMetrics",
    "fly",
]
