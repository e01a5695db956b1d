"""The estimators under sensor noise: the residual prefilter (the same low-pass on both sides
of the IRLS's and the RLS's regression) on seeded noisy flights, the RLS's prefiltered update
against a numpy form, online = offline = batched with the prefilter, and clean errors.

The accuracy targets over the paper's scenarios and several seeds are checked by
``benchmarks/studies/noise_accuracy.py``; these are small seeded cases of the same behaviour."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimators.base import samples
from estimators.batched import BatchedIRLS
from estimators.cli import check_options
from estimators.ekf import IDLE_THRUST, MotorEfficiencyEKF
from estimators.irls import IRLSConfig, SlidingWindowIRLS
from estimators.residuals import segment_terms
from estimators.rls import BatchedRLS, RecursiveLeastSquares, RLSConfig
from estimators.ukf import UnscentedKalmanFilter
from quadfault.errors import ConfigError
from quadfault.model.scenarios import AbruptFault, ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.model.sensors import SensorNoise
from quadfault.model.trajectory import Circle, Lissajous
from quadfault.sim.simulator import SimConfig, simulate

#: white noise std of position [m], velocity [m/s], attitude [rad], gyro [rad/s] and
#: accelerometer [m/s^2]: about what a small vehicle's estimator output and IMU carry
NOISE = SensorNoise(0.003, 0.01, 0.003, 0.01, 0.1)


def _fly(schedule, duration, trajectory, seed, noise=NOISE):
    scenario = Scenario("noisy", duration, schedule, trajectory, thrust_noise=0.07)
    return simulate(scenario, config=SimConfig(saturate=False, sensor_noise=noise), seed=seed)


@pytest.fixture(scope="module")
def weak():
    """4 s of a Lissajous flight with sensor noise, rotor 3 at 0.8 throughout."""
    sched = EfficiencySchedule(ConstantEfficiency((1.0, 1.0, 0.8, 1.0)))
    return _fly(sched, 4.0, Lissajous(), seed=7)


@pytest.fixture(scope="module")
def fault():
    """3 s of the circle with sensor noise, rotor 2 dropping to 0.6 at 1.5 s."""
    sched = EfficiencySchedule(ConstantEfficiency(), (AbruptFault(motor=2, onset=1.5, level=0.6),))
    return _fly(sched, 3.0, Circle(), seed=5)


def _errors(rec, series, after):
    late = series.t >= after
    return series.eta[late] - rec.eta_true[late]


ROBUST = {
    "irls prefilter": lambda v: SlidingWindowIRLS(v, IRLSConfig(prefilter=0.01)),
    "irls improved": lambda v: SlidingWindowIRLS(v, IRLSConfig.improved()),
    "rls": lambda v: RecursiveLeastSquares(v),
    "ekf": lambda v: MotorEfficiencyEKF(v),
    "ukf": lambda v: UnscentedKalmanFilter(v),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(ROBUST))
def test_a_weak_rotor_is_found_under_sensor_noise(weak, name):
    est = ROBUST[name](weak.vehicle).run(weak.without_truth())
    e = _errors(weak, est, 1.0)
    assert np.sqrt(np.mean(e**2)) < 0.06, (name, np.sqrt(np.mean(e**2, axis=0)))
    healthy = np.mean(e[:, [0, 1, 3]])
    assert abs(healthy) < 0.03, (name, healthy)
    mean = est.eta[est.t >= 1.0].mean(axis=0)
    assert int(np.argmin(mean)) == 2, (name, mean)


def test_the_prefilter_removes_the_noise_of_the_paper_residual(weak):
    """Sensor noise differenced over 1 ms swamps the paper's residual (its estimate falls far
    below the truth, clipped at the upper bound); the prefilter restores the accuracy."""
    rec = weak.without_truth()
    paper = SlidingWindowIRLS(rec.vehicle).run(rec)
    filtered = SlidingWindowIRLS(rec.vehicle, IRLSConfig(prefilter=0.01)).run(rec)
    rmse_paper = np.sqrt(np.mean(_errors(weak, paper, 1.0) ** 2))
    rmse_filtered = np.sqrt(np.mean(_errors(weak, filtered, 1.0) ** 2))
    assert rmse_paper > 0.1 and rmse_filtered < rmse_paper / 3, (rmse_paper, rmse_filtered)


def test_an_abrupt_fault_is_followed_under_sensor_noise(fault):
    for name in ("irls improved", "rls", "ekf"):
        est = ROBUST[name](fault.vehicle).run(fault.without_truth())
        k = np.searchsorted(est.t, [1.4, 1.6, 2.9])
        assert est.eta[k[0], 1] > 0.9, name
        assert est.eta[k[1], 1] < 0.75, (name, est.eta[k[1]])  # within 0.1 s of the drop
        assert abs(est.eta[k[2], 1] - 0.6) < 0.08, (name, est.eta[k[2]])


def test_rls_with_the_prefilter_equals_a_numpy_form(fault):
    """The covariance-form RLS on the residual model low-passed on both sides
    (``x_f <- a x_f + (1 - a) x``, ``a = exp(-dt / tau)``), the velocity rows weighted as one
    block (the sensitivity of the thrust along any axis), in numpy."""
    rec = fault.without_truth().slice(0, 300)
    lam, tau = 0.98, 0.01
    f = np.maximum(rec.thrust_cmd, 0.0)  # an unsaturated flight: no upper clip
    seg = segment_terms(
        rec.vehicle, rec.t, rec.position, rec.velocity, rec.rotation, rec.omega, f, np.ones(10)
    )
    theta, P = np.ones(4), np.eye(4)
    r0f = Jf = None
    expected = [theta.copy()]
    for k in range(len(seg.dt)):
        if np.any(f[k] <= IDLE_THRUST):  # an idle rotor: no update, the filter waits
            expected.append(theta.copy())
            continue
        a = np.exp(-seg.dt[k] / tau) if r0f is not None else 0.0
        r0f = seg.r0[k] if r0f is None else a * r0f + (1 - a) * seg.r0[k]
        Jf = seg.J[k] if Jf is None else a * Jf + (1 - a) * seg.J[k]
        c2 = np.array([np.sum((seg.J[k, r] / f[k]) ** 2) for r in (0, 1, 2, 6, 7, 8)])
        g = np.where(c2 > 0, 1.0 / np.where(c2 > 0, c2, 1.0), 0.0)
        g[:3] = 1.0 / np.sum(c2[:3])
        P = P / lam ** (seg.dt[k] / 1e-3)
        for q, r in enumerate((0, 1, 2, 6, 7, 8)):
            if g[q] == 0.0:
                continue
            phi, y = Jf[r], -r0f[r]
            Pphi = P @ phi
            den = 1.0 / g[q] + phi @ Pphi
            theta = theta + Pphi * (y - phi @ theta) / den
            P = P - np.outer(Pphi, Pphi) / den
        theta = np.clip(theta, -0.001, 1.2)
        expected.append(theta.copy())
    cfg = RLSConfig(forgetting=lam, prefilter=tau)
    got = RecursiveLeastSquares(rec.vehicle, cfg).run(rec)
    np.testing.assert_allclose(got.eta, np.array(expected), rtol=0, atol=1e-10)


@pytest.mark.slow
@pytest.mark.parametrize(
    "single,batched,config",
    [
        (SlidingWindowIRLS, BatchedIRLS, IRLSConfig(prefilter=0.02)),
        (SlidingWindowIRLS, BatchedIRLS, IRLSConfig.improved()),
        (RecursiveLeastSquares, BatchedRLS, RLSConfig(prefilter=0.02)),
        (RecursiveLeastSquares, BatchedRLS, RLSConfig(accelerometer="on")),
    ],
)
def test_prefiltered_online_offline_and_batched_agree(fault, single, batched, config):
    """The prefilter's state lives in the estimator's state: a loop of ``update`` (through a
    bad sample, which restarts the filter), ``run`` and a batch row give the same numbers."""
    rec = fault.without_truth().slice(0, 400)
    vehicle = rec.vehicle.replace(max_thrust=math.inf)  # unsaturated, as run() reads it
    est = single(vehicle, config)
    rows = list(samples(rec))
    rows[150] = rows[150]._replace(v=np.full(3, np.nan))
    online = np.array([est.update(s).eta for s in rows])
    est.reset()
    good = np.array([est.update(s).eta for s in rows[:150]])
    np.testing.assert_array_equal(good, online[:150])
    offline = single(vehicle, config).run(rec)
    np.testing.assert_array_equal(offline.eta[:150], online[:150])
    batch = batched(vehicle, 2, config)
    for k, s in enumerate(rows):
        fields = ("t", "p", "v", "R", "w", "f")
        out = batch.update(*(np.array([getattr(s, a)] * 2) for a in fields), accel=[s.accel] * 2)
        np.testing.assert_array_equal(out.eta[1], online[k])


def test_the_prefilter_is_off_in_the_paper_configuration():
    assert IRLSConfig().prefilter == 0.0
    assert IRLSConfig.improved().prefilter > 0.0 and RLSConfig().prefilter > 0.0


@pytest.mark.parametrize("value", [-0.01, float("nan"), float("inf"), True, "0.01"])
def test_a_bad_prefilter_is_a_clear_error(value):
    with pytest.raises(ConfigError, match="prefilter"):
        IRLSConfig(prefilter=value)
    with pytest.raises(ConfigError, match="prefilter"):
        RLSConfig(prefilter=value)


def test_prefilter_is_an_option_of_the_irls_and_the_rls_only():
    check_options("irls", False, None, None, None, 0.02)
    check_options("rls", False, None, None, None, 0.02)
    with pytest.raises(ConfigError, match="--prefilter applies to the irls, rls"):
        check_options("ekf", False, None, None, None, 0.02)
    with pytest.raises(ConfigError, match="--prefilter must be"):
        check_options("irls", False, None, None, None, -1.0)
