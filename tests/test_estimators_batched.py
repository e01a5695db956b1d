"""Batched estimators: row i of a batch gives the single estimator's estimates on vehicle i."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.base import STATUSES, Sample, samples
from estimators.batched import BatchedEKF, BatchedIRLS, make_batched_estimator
from estimators.ekf import EKFConfig, MotorEfficiencyEKF
from estimators.irls import IRLSConfig, SlidingWindowIRLS, numba_available
from quadfault.errors import ConfigError
from quadfault.scenarios import AbruptFault, ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.simulator import simulate
from quadfault.trajectory import Circle, Hover

N_VEHICLES = 3


@pytest.fixture(scope="module")
def flights():
    """Three flights of equal length: different faults, noise and trajectories."""
    out = []
    for k in range(N_VEHICLES):
        sched = EfficiencySchedule(ConstantEfficiency((1.0, 0.9 - 0.1 * k, 0.8, 0.95)),
                                   (AbruptFault(motor=k + 1, onset=0.1, level=0.5),))
        traj = Circle() if k != 1 else Hover()
        sc = Scenario(f"v{k}", 0.2, sched, traj, thrust_noise=0.03 * k)
        out.append(simulate(sc, seed=20 + k).without_truth())
    return out


def _stack(flights):
    rows = [list(samples(rec)) for rec in flights]
    T = min(len(r) for r in rows)
    for k in range(T):
        batch = [r[k] for r in rows]
        yield tuple(np.array([getattr(s, name) for s in batch])
                    for name in ("t", "p", "v", "R", "w", "f"))


def _compare(flights, single_factory, batched, corrupt=None, reset_at=None):
    """Feed both; ``reset_at = (k, row)`` resets that row (batch and single) before step k."""
    singles = [single_factory() for _ in flights]
    n_ok = 0
    for k, sample in enumerate(_stack(flights)):
        if reset_at is not None and k == reset_at[0]:
            mask = np.zeros(len(flights), dtype=bool)
            mask[reset_at[1]] = True
            batched.reset(mask, eta0=np.full(4, 0.8))
            singles[reset_at[1]].reset(np.full(4, 0.8))
        if corrupt is not None and k == corrupt:
            sample = list(sample)
            sample[1] = sample[1].copy()
            sample[1][1] = np.nan  # vehicle 1 gets a bad sample
            sample = tuple(sample)
        out = batched.update(*sample)
        for i, est in enumerate(singles):
            e = est.update(Sample(*(a[i] for a in sample)))
            assert STATUSES[out.status[i]] == e.status, (k, i)
            np.testing.assert_allclose(out.eta[i], e.eta, rtol=0, atol=1e-6)
            if e.sd is None:
                assert np.all(np.isnan(out.sd[i]))
            else:
                np.testing.assert_allclose(out.sd[i], e.sd, rtol=0, atol=1e-6)
            n_ok += e.status == "ok"
    return n_ok, singles


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_batched_irls_matches_single(flights, backend):
    if backend == "numba":
        pytest.importorskip("numba")
    veh = flights[0].vehicle
    cfg = IRLSConfig(backend=backend)
    batched = BatchedIRLS(veh, N_VEHICLES, cfg)
    assert batched.backend == backend
    n_ok, _ = _compare(flights, lambda: SlidingWindowIRLS(veh, cfg), batched, corrupt=40)
    assert n_ok > 100  # the windows were really solved, not held by a guard


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_batched_improved_irls_matches_single(flights, backend):
    """Change completion and output median (IRLSConfig.improved()) row by row, through a
    bad sample and a reset of one row in the middle."""
    if backend == "numba":
        pytest.importorskip("numba")
    veh = flights[0].vehicle
    cfg = IRLSConfig.improved(backend=backend)
    batched = BatchedIRLS(veh, N_VEHICLES, cfg)
    n_ok, singles = _compare(flights, lambda: SlidingWindowIRLS(veh, cfg), batched,
                             corrupt=40, reset_at=(70, 2))
    assert n_ok > 100
    events = [s._completion.events for s in singles]
    assert sum(events) >= 2  # the faults triggered the completion
    np.testing.assert_array_equal(batched._completion.events, events)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_batched_ekf_matches_single(flights, backend):
    if backend == "numba":
        pytest.importorskip("numba")
    veh = flights[0].vehicle
    cfg = EKFConfig(backend=backend)
    batched = BatchedEKF(veh, N_VEHICLES, cfg)
    n_ok, _ = _compare(flights, lambda: MotorEfficiencyEKF(veh, cfg), batched, corrupt=40)
    assert n_ok > 100


def test_batched_irls_reset_restarts_only_masked_rows(flights):
    veh = flights[0].vehicle
    est = BatchedIRLS(veh, N_VEHICLES, IRLSConfig(backend="numpy"))
    for k, sample in enumerate(_stack(flights)):
        out = est.update(*sample)
        if k == 12:
            break
    assert np.all(out.status_names == "ok")
    est.reset(np.array([False, True, False]))
    out = est.update(*next(iter(_stack([f for f in flights]))))  # earlier time: bad for 0, 2
    assert list(out.status_names) == ["bad_sample", "warmup", "bad_sample"]
    np.testing.assert_array_equal(out.eta[1], np.ones(4))


def test_bad_shapes_and_names_raise_config_errors(flights):
    veh = flights[0].vehicle
    est = BatchedIRLS(veh, 2)
    with pytest.raises(ConfigError, match="batched sample"):
        est.update(np.zeros(3), np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3, 3)),
                   np.zeros((3, 3)), np.zeros((3, 4)))
    with pytest.raises(ConfigError, match="reset mask"):
        est.reset(np.ones(5, dtype=bool))
    with pytest.raises(ConfigError, match="integer >= 1"):
        BatchedEKF(veh, 0)
    with pytest.raises(ConfigError, match="no batched estimator"):
        make_batched_estimator("kalman", veh, 2)


@pytest.mark.parametrize("length", [1, 4, 21])
def test_batched_causal_median_equals_single_medians(length):
    """Both pushes (numpy sort, compiled incremental) give N single CausalMedians' values
    exactly, through ties and resets of some rows."""
    from estimators.change_completion import BatchedCausalMedian, CausalMedian

    rng = np.random.default_rng(3)
    N, n = 7, 4
    kernels = [None]
    if numba_available():
        from estimators._irls_online_numba import median_push_rows
        kernels.append(median_push_rows)
    batches = [BatchedCausalMedian(N, n, length, kernel) for kernel in kernels]
    singles = [CausalMedian(length) for _ in range(N)]
    for step in range(60):
        x = np.round(rng.random((N, n)), 1)  # many ties
        if step in (10, 33):
            mask = rng.random(N) < 0.5
            for b in batches:
                b.reset(mask)
            for i in np.flatnonzero(mask):
                singles[i].reset()
        want = np.array([s.push(x[i]) for i, s in enumerate(singles)])
        for b in batches:
            np.testing.assert_array_equal(b.push(x), want)


def test_l1_completion_rows_equals_the_single_completion():
    from estimators.change_completion import l1_completion, l1_completion_rows

    rng = np.random.default_rng(4)
    v = rng.standard_normal((50, 4))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v[3] = [0.0, 0.0, 0.6, 0.8]  # entries the completion must skip
    v[4] = [0.5, -0.5, 0.5, -0.5]  # the yaw mode: ties in the weighted median
    delta = rng.standard_normal((50, 4))
    delta[4] = [0.0, -0.4, 0.0, 0.0]
    want = np.array([l1_completion(d, vi) for d, vi in zip(delta, v)])
    np.testing.assert_allclose(l1_completion_rows(delta, v), want, rtol=0, atol=1e-12)
