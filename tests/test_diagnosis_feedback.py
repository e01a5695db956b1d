"""Closed-loop feedback bias: effect-free fast logs with thrust noise stay consistent, the
instrument (block inputs frozen at the block start) separates real effects from fitted noise
reactions, and timing effects on merged 1 kHz logs are unbiased."""

import numpy as np
import pytest

from quadfault.diagnosis import Diagnosis
from quadfault.diagnosis.fit import fit
from quadfault.diagnosis.library import build_library, predict
from quadfault.diagnosis.residuals import noise_scale, prepare
from quadfault.diagnosis.select import frozen_replay, iv_slope
from quadfault.model import effects as fx
from quadfault.model.scenarios import named_scenario
from quadfault.model.trajectory import Lissajous
from quadfault.sim.simulator import SimConfig, simulate


def _fly(duration, effects=(), thrust_noise=0.07, trajectory=None, seed=0):
    sc = named_scenario("nominal", duration, 1e-3)
    if trajectory is not None:
        sc = sc.replace(trajectory=trajectory)
    return simulate(
        sc, config=SimConfig(dt=1e-3), seed=seed, effects=tuple(effects), thrust_noise=thrust_noise
    ).without_truth()


@pytest.fixture(scope="module")
def noisy_effect_free():
    """The simulator's defaults (1 kHz, control every step, sigma_f = 0.07), no effect."""
    return _fly(8.0)


def _lag(rp):
    return next(c for c in build_library(rp) if c.name == "motor_lag")


def test_frozen_replay_knows_only_what_was_known_at_each_block_start(noisy_effect_free):
    rp = prepare(noisy_effect_free)
    fr = frozen_replay(rp)
    assert rp.raw is not None  # 1 kHz is merged to 4 ms
    t, f = rp.raw["t"], rp.raw["f"]
    for b in (0, 7, rp.n_blocks - 1):
        rows = np.flatnonzero(rp.block == b)
        k0 = rp.knots[rows[0]]
        # states: those of the block's first row, held
        np.testing.assert_array_equal(
            fr.w[rows], np.broadcast_to(noisy_effect_free.omega[k0], (len(rows), 3))
        )
        # commands: the first row's, extrapolated with the slope over the row before it
        raw_rows = np.flatnonzero(np.isin(rp.raw["seg"], rows))
        slope = (f[k0] - f[k0 - 1]) / (t[k0] - t[k0 - 1]) if b > 0 else 0.0 * f[k0]
        expect = f[k0] + (t[raw_rows] - t[k0])[:, None] * slope
        np.testing.assert_allclose(fr.raw["f"][raw_rows], expect, rtol=0, atol=1e-12)
        np.testing.assert_allclose(fr.f[rows], np.asarray(rp.raw["merge"] @ fr.raw["f"])[rows])
    assert not np.array_equal(fr.f, rp.f)


def test_least_squares_fits_a_lag_to_noise_and_the_iv_check_sees_through_it(noisy_effect_free):
    rp = prepare(noisy_effect_free)
    base = predict(rp, [])
    scale = noise_scale(rp, rp.measured - base)
    f = fit(rp, [_lag(rp)], scale)
    assert f.x[0][0] > 0.01  # least squares "finds" a lag that is not there
    slope, se = iv_slope(
        rp, [], f.terms, scale, (rp.measured - base) / scale, np.arange(len(rp.channels))
    )
    assert slope + 2 * se < 0.5


def test_effect_free_noisy_1khz_flight_is_consistent(noisy_effect_free):
    res = Diagnosis().fit(noisy_effect_free)
    assert res.verdict == "consistent", res.effect_names
    assert res.effect_names == []


@pytest.mark.parametrize("tau", [0.02, 0.05])
def test_motor_lag_on_a_merged_1khz_log_is_unbiased(tau):
    rec = _fly(
        4.0,
        [fx.MotorLag(tau)],
        thrust_noise=0.0,
        trajectory=Lissajous(amplitude=(2.0, 1.5, 0.3), frequency=0.3),
    )
    rp = prepare(rec)
    base = predict(rp, [])
    scale = noise_scale(rp, rp.measured - base)
    f = fit(rp, [_lag(rp)], scale)
    assert f.x[0][0] == pytest.approx(tau, rel=0.01)
    slope, se = iv_slope(
        rp, [], f.terms, scale, (rp.measured - base) / scale, np.arange(len(rp.channels))
    )
    assert slope == pytest.approx(1.0, abs=0.1)


@pytest.mark.slow
def test_real_lag_with_thrust_noise_is_found():
    rec = _fly(
        8.0,
        [fx.MotorLag(0.04)],
        thrust_noise=0.05,
        trajectory=Lissajous(amplitude=(2.0, 1.5, 0.3), frequency=0.3),
        seed=3,
    )
    res = Diagnosis().fit(rec)
    assert res.effect_names[:1] == ["motor_lag"]
    tau = res.to_dict()["effects"][0]["params"]["tau_s"]
    assert tau == pytest.approx(0.04, rel=0.1)
