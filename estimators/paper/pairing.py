"""Fair pairs for ``quadfault reproduce``: every IRLS variant against each baseline (the EKF,
RLS, the UKF) given the same post-processing, each baseline tuned to the best it can do at the
IRLS's accuracy.

A variant (:class:`Variant`) is a set of ``quadfault estimate`` options of the IRLS; each
baseline (:data:`BASELINES`) partners it with the identical post-processing (the causal output
median) and the value of its one tuning knob chosen on a separate calibration flight by
:func:`choose_partner`. The knob is written as a speed ``q`` (larger reacts faster): the EKF's
and the UKF's ``Q_eta``, RLS's ``1 - lambda``. Among the ``q`` whose motor-averaged RMSE is at
most the IRLS's, the one with the smallest motor-averaged excess spike (the RMSE-vs-``q``
curve is U-shaped, so "equal RMSE" alone has two answers and says nothing about spikes). The
search keeps to the fast branch of the U (``q`` at least the most accurate one): on the slow
branch the filter lags every fault, and its excess spike is deflated because the lag already
inflates its error outside the fault windows, the baseline the excess is measured from. When
no ``q`` reaches the IRLS's RMSE, the most accurate one is taken (and the result says so).
The rule sees the calibration flight only; the scored flights never choose a tuning.

The regression's residual prefilter (``--prefilter``) is pre-processing of the same kind: a
baseline that regresses the same residual model (RLS) gets the IRLS variant's prefilter (none
for the paper's settings and the median alone, the improved IRLS's 10 ms for the improved),
in its scan on the calibration flight and on the scored flights. The EKF and the UKF have no
regression to filter; they weigh the noise through their own measurement model. The data is
shared the same way: every partner reads the accelerometer where its IRLS variant does
(``accelerometer="auto"`` for the improved IRLS, none for the paper's settings and the median
alone: :attr:`Variant.accelerometer`).

Every series of a pair comes from :func:`estimators.cli.estimate_series`, the code behind
``quadfault estimate``, and each ``metrics.json`` entry records the arguments
(:func:`estimators.cli.cli_args`) that reproduce it on a recording.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimators.cli import cli_args, estimate_series
from estimators.irls_config import IRLSConfig
from estimators.median import median_series, postprocess_label
from estimators.metrics import mean_or_none, score
from quadfault.errors import ConfigError
from quadfault.io.recording import Recording

#: an excess-spike ratio IRLS / EKF is defined only when the EKF's motor-averaged excess spike
#: exceeds this [1]: below it the EKF's transient is within its own noise and a ratio over it
#: is meaningless (the difference IRLS - EKF, ``excess_spike_difference``, is always given)
MIN_EXCESS = 0.01


@dataclass(frozen=True)
class Baseline:
    """An estimator the IRLS is compared with, and its one tuning knob.

    Attributes:
        name: its registered name.
        option: the :func:`estimators.cli.estimate_series` option the knob sets.
        label: the knob's name in messages.
        q_range: the scan of the speed ``q`` (:func:`choose_partner`).
        prefilter: True when it regresses the IRLS's residual model and so takes its
            residual prefilter (``--prefilter``).
    """

    name: str
    option: str
    label: str
    q_range: tuple
    prefilter: bool = False

    def value(self, q: float) -> float:
        """The option's value at speed ``q`` (RLS: ``forgetting = 1 - q``)."""
        return 1.0 - float(q) if self.option == "forgetting" else float(q)

    def options(
        self, q: float, prefilter: float | None = None, accelerometer: str | None = None
    ) -> dict:
        """The :func:`estimate_series` options at speed ``q`` with the residual prefilter
        ``prefilter`` [s] (``None``: the estimator's default; ignored by a baseline without
        a regression) and the accelerometer's mode ``accelerometer`` (``None`` or
        ``"off"``: the estimator's default, none)."""
        out = {self.option: self.value(q)}
        if self.prefilter and prefilter is not None:
            out["prefilter"] = float(prefilter)
        if accelerometer not in (None, "off"):
            out["accelerometer"] = accelerometer
        return out


#: the baselines ``reproduce`` pairs with every IRLS variant, the EKF first (the paper's)
BASELINES = {
    b.name: b
    for b in (
        Baseline("ekf", "q_eta", "Q_eta", (1e-4, 1e3)),
        Baseline("rls", "forgetting", "1 - lambda", (1e-4, 0.5), prefilter=True),
        Baseline("ukf", "q_eta", "Q_eta", (1e-4, 1e3)),
    )
}


def baseline(name: str) -> Baseline:
    if name not in BASELINES:
        raise ConfigError(f"unknown baseline {name!r}; choose from {', '.join(BASELINES)}")
    return BASELINES[name]


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
        return self.key("ekf")

    def key(self, baseline_name: str) -> str:
        """The key of this variant's partner among the baseline ``baseline_name``."""
        return baseline_name if self.name == "paper" else f"{baseline_name}_{self.name}"

    @property
    def postprocess(self) -> str:
        return postprocess_label(self.median)

    @property
    def prefilter(self) -> float:
        """The IRLS's residual prefilter [s] (0 = none), shared by a partner that regresses
        the same residual model (:attr:`Baseline.prefilter`)."""
        return IRLSConfig.from_options(self.improved).prefilter

    @property
    def accelerometer(self) -> str:
        """The IRLS's accelerometer mode, shared by every partner: a partner reads the data
        its IRLS reads (the improved IRLS's thrust rows come from the accelerometer; the EKF,
        RLS and UKF partners then measure it too)."""
        return IRLSConfig.from_options(self.improved).accelerometer

    def irls_args(self) -> dict:
        """Options of :func:`estimate_series` for the IRLS."""
        med = None if self.improved or self.median <= 1 else self.median
        return {"improved": self.improved, "median": med}

    def ekf_args(self, q_eta: float) -> dict:
        """Options of :func:`estimate_series` for the EKF partner."""
        return self.partner_args("ekf", q_eta)

    def partner_args(self, baseline_name: str, q: float) -> dict:
        """Options of :func:`estimate_series` for the partner of ``baseline_name`` at speed
        ``q``."""
        b = baseline(baseline_name)
        options = b.options(q, self.prefilter, self.accelerometer)
        return {**options, "median": self.median if self.median > 1 else None}


#: The variants ``reproduce`` runs: the paper's estimator, the output median alone, and the
#: improved IRLS (median plus change completion).
VARIANTS = (
    Variant("paper"),
    Variant("median", median=21),
    Variant("improved", improved=True, median=21),
)


@dataclass(frozen=True)
class PartnerResult:
    """The partner of an IRLS variant among one baseline, chosen by :func:`choose_partner`.

    Attributes:
        q_eta: the chosen speed ``q``: the random-walk variance per 1 ms step of the EKF and
            the UKF, ``1 - lambda`` of RLS.
        target_rmse: the IRLS's motor-averaged RMSE on the calibration flight [1].
        rmse, excess_spike: the partner's at ``q_eta`` (motor averages) [1].
        matched: True when some ``q`` reached the target (else the most accurate is used).
        curve_q, curve_rmse, curve_excess: every evaluated point, sorted by ``q``.
        message: one line on what was chosen.
        baseline: the baseline's name.
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
    baseline: str = "ekf"

    @property
    def option(self) -> dict:
        """The partner's tuning as an :func:`estimate_series` option."""
        b = baseline(self.baseline)
        return {b.option: b.value(self.q_eta)}

    def to_dict(self) -> dict:
        return {
            "baseline": self.baseline,
            **self.option,
            "q_eta": self.q_eta,
            "target_rmse": self.target_rmse,
            "rmse": self.rmse,
            "excess_spike": self.excess_spike,
            "matched": self.matched,
            "curve_q": list(self.curve_q),
            "curve_rmse": list(self.curve_rmse),
            "curve_excess": list(self.curve_excess),
            "message": self.message,
            "rule": "smallest excess spike with RMSE <= target, q >= the most "
            "accurate one, on the calibration flight",
        }


def _best(points: dict, target: float):
    """``(q, matched)``: the feasible point (RMSE <= target, on the fast branch: ``q`` at
    least the most accurate evaluated ``q``) of least excess spike, or the least-RMSE point
    when none is feasible."""
    q_min = min(points, key=lambda q: points[q][0])
    feasible = [q for q, (r, _) in points.items() if r <= target and q >= q_min]
    if feasible:
        return min(feasible, key=lambda q: (points[q][1], points[q][0])), True
    return min(points, key=lambda q: points[q][0]), False


def choose_partner(
    recording: Recording,
    target_rmse: float,
    median: int = 1,
    *,
    q_range: tuple | None = None,
    points_per_decade: float = 3.0,
    refine: int = 3,
    evaluate=None,
    baseline_name: str = "ekf",
    prefilter: float | None = None,
    accelerometer: str | None = None,
) -> PartnerResult:
    """The speed ``q`` of baseline ``baseline_name`` (the EKF's ``Q_eta`` by default) on the
    calibration ``recording`` (which holds the truth) with the smallest motor-averaged excess
    spike among those on the fast branch whose RMSE (of the output after a ``median``-row
    causal median) is at most ``target_rmse``: a log-spaced scan of ``q_range`` (default the
    baseline's), then ``refine`` rounds of halving the log-spacing around the best point.

    ``prefilter`` the residual prefilter of a baseline that takes one and ``accelerometer``
    its accelerometer mode (:meth:`Baseline.options`).
    ``evaluate(q) -> (rmse, excess)`` replaces the baseline's run (tests; shared scans)."""
    b = baseline(baseline_name)
    q_range = b.q_range if q_range is None else q_range
    lo, hi = q_range
    if not (0 < lo < hi):
        raise ConfigError(f"q_range must be (low, high) with 0 < low < high, got {q_range!r}")
    if not (math.isfinite(target_rmse) and target_rmse > 0):
        raise ConfigError(f"target RMSE must be positive, got {target_rmse!r}")
    if evaluate is None:

        def evaluate(q):
            return partner_point(recording, b.name, q, median, prefilter, accelerometer)

    n = max(2, round(math.log10(hi / lo) * points_per_decade) + 1)
    points = {float(q): evaluate(float(q)) for q in np.logspace(math.log10(lo), math.log10(hi), n)}
    step = math.log10(hi / lo) / (n - 1)
    for _ in range(refine):
        step /= 2.0
        q0, _ = _best(points, target_rmse)
        for q in (q0 * 10**-step, q0 * 10**step):
            if lo <= q <= hi and q not in points:
                points[q] = evaluate(q)
    q, matched = _best(points, target_rmse)
    rmse, excess = points[q]
    order = sorted(points)
    lab = f"{b.name} {b.label}"
    if matched:
        msg = (
            f"{lab} = {q:.4g}: least excess spike {excess:.4f} with RMSE {rmse:.4f} <= "
            f"{target_rmse:.4f} on the fast branch ({len(points)} evaluations)"
        )
    else:
        msg = (
            f"no {lab} in [{lo:.3g}, {hi:.3g}] reaches RMSE {target_rmse:.4f}; using the "
            f"most accurate, {b.label} = {q:.4g} (RMSE {rmse:.4f})"
        )
    return PartnerResult(
        float(q),
        float(target_rmse),
        float(rmse),
        float(excess),
        matched,
        tuple(order),
        tuple(points[k][0] for k in order),
        tuple(points[k][1] for k in order),
        msg,
        b.name,
    )


def ekf_point(recording: Recording, q_eta: float, median: int = 1) -> tuple[float, float]:
    """``(rmse, excess_spike)``, motor averages, of the EKF with ``q_eta`` and the output
    median ``median`` on ``recording``."""
    return partner_point(recording, "ekf", q_eta, median)


def partner_point(
    recording: Recording,
    baseline_name: str,
    q: float,
    median: int = 1,
    prefilter: float | None = None,
    accelerometer: str | None = None,
) -> tuple[float, float]:
    """``(rmse, excess_spike)``, motor averages, of the baseline at speed ``q`` with the
    residual prefilter ``prefilter`` and the accelerometer mode ``accelerometer``
    (:meth:`Baseline.options`) and the output median ``median`` on ``recording``."""
    b = baseline(baseline_name)
    s = estimate_series(recording, b.name, **b.options(q, prefilter, accelerometer))
    return _rmse_excess(recording, median_series(s, median))


def _rmse_excess(recording, series) -> tuple[float, float]:
    sc = score(recording, series)
    excess = mean_or_none(sc.excess_spike)
    return float(np.mean(sc.rmse)), (math.inf if excess is None else float(excess))


def shared_scan(recording: Recording, baseline_name: str = "ekf"):
    """``evaluate(median, prefilter=None, accelerometer=None)``: per median (and residual
    prefilter, for a baseline that takes one, and accelerometer mode), a
    ``q -> (rmse, excess)`` for :func:`choose_partner` that runs the baseline once per ``q``,
    prefilter and accelerometer mode for every median (the median is post-processing)."""
    b = baseline(baseline_name)
    runs: dict = {}

    def run(q, prefilter, accelerometer):
        options = b.options(q, prefilter, accelerometer)
        key = tuple(sorted(options.items()))
        if key not in runs:
            runs[key] = estimate_series(recording, b.name, **options)
        return runs[key]

    def for_median(median, prefilter=None, accelerometer=None):
        return lambda q: _rmse_excess(
            recording, median_series(run(q, prefilter, accelerometer), median)
        )

    return for_median


def irls_target(recording: Recording, variant: Variant) -> float:
    """The IRLS variant's motor-averaged RMSE on ``recording``."""
    return float(
        np.mean(score(recording, estimate_series(recording, "irls", **variant.irls_args())).rmse)
    )


def run_pair(recording: Recording, variant: Variant, q_eta: float) -> dict:
    """``{key: (series, entry extras)}`` of the IRLS variant and its EKF partner on
    ``recording`` (the extras: ``postprocess``, ``partner``, ``cli``, ``q_eta``)."""
    return run_pairs(recording, variant, {"ekf": q_eta})


def run_pairs(recording: Recording, variant: Variant, tunings: dict) -> dict:
    """``{key: (series, entry extras)}`` of the IRLS variant and its partner of every baseline
    in ``tunings`` (baseline name -> its chosen speed ``q``) on ``recording``. The extras:
    ``postprocess``, ``partner`` (the IRLS's: its EKF partner, or the first baseline),
    ``cli``, and the partner's tuning (``q_eta`` or ``forgetting``)."""
    names = list(tunings)
    first = variant.key("ekf" if "ekf" in tunings else names[0])
    jobs = [(variant.irls_key, "irls", variant.irls_args(), first)]
    jobs += [
        (variant.key(b), b, variant.partner_args(b, q), variant.irls_key)
        for b, q in tunings.items()
    ]
    out = {}
    for key, name, kw, partner in jobs:
        series = estimate_series(recording, name, **kw)
        extra = {"postprocess": series.postprocess, "partner": partner, "cli": cli_args(name, **kw)}
        if name != "irls":
            option = baseline(name).option
            extra[option] = kw[option]
        out[key] = (series, extra)
    return out


def pair_ratios(scenarios: dict, variants=VARIANTS, baseline_name: str = "ekf") -> dict:
    """Per scenario and variant, IRLS / its partner of ``baseline_name`` (the EKF by default)
    of the motor-averaged ``spike``, ``excess_spike`` and ``rmse`` (``None`` where undefined:
    no fault windows, or for ``excess_spike`` a partner excess spike of at most
    :data:`MIN_EXCESS`), and ``excess_spike_difference``, IRLS - partner (``None`` without
    fault windows)."""
    out = {}
    for name, per in scenarios.items():
        block = {}
        for v in variants:
            a, b = per.get(v.irls_key), per.get(v.key(baseline_name))
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


__all__ = [
    "BASELINES",
    "MIN_EXCESS",
    "VARIANTS",
    "Baseline",
    "PartnerResult",
    "Variant",
    "baseline",
    "choose_partner",
    "ekf_point",
    "irls_target",
    "pair_ratios",
    "partner_point",
    "run_pair",
    "run_pairs",
    "shared_scan",
]
