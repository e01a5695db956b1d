"""The blinded study scores only what a recording can resolve: a time constant shorter than two
sample periods is reported on its own line, not counted as a miss or a hit."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import blinded_study  # noqa: E402


def _row(truth, params, found, indistinguishable=()):
    return {
        "truth": truth,
        "found": found,
        "indistinguishable": list(indistinguishable),
        "snr": [5.0] * len(truth),
        "improvement": 0.5,
        "param_errors": {},
        "t_diag": 0.1,
        "cpu_diag": 0.1,
        "samples": 3000,
        "truth_params": [{"name": n, "params": p} for n, p in zip(truth, params)],
    }


def test_time_constants_below_two_samples_are_not_scored():
    rate = 250.0  # two samples: 8 ms
    short_lag = _row(
        ["motor_lag"], [{"tau_s": 0.005}], [], indistinguishable=[["inertia", "motor_lag"]]
    )
    short_delay_pair = _row(
        ["delay", "drag"], [{"delay_s": 0.002}, {"k_N_s_per_m": [0.3] * 3}], ["drag"]
    )
    long_lag = _row(["motor_lag"], [{"tau_s": 0.03}], ["inertia"])
    free = _row([], [], [])
    assert blinded_study.resolvable(short_lag, rate) == []
    assert blinded_study.resolvable(short_delay_pair, rate) == ["drag"]
    assert blinded_study.resolvable(long_lag, rate) == ["motor_lag"]
    # at 1 kHz the same 5 ms lag is resolved and must be found
    assert blinded_study.resolvable(short_lag, 1000.0) == ["motor_lag"]

    s = blinded_study.summarise([short_lag, short_delay_pair, long_lag, free], rate, 12.0)
    assert s["n"] == 4 and s["n_below_resolution"] == 1 and s["n_with_effect"] == 2
    assert s["below_resolution_found_nothing"] == 1
    assert s["below_resolution_indistinguishable"] == 1
    # drag found on the pair (its delay unresolvable), the long lag missed as inertia
    assert s["top_effect_correct"] == 0.5
    # counting every concealed effect, the short lag's silence is a miss too
    assert abs(s["top_effect_correct_every_concealed"] - 1 / 3) < 1e-12
    assert s["false_alarm_rate"] == 0.0
