"""Fair pairs for ``quadfault reproduce``: every IRLS variant against an EKF given the same
post-processing, the EKF tuned to the best it can do at the IRLS's accuracy.

A variant (:class:`Variant`) is a set of ``quadfault estimate`` options of the IRLS; its EKF
partner gets the identical post-processing (the causal output median) and the ``Q_eta``
chosen on a separate calibration flight by :func:`choose_partner`: among the ``Q_eta`` whose
motor-averaged RMSE is at most the IRLS's, the one with the smallest motor-averaged excess
spike (the EKF's RMSE-vs-``Q_eta`` curve is U-shaped, so "equal RMSE" alone has two answers
and says nothing about spikes). The search keeps to the fast branch of the U (``Q_eta`` at
least the most accurate one): on the slow branch the filter lags every fault, and its excess
spike is deflated because the lag already inflates its error outside the fault windows, the
baseline the excess is measured from. When no ``Q_eta`` reaches the IRLS's RMSE, the most
accurate one is taken (and the result says so).

Every series of a pair comes from :func:`estimators.cli.estimate_series`, the code behind
``quadfault estimate``, and each ``metrics.json`` entry records the arguments
(:func:`estimators.cli.cli_args`) that reproduce it on a recording.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimators.cli import cli_args, estimate_series
from estimators.median import median_series, postprocess_label
from estimators.metrics import mean_or_none, score
from quadfault.errors import ConfigError
from quadfault.recording import Recording

#: an excess-spike ratio IRLS / EKF is defined only when the EKF's motor-averaged excess spike
#: exceeds this [1]: below it the EKF's transient is within its own noise and a ratio over it
#: is meaningless (the difference IRLS - EKF, ``excess_spike_difference``, is always given)
MIN_EXCESS = 0.01


@dataclass(frozen=True)
class Variant:
    """An IRLS variant and the post-processing its EKF partner shares.

    Attributes:
        name: ``"paper"`` (keys ``irls`` / ``ekf``) or a suffix (keys ``irls_<name>`` /
            ``ekf_<name>``).
        improved: the IRLS options beyond the paper (``--improved``: change completion and a
            21-sample output median).
        median: the output median of both estimators [samples] (1 = none).
    """

    name: str
    improved: bool = False
    median: int = 1

    @property
    def irls_key(self) -> str:
        return "irls" if self.name == "paper" else f"irls_{self.name}"

    @property
    def ekf_key(self) -> str:
        return "ekf" if self.name == "paper" else f"ekf_{self.name}"

    @property
    def postprocess(self) -> str:
        return postprocess_label(self.median)

    def irls_args(self) -> dict:
        """Options of :func:`estimate_series` for the IRLS."""
        med = None if self.improved or self.median <= 1 else self.median
        return {"improved": self.improved, "median": med}

    def ekf_args(self, q_eta: float) -> dict:
        """Options of :func:`estimate_series` for the EKF partner."""
        return {"q_eta": float(q_eta), "median": self.median if self.median > 1 else None}


#: The variants ``reproduce`` runs: the paper's estimator, the output median alone, and the
#: improved IRLS (median plus change completion).
VARIANTS = (Variant("paper"), Variant("median", median=21),
            Variant("improved", improved=True, median=21))


@dataclass(frozen=True)
class PartnerResult:
    """The EKF partner of an IRLS variant, chosen by :func:`choose_partner`.

    Attributes:
        q_eta: the chosen random-walk variance per 1 ms step [1].
        target_rmse: the IRLS's motor-averaged RMSE on the calibration flight [1].
        rmse, excess_spike: the EKF's at ``q_eta`` (motor averages) [1].
        matched: True when some ``Q_eta`` reached the target (else the most accurate is used).
        curve_q, curve_rmse, curve_excess: every evaluated point, sorted by ``Q_eta``.
        message: one line on what was chosen.
    """

    q_eta: float
    target_rmse: float
    rmse: float
    excess_spike: float
    matched: bool
    curve_q: tuple
    curve_rmse: tuple
    curve_excess: tuple
    message: str

    def to_dict(self) -> dict:
        return {"q_eta": self.q_eta, "target_rmse": self.target_rmse, "rmse": self.rmse,
                "excess_spike": self.excess_spike, "matched": self.matched,
                "curve_q": list(self.curve_q), "curve_rmse": list(self.curve_rmse),
                "curve_excess": list(self.curve_excess), "message": self.message,
                "rule": "smallest excess spike with RMSE <= target, Q_eta >= the most "
                        "accurate one"}


def _best(points: dict, target: float):
    """``(q, matched)``: the feasible point (RMSE <= target, on the fast branch: ``q`` at
    least the most accurate evaluated ``q``) of least excess spike, or the least-RMSE point
    when none is feasible."""
    q_min = min(points, key=lambda q: points[q][0])
    feasible = [q for q, (r, _) in points.items() if r <= target and q >= q_min]
    if feasible:
        return min(feasible, key=lambda q: (points[q][1], points[q][0])), True
    return min(points, key=lambda q: points[q][0]), False


def choose_partner(recording: Recording, target_rmse: float, median: int = 1, *,
                   q_range: tuple = (1e-4, 10.0), points_per_decade: float = 3.0,
                   refine: int = 3, evaluate=None) -> PartnerResult:
    """The EKF's ``Q_eta`` on ``recording`` (which holds the truth) with the smallest
    motor-averaged excess spike among those on the fast branch whose RMSE (of the output after
    a ``median``-row causal median) is at most ``target_rmse``: a log-spaced scan of
    ``q_range``, then
    ``refine`` rounds of halving the log-spacing around the best point.

    ``evaluate(q) -> (rmse, excess)`` replaces the EKF run (tests; shared scans)."""
    lo, hi = q_range
    if not (0 < lo < hi):
        raise ConfigError(f"q_range must be (low, high) with 0 < low < high, got {q_range!r}")
    if not (math.isfinite(target_rmse) and target_rmse > 0):
        raise ConfigError(f"target RMSE must be positive, got {target_rmse!r}")
    if evaluate is None:
        def evaluate(q):
            return ekf_point(recording, q, median)
    n = max(2, round(math.log10(hi / lo) * points_per_decade) + 1)
    points = {float(q): evaluate(float(q)) for q in np.logspace(math.log10(lo),
                                                                  math.log10(hi), n)}
    step = math.log10(hi / lo) / (n - 1)
    for _ in range(refine):
        step /= 2.0
        q0, _ = _best(points, target_rmse)
        for q in (q0 * 10 ** -step, q0 * 10 ** step):
            if lo <= q <= hi and q not in points:
                points[q] = evaluate(q)
    q, matched = _best(points, target_rmse)
    rmse, excess = points[q]
    order = sorted(points)
    if matched:
        msg = (f"Q_eta = {q:.4g}: least excess spike {excess:.4f} with RMSE {rmse:.4f} <= "
               f"{target_rmse:.4f} on the fast branch ({len(points)} evaluations)")
    else:
        msg = (f"no Q_eta in [{lo:.3g}, {hi:.3g}] reaches RMSE {target_rmse:.4f}; using the most "
               f"accurate, Q_eta = {q:.4g} (RMSE {rmse:.4f})")
    return PartnerResult(float(q), float(target_rmse), float(rmse), float(excess), matched,
                         tuple(order), tuple(points[k][0] for k in order),
                         tuple(points[k][1] for k in order), msg)


def ekf_point(recording: Recording, q_eta: float, median: int = 1) -> tuple[float, float]:
    """``(rmse, excess_spike)``, motor averages, of the EKF with ``q_eta`` and the output
    median ``median`` on ``recording``."""
    s = estimate_series(recording, "ekf", q_eta=q_eta)
    return _rmse_excess(recording, median_series(s, median))


def _rmse_excess(recording, series) -> tuple[float, float]:
    sc = score(recording, series)
    excess = mean_or_none(sc.excess_spike)
    return float(np.mean(sc.rmse)), (math.inf if excess is None else float(excess))


def shared_scan(recording: Recording):
    """``evaluate(median)``: per median, a ``q -> (rmse, excess)`` for :func:`choose_partner`
    that runs the EKF once per ``Q_eta`` for every median (the median is post-processing)."""
    runs: dict = {}

    def run(q):
        if q not in runs:
            runs[q] = estimate_series(recording, "ekf", q_eta=q)
        return runs[q]

    def for_median(median):
        return lambda q: _rmse_excess(recording, median_series(run(q), median))

    return for_median


def irls_target(recording: Recording, variant: Variant) -> float:
    """The IRLS variant's motor-averaged RMSE on ``recording``."""
    return float(np.mean(score(recording, estimate_series(recording, "irls",
                                                          **variant.irls_args())).rmse))


def run_pair(recording: Recording, variant: Variant, q_eta: float) -> dict:
    """``{key: (series, entry extras)}`` of the IRLS variant and its EKF partner on
    ``recording`` (the extras: ``postprocess``, ``partner``, ``cli``, ``q_eta``)."""
    out = {}
    for key, name, kw, partner in (
            (variant.irls_key, "irls", variant.irls_args(), variant.ekf_key),
            (variant.ekf_key, "ekf", variant.ekf_args(q_eta), variant.irls_key)):
        series = estimate_series(recording, name, **kw)
        extra = {"postprocess": series.postprocess, "partner": partner,
                 "cli": cli_args(name, **kw)}
        if name == "ekf":
            extra["q_eta"] = float(q_eta)
        out[key] = (series, extra)
    return out


def pair_ratios(scenarios: dict, variants=VARIANTS) -> dict:
    """Per scenario and variant, IRLS / EKF of the motor-averaged ``spike``,
    ``excess_spike`` and ``rmse`` (``None`` where undefined: no fault windows, or for
    ``excess_spike`` an EKF excess spike of at most :data:`MIN_EXCESS`), and
    ``excess_spike_difference``, IRLS - EKF (``None`` without fault windows)."""
    out = {}
    for name, per in scenarios.items():
        block = {}
        for v in variants:
            a, b = per.get(v.irls_key), per.get(v.ekf_key)
            if a is None or b is None:
                continue
            r = {}
            for key in ("spike", "excess_spike", "rmse"):
                x = float(np.mean(a[key])) if key == "rmse" else mean_or_none(a[key])
                y = float(np.mean(b[key])) if key == "rmse" else mean_or_none(b[key])
                r[key] = x / y if x is not None and y else None
                if key == "excess_spike":
                    r["excess_spike_difference"] = None if x is None or y is None else x - y
                    if y is not None and y <= MIN_EXCESS:
                        r[key] = None
            block[v.name] = r
        if block:
            out[name] = block
    return out


__all__ = ["MIN_EXCESS", "VARIANTS", "PartnerResult", "Variant", "choose_partner", "ekf_point",
           "irls_target", "pair_ratios", "run_pair", "shared_scan"]
