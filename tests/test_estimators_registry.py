"""The estimator registry: every row builds an estimator with the one interface, its batched
form agrees with it, its options build its configuration, and bad choices are one-line
errors."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from estimators.base import Estimate, EstimateSeries, samples
from estimators.registry import (
    ESTIMATORS,
    OPTIONS,
    ROLES,
    config_class,
    config_from_options,
    estimator_class,
    estimator_names,
    make_estimator,
)
from quadfault.errors import ConfigError
from quadfault.model.scenarios import named_scenario
from quadfault.model.vehicle import Vehicle
from quadfault.sim.simulator import simulate


@pytest.fixture(scope="module")
def flight():
    return simulate(replace(named_scenario("abrupt"), duration=0.12), seed=3)


def _truth(t):
    return np.full(4, 0.9)


@pytest.mark.parametrize("name", sorted(ESTIMATORS))
def test_every_row_builds_an_estimator_with_the_interface(name, flight):
    spec = ESTIMATORS[name]
    assert spec.role in ROLES and set(spec.options) <= set(OPTIONS)
    est = make_estimator(name, flight.vehicle, schedule=_truth)
    assert est.name == name and isinstance(est, estimator_class(name))
    est.reset()
    rows = [est.update(s) for s in samples(flight.without_truth())]
    assert all(isinstance(r, Estimate) and r.eta.shape == (4,) for r in rows)
    assert [r.t for r in rows] == list(flight.t)
    if spec.role == "estimator":  # measurements only: run() over the recording without truth
        series = make_estimator(name, flight.vehicle).run(flight.without_truth())
        assert isinstance(series, EstimateSeries) and series.eta.shape == (len(flight), 4)
        np.testing.assert_allclose(series.eta, np.array([r.eta for r in rows]), atol=1e-12)
    if spec.role == "oracle":
        np.testing.assert_array_equal(rows[-1].eta, _truth(0.0))


@pytest.mark.slow
@pytest.mark.parametrize("name", estimator_names(batched=True))
def test_batched_form_row_equals_the_single_estimator(name, flight):
    rec = flight.without_truth()
    single = make_estimator(name, rec.vehicle)
    batch = make_estimator(name, rec.vehicle, num=2)
    for s in samples(rec):
        one = single.update(s)
        both = batch.update(*(np.array([a, a]) for a in s))
        np.testing.assert_allclose(both.eta, [one.eta, one.eta], atol=1e-12)


@pytest.mark.parametrize("name", sorted(ESTIMATORS))
def test_options_build_the_configuration(name):
    spec = ESTIMATORS[name]
    assert config_from_options(name) is None
    values = {
        "improved": True,
        "median": 5,
        "q_eta": 0.25,
        "forgetting": 0.95,
        "prefilter": 0.02,
        "accelerometer": "on",
    }
    for key in spec.options:
        cfg = config_from_options(name, **{key: values[key]})
        assert isinstance(cfg, config_class(name)) and cfg != config_class(name)()
        assert isinstance(
            make_estimator(name, Vehicle(), **{key: values[key]}).config, config_class(name)
        )
    for key in set(OPTIONS) - set(spec.options):
        with pytest.raises(ConfigError, match=f"{key!r} applies to"):
            make_estimator(name, Vehicle(), **{key: values[key]})


def test_bad_choices_are_one_line_errors():
    v = Vehicle()
    with pytest.raises(ConfigError, match="unknown estimator 'kalman'; choose from irls, ekf"):
        make_estimator("kalman", v)
    with pytest.raises(ConfigError, match="no batched form"):
        make_estimator("truth", v, num=3)
    with pytest.raises(ConfigError, match="takes no configuration"):
        make_estimator("none", v, config=object())
    irls_config = config_class("irls")
    with pytest.raises(ConfigError, match="config or options, not both"):
        make_estimator("irls", v, irls_config(), median=3)
    with pytest.raises(ConfigError, match="reset\\(\\) and update"):
        make_estimator(object(), v)
