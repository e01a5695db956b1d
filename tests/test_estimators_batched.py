"""Batched estimators: row i of a batch gives the single estimator's estimates on vehicle i
(the batch runs the single estimators' compiled steps over its rows)."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.base import STATUSES, Sample, samples
from estimators.batched import BatchedEKF, BatchedIRLS
from estimators.ekf import MotorEfficiencyEKF
from estimators.irls import IRLSConfig, SlidingWindowIRLS
from estimators.registry import make_estimator
from quadfault.errors import ConfigError
from quadfault.model.scenarios import AbruptFault, ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.model.trajectory import Circle, Hover
from quadfault.sim.simulator import simulate

N_VEHICLES = 3


@pytest.fixture(scope="module")
def flights():
    """Three flights of equal length: different faults, noise and trajectories."""
    out = []
    for k in range(N_VEHICLES):
        sched = EfficiencySchedule(
            ConstantEfficiency((1.0, 0.9 - 0.1 * k, 0.8, 0.95)),
            (AbruptFault(motor=k + 1, onset=0.1, level=0.5),),
        )
        traj = Circle() if k != 1 else Hover()
        sc = Scenario(f"v{k}", 0.2, sched, traj, thrust_noise=0.03 * k)
        out.append(simulate(sc, seed=20 + k).without_truth())
    return out


def _stack(flights):
    rows = [list(samples(rec)) for rec in flights]
    T = min(len(r) for r in rows)
    for k in range(T):
        batch = [r[k] for r in rows]
        yield tuple(
            np.array([getattr(s, name) for s in batch]) for name in ("t", "p", "v", "R", "w", "f")
        )


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
            np.testing.assert_array_equal(out.eta[i], e.eta)  # the same kernel: bit for bit
            if e.sd is None:
                assert np.all(np.isnan(out.sd[i]))
            else:
                np.testing.assert_array_equal(out.sd[i], e.sd)
            n_ok += e.status == "ok"
    return n_ok, singles


def test_batched_irls_matches_single(flights):
    veh = flights[0].vehicle
    batched = BatchedIRLS(veh, N_VEHICLES)
    n_ok, _ = _compare(flights, lambda: SlidingWindowIRLS(veh), batched, corrupt=40)
    assert n_ok > 100  # the windows were really solved, not held by a guard


@pytest.mark.slow
def test_batched_improved_irls_matches_single(flights):
    """Change completion and output median (IRLSConfig.improved()) row by row, through a
    bad sample and a reset of one row in the middle."""
    veh = flights[0].vehicle
    cfg = IRLSConfig.improved()
    batched = BatchedIRLS(veh, N_VEHICLES, cfg)
    n_ok, singles = _compare(
        flights, lambda: SlidingWindowIRLS(veh, cfg), batched, corrupt=40, reset_at=(70, 2)
    )
    assert n_ok > 100
    events = [s.change_events for s in singles]
    assert sum(events) >= 2  # the faults triggered the completion
    np.testing.assert_array_equal(batched.change_events, events)


@pytest.mark.slow
def test_batched_ekf_matches_single(flights):
    veh = flights[0].vehicle
    batched = BatchedEKF(veh, N_VEHICLES)
    n_ok, _ = _compare(
        flights, lambda: MotorEfficiencyEKF(veh), batched, corrupt=40, reset_at=(70, 1)
    )
    assert n_ok > 100


def test_batched_ekf_follows_the_single_rules_for_idle_rotors_and_repeated_times(flights):
    """An idle rotor holds the efficiencies (no_excitation) and a repeated time stamp is a
    bad sample, in every row, as in the single filter."""
    veh = flights[0].vehicle
    rows = [list(samples(rec))[:30] for rec in flights]
    for k in range(12, 16):
        rows[0][k] = rows[0][k]._replace(f=np.array([0.0, 2.0, 2.0, 2.0]))
    rows[2][20] = rows[2][20]._replace(t=rows[2][19].t)
    batched = BatchedEKF(veh, N_VEHICLES)
    singles = [MotorEfficiencyEKF(veh) for _ in flights]
    seen = set()
    for k in range(30):
        batch = [r[k] for r in rows]
        out = batched.update(
            *(np.array([getattr(s, f) for s in batch]) for f in ("t", "p", "v", "R", "w", "f"))
        )
        for i, est in enumerate(singles):
            e = est.update(batch[i])
            assert STATUSES[out.status[i]] == e.status
            np.testing.assert_array_equal(out.eta[i], e.eta)
            seen.add(e.status)
    assert {"no_excitation", "bad_sample"} <= seen


def test_batched_irls_reset_restarts_only_masked_rows(flights):
    veh = flights[0].vehicle
    est = BatchedIRLS(veh, N_VEHICLES)
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
        est.update(
            np.zeros(3),
            np.zeros((3, 3)),
            np.zeros((3, 3)),
            np.zeros((3, 3, 3)),
            np.zeros((3, 3)),
            np.zeros((3, 4)),
        )
    with pytest.raises(ConfigError, match="reset mask"):
        est.reset(np.ones(5, dtype=bool))
    with pytest.raises(ConfigError, match="integer >= 1"):
        BatchedEKF(veh, 0)
    with pytest.raises(ConfigError, match="unknown estimator"):
        make_estimator("kalman", veh, num=2)
    with pytest.raises(ConfigError, match="no batched form"):
        make_estimator("none", veh, num=2)
