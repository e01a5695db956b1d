"""Fault detection and isolation on estimate streams: hand-made series and a seeded flight."""

import numpy as np
import pytest

from estimators.base import Estimate, EstimateSeries
from estimators.fdi import FaultDetector, FDIConfig, detect, evaluate
from quadfault.errors import ConfigError

DT = 1e-3


def _series(eta, status=None):
    n = len(eta)
    return EstimateSeries(
        t=DT * np.arange(n),
        eta=np.asarray(eta, float),
        sd=None,
        status=np.array(status or ["ok"] * n),
        estimator="test",
    )


def _abrupt(seed=0, n=6000, motor=3, onset=2.0, end=4.0, noise=0.02, leak=0.12):
    """Efficiency estimates: noise, motor `motor` drops to 0.5 on [onset, end], and the other
    motors get a transient of +-leak for 50 ms at each edge (cross-coupling)."""
    rng = np.random.default_rng(seed)
    t = DT * np.arange(n)
    eta = 0.95 + noise * rng.standard_normal((n, 4))
    eta[(t >= onset) & (t < end), motor - 1] -= 0.45
    for edge, sign in ((onset, -1.0), (end, 1.0)):
        near = (t >= edge) & (t < edge + 0.05)
        for m in range(4):
            if m != motor - 1:
                eta[near, m] += sign * leak * (1 if m % 2 else -1)
    return eta


def test_abrupt_drop_is_detected_isolated_and_cleared():
    eta = _abrupt()
    res = detect(_series(eta))
    raised = [a for a in res.events if a.kind == "raised"]
    assert [a.motor for a in raised] == [3]
    assert 2.0 <= raised[0].t <= 2.1  # within 0.1 s
    assert raised[0].baseline == pytest.approx(0.95, abs=0.02)
    assert raised[0].drop > 0.2
    cleared = [a for a in res.events if a.kind == "cleared"]
    assert [a.motor for a in cleared] == [3] and 4.0 <= cleared[0].t <= 4.1
    score = evaluate(res, [(3, 2.0, 4.0)])
    assert score.detected == 1 and score.false_alarms == 0 and score.latencies[0] < 0.1
    assert res.active[int(3.0 / DT)].tolist() == [False, False, True, False]
    assert not res.active[-1].any()


def test_slow_degradation_and_noise_raise_nothing():
    rng = np.random.default_rng(1)
    n = 20000
    t = DT * np.arange(n)
    eta = np.exp(0.25 * (-t / 20.0))[:, None] + 0.03 * rng.standard_normal((n, 4))
    res = detect(_series(eta))
    assert res.events == ()


def test_noisy_estimator_raises_its_threshold():
    """The threshold follows the running noise RMS (sd_gain): a 0.25 drop is a fault for a
    quiet estimator and noise for one with an RMS of 0.08."""
    quiet = _abrupt(noise=0.01, leak=0.0)
    quiet[:, 2] = np.where(quiet[:, 2] < 0.7, quiet[:, 2] + 0.2, quiet[:, 2])  # drop of 0.25
    assert [a.motor for a in detect(_series(quiet)).events if a.kind == "raised"] == [3]
    noisy = _abrupt(noise=0.08, leak=0.0)
    noisy[:, 2] = np.where(np.arange(len(noisy)) * DT >= 2.0, noisy[:, 2] + 0.2, noisy[:, 2])
    cfg = FDIConfig(tau_smooth=0.001)  # no smoothing: the raw noise sets the threshold
    assert detect(_series(noisy), cfg).events == ()


def test_online_equals_offline_and_warmup_is_ignored():
    eta = _abrupt(seed=2)
    status = ["warmup"] * 9 + ["ok"] * (len(eta) - 9)
    eta[:9] = 0.0  # warm-up rows hold nothing meaningful
    off = detect(_series(eta, status))
    det = FaultDetector(4)
    on = []
    for k in range(len(eta)):
        on += det.update(Estimate(k * DT, eta[k], None, status[k]))
    assert on == list(off.events) and len(on) == 2


def test_no_alarm_while_settling():
    eta = _abrupt(onset=0.3, end=0.6)
    assert detect(_series(eta), FDIConfig(settle=1.0)).events == ()
    assert len(detect(_series(eta), FDIConfig(settle=0.1)).events) == 2


@pytest.mark.parametrize(
    "changes", [{"threshold": 0}, {"clear": 1.5}, {"confirm": -1.0}, {"tau_baseline": float("inf")}]
)
def test_bad_config_is_a_clear_error(changes):
    with pytest.raises(ConfigError, match="FDIConfig"):
        FDIConfig(**changes)


def test_wrong_motor_count_is_a_clear_error():
    with pytest.raises(ConfigError, match="efficiencies"):
        FaultDetector(4).update(Estimate(0.0, np.ones(3)))


def test_irls_stream_of_a_seeded_abrupt_flight():
    """End to end: simulated abrupt faults (12 s, schedule scaled), IRLS, the detector."""
    from estimators.irls import SlidingWindowIRLS
    from estimators.metrics import fault_windows
    from estimators.paper.reproduce import flight_check, sim_config
    from quadfault.model.scenarios import named_scenario
    from quadfault.sim.simulator import simulate

    rec = simulate(named_scenario("abrupt", 12.0), config=sim_config("rk4", "abrupt"), seed=5)
    assert not flight_check(rec)["diverged"]
    est = SlidingWindowIRLS(rec.vehicle).run(rec.without_truth())
    windows = fault_windows(rec)
    s = evaluate(detect(est, FDIConfig(settle=0.5)), windows)
    assert s.detected == 4 and s.false_alarms == 0
    assert max(s.latencies) < 0.1
