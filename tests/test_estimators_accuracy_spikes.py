"""Beyond the paper: change completion and the output median (estimators/change_completion.py)."""

import numpy as np
import pytest

from estimators.base import samples
from estimators.change_completion import (CausalMedian, ChangeCompletion, causal_median,
                                          l1_completion, run_completed, weak_direction)
from estimators.irls import IRLSConfig, SlidingWindowIRLS, numba_available, solve_window
from estimators.metrics import mean_or_none, score
from estimators.paper.reproduce import sim_config
from quadfault.errors import ConfigError
from quadfault.scenarios import named_scenario
from quadfault.simulator import simulate

YAW = np.array([-1.0, 1.0, -1.0, 1.0]) / 2.0


@pytest.fixture(scope="module")
def combined():
    """8 s of the combined scenario (four 0.33 s faults on a degraded level)."""
    return simulate(named_scenario("combined", 8.0), config=sim_config("rk4", "combined"),
                    seed=11, thrust_noise=0.07)


def test_l1_completion_recovers_a_single_motor_step_from_its_observable_part():
    P = np.eye(4) - np.outer(YAW, YAW)
    for j in range(4):
        for delta in (0.355, -0.5, 0.12):
            step = np.zeros(4)
            step[j] = delta
            # the data fix P step; the prior leaves any component along YAW
            observed = P @ step + 0.3 * YAW
            np.testing.assert_allclose(l1_completion(observed, YAW), step, atol=1e-12)


def test_l1_completion_keeps_the_observable_part_and_minimises_the_l1_norm():
    rng = np.random.default_rng(3)
    P = np.eye(4) - np.outer(YAW, YAW)
    for _ in range(20):
        d = rng.normal(size=4)
        out = l1_completion(d, YAW)
        np.testing.assert_allclose(P @ out, P @ d, atol=1e-12)
        grid = np.linspace(-5, 5, 2001)
        best = min(np.abs(P @ d + a * YAW).sum() for a in grid)
        assert np.abs(out).sum() <= best + 1e-9


def test_weak_direction_is_the_smallest_eigenvector():
    Q = np.linalg.qr(np.random.default_rng(0).normal(size=(4, 4)))[0]
    info = Q @ np.diag([3.0, 2e-4, 1.0, 7.0]) @ Q.T
    v, lam = weak_direction(info)
    assert lam == pytest.approx(2e-4)
    assert abs(abs(v @ Q[:, 1]) - 1.0) < 1e-10


def test_completion_leaves_small_moves_and_well_observed_windows_alone():
    comp = ChangeCompletion(0.1, 5, gamma=5e-3, lower=-0.001, upper=1.001, span=3)
    x0 = np.full(4, 0.9)
    comp.reset(x0)
    x1 = x0 + [0.05, -0.05, 0.0, 0.02]
    np.testing.assert_array_equal(comp.step(x1, lambda: np.eye(4)), x1)
    assert comp.events == 0
    # a step, but the weakest direction carries more information than gamma: no completion
    big = x0 + [0.0, 0.0, -0.3, 0.0] + 0.05 * YAW
    np.testing.assert_array_equal(comp.step(big, lambda: np.eye(4)), big)
    assert comp.events == 1 and comp.v is None


def test_completion_anchors_at_the_estimate_before_the_change():
    """A step of motor 3 that arrives over several windows, with the prior's yaw error."""
    comp = ChangeCompletion(0.2, 4, gamma=5e-3, lower=-0.001, upper=1.001, span=3)
    x0 = np.full(4, 0.9)
    comp.reset(x0)
    weak = np.diag([1.0, 1.0, 1.0, 1e-4])
    Q = np.linalg.qr(np.column_stack([YAW, np.eye(4)[:, :3]]))[0]
    info = Q[:, ::-1] @ weak @ Q[:, ::-1].T  # smallest eigenvector: YAW
    P = np.eye(4) - np.outer(YAW, YAW)
    step = np.array([0.0, 0.0, -0.4, 0.0])
    outs = []
    for frac in (0.1, 0.3, 0.7, 1.0, 1.0, 1.0):
        raw = x0 + P @ (frac * step)  # the data give the observable part only
        outs.append(comp.step(raw, lambda: info))
    assert comp.events == 1
    np.testing.assert_allclose(outs[-1], x0 + step, atol=1e-12)
    np.testing.assert_allclose(outs[0], x0 + P @ (0.1 * step))  # below the threshold


def test_causal_median_matches_a_direct_loop_and_its_online_twin():
    x = np.random.default_rng(1).normal(size=(50, 3))
    L = 7
    padded = np.vstack([np.repeat(x[:1], L - 1, axis=0), x])
    direct = np.array([np.median(padded[k:k + L], axis=0) for k in range(len(x))])
    np.testing.assert_allclose(causal_median(x, L), direct)
    online = CausalMedian(L)
    np.testing.assert_allclose([online.push(row) for row in x], direct)
    np.testing.assert_array_equal(causal_median(x, 1), x)


@pytest.mark.parametrize("bad", [{"output_median": 0}, {"change_hold": True},
                                 {"change_threshold": -0.1}, {"change_completion": 1}])
def test_bad_settings_are_config_errors(bad):
    with pytest.raises(ConfigError):
        IRLSConfig(**bad)


def test_improved_irls_lowers_the_cross_coupling_spike_on_a_seeded_flight(combined):
    blind = combined.without_truth()
    paper = score(combined, SlidingWindowIRLS(combined.vehicle).run(blind))
    better = score(combined, SlidingWindowIRLS(combined.vehicle, IRLSConfig.improved()).run(blind))
    # measured: spike 0.13 -> 0.07, excess spike 0.04 -> 0.00 (seed 11, 8 s)
    assert mean_or_none(better.spike) < 0.75 * mean_or_none(paper.spike)
    assert mean_or_none(better.excess_spike) < mean_or_none(paper.excess_spike) - 0.01
    assert np.mean(better.rmse) < 0.035


def test_completion_alone_removes_most_of_the_transient(combined):
    blind = combined.without_truth()
    paper = score(combined, SlidingWindowIRLS(combined.vehicle).run(blind))
    cfg = IRLSConfig(change_completion=True)
    done = score(combined, SlidingWindowIRLS(combined.vehicle, cfg).run(blind))
    assert mean_or_none(done.excess_spike) < 0.7 * mean_or_none(paper.excess_spike)
    assert np.mean(done.rmse) <= np.mean(paper.rmse) + 1e-3


def test_offline_run_equals_online_updates(combined):
    rec = combined.slice(0, 3000).without_truth()  # holds the first fault (onset 0.67 s)
    cfg = IRLSConfig.improved()
    offline = SlidingWindowIRLS(rec.vehicle, cfg).run(rec)
    est = SlidingWindowIRLS(rec.vehicle, cfg)
    online = np.array([est.update(s).eta for s in samples(rec)])
    assert est._completion.events >= 1
    np.testing.assert_allclose(offline.eta, online, atol=1e-9)


def test_chunked_driver_equals_one_window_at_a_time(combined):
    """run_completed's fast chunks give the same windows as a plain per-window loop."""
    from estimators.residuals import quadratic_terms, segment_models

    rec = combined.slice(0, 900)  # the first onset is at 0.67 s
    cfg = IRLSConfig()
    f = np.clip(rec.thrust_cmd, 0, rec.vehicle.rotor_max_thrust)
    mdl = segment_models(rec.vehicle, rec.t, rec.position, rec.velocity, rec.rotation,
                         rec.omega, f)
    c, b, H = quadratic_terms(mdl, cfg.segment_weights)
    m = cfg.window - 1
    excited = np.ones(len(c) - m + 1, dtype=bool)
    excited[100:103] = False

    if numba_available():  # same algorithm, compiled (the numpy path is tested above)
        from estimators._irls_numba import solve_window_numba

        def solve_one(c_, b_, H_, x):
            return solve_window_numba(c_, b_, H_, x, cfg)
    else:
        def solve_one(c_, b_, H_, x):
            return solve_window(c_, b_, H_, x, cfg)

    def run_chunk(c_, b_, H_, ex, x):
        out_eta, out_sd, out_st = [], [], []
        s = np.full(4, np.nan)
        for k in range(len(ex)):
            if ex[k]:
                xk, sk, d = solve_one(c_[k:k + m], b_[k:k + m], H_[k:k + m], x)
                if sk is not None:
                    x, s = xk, sk
                out_st.append(d.status)
            else:
                out_st.append("no_excitation")
            out_eta.append(x)
            out_sd.append(s)
        return np.array(out_eta), np.array(out_sd), np.array(out_st, dtype=object)

    def info(Hw, w):
        return np.tensordot(w, Hw, 1)

    # threshold low enough to trigger on noise too: many hand-overs between the two paths
    results = []
    for chunk in (1, 37, 10 ** 6):
        comp = ChangeCompletion(0.06, 4, cfg.gamma, cfg.lower, cfg.upper)
        results.append(run_completed(c, b, H, excited, np.ones(4), comp, run_chunk, solve_one,
                                     info, chunk=chunk))
        assert comp.events >= 2
    for eta, sd, status in results[1:]:
        np.testing.assert_allclose(eta, results[0][0], atol=1e-12)
        np.testing.assert_allclose(sd, results[0][1], atol=1e-12)
        assert list(status) == list(results[0][2])


@pytest.mark.skipif(not numba_available(), reason="numba not installed")
def test_numba_and_numpy_paths_agree_with_the_options_on(combined):
    rec = combined.slice(500, 900).without_truth()  # straddles the first onset (0.67 s)
    a = SlidingWindowIRLS(rec.vehicle, IRLSConfig.improved(backend="numba")).run(rec)
    b = SlidingWindowIRLS(rec.vehicle, IRLSConfig.improved(backend="numpy")).run(rec)
    np.testing.assert_allclose(a.eta, b.eta, atol=1e-9)


def test_median_filtered_series_keeps_everything_but_eta(combined):
    from estimators.paper.calibration import median_filtered

    rec = combined.slice(0, 400).without_truth()
    s = SlidingWindowIRLS(rec.vehicle).run(rec)
    f = median_filtered(s, 5)
    np.testing.assert_array_equal(f.eta, causal_median(s.eta, 5))
    np.testing.assert_array_equal(f.sd, s.sd)
    assert f.estimator == s.estimator and list(f.status) == list(s.status)
