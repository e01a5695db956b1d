"""Estimator robustness, CI subset (``benchmarks/studies/estimator_robustness.py`` has the full run and
the measured recovery times): degenerate windows yield the status that says so with the
previous estimate kept and never NaN; both estimators recover after a burst of corrupted
samples within the documented bound."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

_spec = importlib.util.spec_from_file_location(
    "estimator_robustness",
    Path(__file__).resolve().parents[1] / "benchmarks" / "studies" / "estimator_robustness.py",
)
er = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(er)

AT, SPAN = 600, 100  # degenerate span: samples 600..699 of a 1.2 s flight at 1 kHz
#: recovery bounds [s] after a 50 ms burst of spikes (docs/reliability.md: measured 0.007 s
#: for IRLS and 0.075 s for the EKF, seed 0; the bounds leave room for other seeds)
RECOVERY_BOUND = {"irls": 0.05, "ekf": 0.3}


@pytest.fixture(scope="module")
def flight():
    return er.flight(1.2, seed=0)


@pytest.fixture(scope="module")
def streams(flight):
    base, vehicle = flight
    return er.degenerate_streams(base, vehicle, AT, SPAN)


@pytest.fixture(scope="module")
def clean_runs(flight):
    base, vehicle = flight
    return {name: er.run_stream(name, vehicle, base) for name in er.ESTIMATORS}


def _check(name, flight, streams, case):
    stream, span = streams[case]
    return er.check_degenerate(name, flight[1], stream, span)


@pytest.mark.parametrize("name", ["irls", "ekf"])
def test_dropped_samples_are_flagged_and_the_estimate_kept(name, flight, streams):
    r = _check(name, flight, streams, "nan_rows")
    assert r["statuses"] == ["bad_sample"] and r["kept"] and r["finite"]
    assert r["error_at_end"] == r["error_before"] < 0.05


@pytest.mark.parametrize("name", ["irls", "ekf"])
def test_steady_hover_is_not_degenerate_and_stays_accurate(name, flight, streams):
    r = _check(name, flight, streams, "hover")
    assert r["statuses"] == ["ok"] and r["finite"]
    assert r["error_at_end"] < 0.01  # eta is observable in hover through the allocation


def test_irls_idle_window_is_no_excitation_and_kept(flight, streams):
    r = _check("irls", flight, streams, "idle")
    assert r["statuses"] == ["no_excitation"] and r["kept"] and r["finite"]
    assert r["error_at_end"] < 0.02


def test_irls_rotor_at_zero_is_ill_conditioned_and_kept(flight, streams):
    r = _check("irls", flight, streams, "rotor_off")
    assert r["statuses"] == ["ill_conditioned"] and r["kept"] and r["finite"]


def test_irls_repeated_time_is_bad_sample_and_kept(flight, streams):
    r = _check("irls", flight, streams, "repeated_time")
    assert r["statuses"] == ["bad_sample"] and r["kept"] and r["raised"] is None


@pytest.mark.parametrize("case", ["idle", "rotor_off"])
def test_ekf_degenerate_windows_never_nan(case, flight, streams):
    assert _check("ekf", flight, streams, case)["finite"]


@pytest.mark.parametrize("case", ["idle", "rotor_off"])
def test_ekf_degenerate_windows_flagged_and_kept(case, flight, streams):
    r = _check("ekf", flight, streams, case)
    assert r["statuses"] != ["ok"] and r["kept"]


def test_ekf_repeated_time_is_bad_sample_and_kept(flight, streams):
    r = _check("ekf", flight, streams, "repeated_time")
    assert r["raised"] is None and r["statuses"] == ["bad_sample"] and r["kept"]


@pytest.fixture(scope="module")
def saturated():
    return er.saturated_flight(1.2, seed=0)


@pytest.mark.parametrize("name", ["irls", "ekf"])
def test_saturated_rotor_is_estimated_from_its_limit(name, saturated):
    """The weak rotor's command stays above the limit: the clipped command still identifies
    eta (thrust = eta * limit), no NaN."""
    stream, vehicle, frac = saturated
    assert frac > 0.9
    r = er.check_saturated(name, vehicle, stream)
    assert r["finite"] and r["raised"] is None
    assert set(r["statuses"]) <= {"ok", "warmup"}
    assert r["error_at_end"] < 0.05


@pytest.mark.parametrize("name", ["irls", "ekf"])
@pytest.mark.parametrize("kind", er.BURSTS)
def test_recovery_after_a_burst_of_corrupted_samples(name, kind, flight, clean_runs):
    base, vehicle = flight
    r = er.recovery_time(
        name, vehicle, base, kind, AT, 50, tol=0.02, seed=1, clean=clean_runs[name]
    )
    assert r["raised"] is None and r["finite"]
    assert math.isfinite(r["recovery_s"]) and r["recovery_s"] <= RECOVERY_BOUND[name], r
    if kind == "spikes":
        assert r["max_deviation"] > 0.02  # the burst did disturb the estimate


def test_recovery_time_is_measured_against_the_clean_run(flight, clean_runs):
    """No burst at all (a zero-length burst) recovers in zero time with zero deviation."""
    base, vehicle = flight
    r = er.recovery_time("ekf", vehicle, base, "spikes", AT, 0, tol=1e-12, clean=clean_runs["ekf"])
    assert r["recovery_s"] == 0.0 and r["max_deviation"] == 0.0
    assert np.isfinite(r["max_deviation"])
