"""Calibrate the EKF's efficiency random walk ``Q_eta`` to a target RMSE (paper Sec. V-B:
"both methods ... calibrated to the same root mean square error").

The reference code hard-codes ``Q_eta = 0.5`` and ships no tuning script (facts sec. 5), so
the procedure is ours: on a calibration recording (a *different* seed from the scored one),
the motor-averaged RMSE of the EKF as a function of ``Q_eta`` is U-shaped -- too small a
``Q_eta`` lags behind every change, too large a one follows the thrust noise. We

1. scan ``Q_eta`` on a log-spaced grid;
2. take the *largest* bracket where the curve crosses the target (the fast, noisy branch:
   the filter that still matches the accuracy while reacting quickest to a fault), or the
   minimum-RMSE grid point when the curve never reaches the target;
3. refine the crossing by bisection in ``log Q_eta``.

The returned :class:`CalibrationResult` keeps every evaluated point (for a figure).

:func:`calibrate_sd_scale` calibrates the EKF's reported one-sigma ``sd`` (not part of the
paper): the filter's ``sqrt(diag P_eta)`` follows its noise model, which with the reference's
measurement noise bounds the error by two orders of magnitude (coverage 100 %). One scale,
the ``coverage`` quantile of ``|error| / sd`` on a calibration flight, makes ``scale * sd`` a
calibrated error bar for that tuning (docs/ekf.md, "Uncertainty").
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from estimators.ekf import EKFConfig, MotorEfficiencyEKF
from estimators.median import median_series
from estimators.metrics import aligned_truth, score
from quadfault.errors import ConfigError
from quadfault.io.recording import Recording
from quadfault.progress import progress_bar


@dataclass(frozen=True)
class CalibrationResult:
    """Outcome of :func:`calibrate_q_eta`.

    Attributes:
        q_eta: the chosen random-walk variance per 1 ms step [1].
        target_rmse: the RMSE to match (motor average) [1].
        rmse: the EKF's RMSE at ``q_eta`` [1].
        matched: True when a crossing of the target was found (else the minimum is used).
        curve_q, curve_rmse: every evaluated ``(Q_eta, RMSE)``, sorted by ``Q_eta``.
        message: one line on what was done.
    """

    q_eta: float
    target_rmse: float
    rmse: float
    matched: bool
    curve_q: tuple
    curve_rmse: tuple
    message: str

    def to_dict(self) -> dict:
        return {
            "q_eta": self.q_eta,
            "target_rmse": self.target_rmse,
            "rmse": self.rmse,
            "matched": self.matched,
            "curve_q": list(self.curve_q),
            "curve_rmse": list(self.curve_rmse),
            "message": self.message,
        }


def match_larger_root(
    rmse_of: Callable[[float], float],
    target: float,
    grid,
    bisection_steps: int = 8,
    rtol: float = 0.005,
) -> CalibrationResult:
    """Find the largest ``q`` in ``grid``'s span with ``rmse_of(q) == target`` (see module).

    Args:
        rmse_of: ``q -> RMSE``.
        target: RMSE to match.
        grid: increasing positive values of ``q`` to scan.
        bisection_steps: halvings of the bracket in ``log q`` (stops early within ``rtol``).
        rtol: relative tolerance on the RMSE match.
    """
    qs = np.asarray(grid, dtype=float)
    if qs.ndim != 1 or qs.size < 2 or np.any(qs <= 0) or np.any(np.diff(qs) <= 0):
        raise ConfigError("the Q_eta grid must hold at least two increasing positive values")
    if not (math.isfinite(target) and target > 0):
        raise ConfigError(f"target RMSE must be positive, got {target!r}")
    seen: dict[float, float] = {}

    def f(q):
        if q not in seen:
            seen[q] = float(rmse_of(q))
        return seen[q]

    vals = np.array([f(q) for q in qs])
    above = vals - target
    finite = np.isfinite(above)
    brackets = [
        i
        for i in range(len(qs) - 1)
        if finite[i] and finite[i + 1] and above[i] * above[i + 1] <= 0
    ]
    if not brackets:
        k = int(np.nanargmin(vals))
        q_best, matched = float(qs[k]), False
        msg = (
            f"no Q_eta in [{qs[0]:.3g}, {qs[-1]:.3g}] reaches RMSE {target:.4g}; "
            f"using the minimum {vals[k]:.4g} at Q_eta = {q_best:.3g}"
        )
    else:
        i = brackets[-1]  # the larger root of the U
        lo, hi = math.log(qs[i]), math.log(qs[i + 1])
        f_lo = f(qs[i]) - target
        q_best = float(qs[i] if abs(f_lo) < abs(f(qs[i + 1]) - target) else qs[i + 1])
        for _ in range(bisection_steps):
            if abs(f(q_best) - target) <= rtol * target:
                break
            mid = 0.5 * (lo + hi)
            g = f(math.exp(mid)) - target
            if g * f_lo <= 0:
                hi = mid
            else:
                lo, f_lo = mid, g
            q_best = min((math.exp(lo), math.exp(hi)), key=lambda q: abs(f(q) - target))
        matched = True
        msg = (
            f"Q_eta = {q_best:.4g} gives RMSE {f(q_best):.4g} (target {target:.4g}, larger "
            f"root, {len(seen)} evaluations)"
        )
    order = sorted(seen)
    return CalibrationResult(
        q_best, float(target), f(q_best), matched, tuple(order), tuple(seen[q] for q in order), msg
    )


def ekf_rmse(
    recording: Recording,
    q_eta: float,
    base: EKFConfig | None = None,
    align: str = "end",
    post_median: int = 1,
) -> float:
    """Motor-averaged RMSE of the EKF with ``q_eta`` on ``recording`` (which holds truth);
    ``post_median > 1`` scores the causal running median of its output (a fairness check of
    ``IRLSConfig.output_median``, docs/ekf.md)."""
    cfg = (base or EKFConfig()).replace(q_eta=float(q_eta))
    est = MotorEfficiencyEKF(recording.vehicle, cfg).run(recording.without_truth())
    if post_median > 1:
        est = median_series(est, post_median)
    return float(np.mean(score(recording, est, align=align).rmse))


def calibrate_q_eta(
    recording: Recording,
    target_rmse: float,
    *,
    base: EKFConfig | None = None,
    q_range: tuple = (1e-6, 10.0),
    points_per_decade: float = 1.0,
    bisection_steps: int = 8,
    align: str = "end",
    progress: bool = False,
    post_median: int = 1,
) -> CalibrationResult:
    """Choose ``Q_eta`` so the EKF's RMSE on ``recording`` (of its output's causal running
    median over ``post_median`` rows when > 1) equals ``target_rmse``."""
    lo, hi = q_range
    if not (0 < lo < hi):
        raise ConfigError(f"q_range must be (low, high) with 0 < low < high, got {q_range!r}")
    n = max(2, int(round(math.log10(hi / lo) * points_per_decade)) + 1)
    grid = np.logspace(math.log10(lo), math.log10(hi), n)
    bar = None
    if progress:
        bar = progress_bar(total=n + bisection_steps, desc="calibrate EKF", unit="run")

    def rmse_of(q):
        value = ekf_rmse(recording, q, base, align, post_median)
        if bar is not None:
            bar.update(1)
        return value

    try:
        return match_larger_root(rmse_of, target_rmse, grid, bisection_steps)
    finally:
        if bar is not None:
            bar.close()


#: Fraction of a normal error within one standard deviation.
ONE_SIGMA = 0.6827


@dataclass(frozen=True)
class SdCalibration:
    """Scale of the EKF's reported ``sd`` fitted by :func:`calibrate_sd_scale`.

    Attributes:
        scale: multiplier of the reported ``sd`` [1].
        coverage: the target fraction of samples with ``|error| <= scale * sd`` [1].
        raw_coverage: that fraction on the calibration flight before scaling [1].
        samples: number of (row, motor) pairs it was fitted on.
        config: the :class:`~estimators.ekf.EKFConfig` it holds for (a different ``Q_eta`` or
            noise setting changes ``P`` and needs its own scale).
    """

    scale: float
    coverage: float
    raw_coverage: float
    samples: int
    config: EKFConfig

    def apply(self, series):
        """``series`` (an :class:`~estimators.base.EstimateSeries`) with ``sd`` scaled."""
        sd = None if series.sd is None else np.asarray(series.sd, dtype=float) * self.scale
        return replace(series, sd=sd)

    def to_dict(self) -> dict:
        return {
            "scale": self.scale,
            "coverage": self.coverage,
            "raw_coverage": self.raw_coverage,
            "samples": self.samples,
            "q_eta": self.config.q_eta,
        }


def calibrate_sd_scale(
    recording: Recording, config: EKFConfig | None = None, *, coverage: float = ONE_SIGMA
) -> SdCalibration:
    """Fit ``scale`` so that ``|eta_true - eta| <= scale * sd`` on a ``coverage`` fraction of
    the scored samples (status other than ``warmup``, finite positive ``sd``, all motors
    pooled) of the EKF with ``config`` on ``recording``, which must hold the truth. Fit it on
    a calibration flight and apply it (:meth:`SdCalibration.apply`) to other flights."""
    if not (isinstance(coverage, (int, float)) and 0.0 < coverage < 1.0):
        raise ConfigError(f"coverage must be a fraction in (0, 1), got {coverage!r}")
    cfg = config or EKFConfig()
    if recording.eta_true is None:
        raise ConfigError(
            f"{recording.path or 'recording'}: no true efficiency (eta1..eta4) "
            "to calibrate the EKF's sd against"
        )
    est = MotorEfficiencyEKF(recording.vehicle, cfg).run(recording.without_truth())
    _, eta_true = aligned_truth(recording, est)
    sd = np.asarray(est.sd, dtype=float)
    keep = (np.asarray(est.status) != "warmup")[:, None] & np.isfinite(sd) & (sd > 0)
    if keep.sum() < 2:
        raise ConfigError(
            "fewer than two scored estimates with an sd; the recording is too "
            "short to calibrate the EKF's sd"
        )
    err = np.abs(eta_true - est.eta)[keep]
    ratio = err / sd[keep]
    return SdCalibration(
        float(np.quantile(ratio, coverage)),
        float(coverage),
        float(np.mean(ratio <= 1.0)),
        int(keep.sum()),
        cfg,
    )
