"""Calibration of the EKF's reported sd (estimators.paper.calibration.calibrate_sd_scale): a scale
fitted on one seed gives about one-sigma coverage on held-out seeds; clear errors."""

import numpy as np
import pytest

from estimators.ekf import EKFConfig, MotorEfficiencyEKF
from estimators.metrics import score
from estimators.paper.calibration import ONE_SIGMA, SdCalibration, calibrate_sd_scale
from quadfault.errors import ConfigError
from quadfault.model.scenarios import ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.model.trajectory import Circle
from quadfault.sim.simulator import simulate

_FLIGHTS = {}


def _flight(seed, duration=2.0):
    """A circle with constant unequal efficiencies and sigma_f = 0.07 (simulated once)."""
    if (seed, duration) not in _FLIGHTS:
        _FLIGHTS[seed, duration] = _simulate(seed, duration)
    return _FLIGHTS[seed, duration]


def _simulate(seed, duration):
    sc = Scenario(
        "const",
        duration,
        EfficiencySchedule(ConstantEfficiency((0.9, 0.75, 1.0, 0.6))),
        Circle(),
        thrust_noise=0.07,
    )
    return simulate(sc, seed=seed)


@pytest.fixture(scope="module")
def calibration():
    return calibrate_sd_scale(_flight(1000))


def test_raw_sd_is_a_loose_bound_and_the_scale_shrinks_it(calibration):
    assert isinstance(calibration, SdCalibration)
    assert calibration.raw_coverage > 0.99  # the filter's own sd: a model-based bound
    assert 0 < calibration.scale < 0.05
    assert calibration.coverage == ONE_SIGMA and calibration.samples > 4000


@pytest.mark.parametrize("seed", [0, 1])
def test_scaled_sd_has_one_sigma_coverage_on_held_out_seeds(calibration, seed):
    rec = _flight(seed)
    raw = MotorEfficiencyEKF(rec.vehicle, calibration.config).run(rec.without_truth())
    scaled = calibration.apply(raw)
    np.testing.assert_array_equal(scaled.eta, raw.eta)
    np.testing.assert_allclose(scaled.sd, raw.sd * calibration.scale)
    cov = np.mean(score(rec, scaled).coverage)
    assert 0.58 < cov < 0.78, cov
    assert np.mean(score(rec, raw).coverage) > 0.99


def test_scale_depends_on_the_tuning(calibration):
    rec = _flight(1000)
    other = calibrate_sd_scale(rec, EKFConfig(q_eta=1e-3))
    assert other.config.q_eta == 1e-3
    assert abs(np.log(other.scale / calibration.scale)) > 0.2


def test_bad_inputs_are_clear_errors():
    rec = _flight(2, duration=0.2)
    with pytest.raises(ConfigError, match="coverage"):
        calibrate_sd_scale(rec, coverage=1.5)
    with pytest.raises(ConfigError, match="no true efficiency"):
        calibrate_sd_scale(rec.without_truth())
