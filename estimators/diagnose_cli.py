"""``quadfault diagnose``: the model-mismatch diagnosis (:mod:`quadfault.diagnosis.cli`) with
the online estimator's efficiencies beside a weak-rotor hypothesis.

The diagnosis sits below the estimators and never imports them; this command module, above
both, hands it :func:`efficiency_estimate` (the registered IRLS estimator run over the same
recording), which the diagnosis calls only when it names a weak rotor, accepted or among
rivals it cannot tell apart."""

from __future__ import annotations

import numpy as np

from estimators.cli import estimate_series
from quadfault.diagnosis import cli as diagnosis_cli
from quadfault.errors import ConfigError

#: the estimator shown beside a weak-rotor hypothesis
ESTIMATOR = "irls"
#: the first part of the flight left out of the estimator's summary (its window fills) [-]
SETTLE_FRACTION = 0.25

add_arguments = diagnosis_cli.add_arguments


def efficiency_estimate(recording, name: str = ESTIMATOR) -> dict:
    """``{"estimator", "eta", "eta_spread", "from_s", "to_s", "samples"}``: the median of the
    estimator's motor efficiencies over the flight after its first ``SETTLE_FRACTION``, and
    their interquartile half-range; a recording the estimator cannot run on (no pose) is a
    one-line error."""
    if not recording.has_pose:
        raise ConfigError(f"the {name} estimator needs position, velocity and attitude")
    series = estimate_series(recording, name)
    t, eta = np.asarray(series.t, dtype=float), np.asarray(series.eta, dtype=float)
    ok = np.all(np.isfinite(eta), axis=1) & (t >= t[0] + SETTLE_FRACTION * (t[-1] - t[0]))
    if not ok.any():
        raise ConfigError(f"the {name} estimator gave no estimate over this flight")
    q1, med, q3 = np.percentile(eta[ok], [25, 50, 75], axis=0)
    return {
        "estimator": name,
        "eta": med.tolist(),
        "eta_spread": (0.5 * (q3 - q1)).tolist(),
        "from_s": float(t[ok][0]),
        "to_s": float(t[ok][-1]),
        "samples": int(ok.sum()),
        "cli": f"quadfault estimate FILE.csv --estimator {name} --out EST.csv",
    }


def run(args) -> int:
    return diagnosis_cli.run(args, efficiency_estimate=efficiency_estimate)
