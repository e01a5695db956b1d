"""What the diagnosis reports: suspects at a bound, rejected fits, fixed (non-circular) channel
weights with per-channel intervals, localised mismatches, the recording's own frame, pairs,
measured rotor speeds."""

import dataclasses

import numpy as np
import pytest

from quadfault.diagnosis import Diagnosis, DiagnosisConfig
from quadfault.diagnosis.crossval import at_bound, fold_agreement
from quadfault.diagnosis.library import build_library, predict
from quadfault.diagnosis.residuals import prepare
from quadfault.diagnosis.scores import fixed_scoring
from quadfault.diagnosis.select import select
from quadfault.io.recording import read_recording, write_recording
from quadfault.model import effects as fx
from quadfault.model.scenarios import named_scenario
from quadfault.model.trajectory import Lissajous
from quadfault.sim.simulator import SensorNoise, SimConfig, simulate

DT = 4e-3
TRAJ = Lissajous(amplitude=(2.0, 1.5, 0.3), frequency=0.15)


def fly(effects=(), seed=1, duration=8.0, **kw):
    sc = named_scenario("nominal", duration, DT).replace(trajectory=TRAJ)
    cfg = SimConfig(dt=DT, sensor_noise=SensorNoise(0.002, 0.005, 0.001, 0.001))
    return simulate(
        sc, config=cfg, seed=seed, effects=tuple(effects), thrust_noise=0.02, **kw
    ).without_truth()


@pytest.fixture(scope="module")
def lag_and_drag():
    return fly((fx.MotorLag(0.04), fx.Drag(0.3)), seed=5)


def test_at_bound_ignores_a_bound_that_is_the_neutral_value():
    rp = prepare(fly(duration=2.0))
    lib = {c.name: c for c in build_library(rp)}
    drag, inertia = lib["drag"], lib["inertia"]
    assert not at_bound(drag, [0.3, 0.3, 0.0])  # no drag on z is "no effect", not absurd
    assert at_bound(inertia, inertia.upper) and at_bound(inertia, inertia.lower)
    assert not at_bound(inertia, [1.3, 1.3, 1.0])


def test_fold_agreement_accepts_consistent_folds_and_rejects_contradicting_ones():
    rp = prepare(fly(duration=2.0))
    lag = next(c for c in build_library(rp) if c.name == "motor_lag")
    ok, _ = fold_agreement(lag, [0.08], [[0.081], [0.079], [0.080], [0.082], [0.078]])
    assert ok
    bad, detail = fold_agreement(lag, [0.05], [[0.2], [0.001], [0.09], [0.004], [0.01]])
    assert not bad and "jackknife" in detail
    edge, detail = fold_agreement(lag, [0.3], [[0.3]] * 4 + [[lag.upper[0]]])
    assert not edge and "bound" in detail


def test_a_fit_beyond_the_bounds_is_suspect_never_accepted():
    """An inertia beyond what the library allows: the fit sits at the bound."""
    rp = prepare(fly(duration=2.0))
    hi = next(c for c in build_library(rp) if c.name == "inertia").upper[0]
    s = 1.25 * hi
    rec = fly((fx.Inertia((s, s, s)),), seed=2)
    res = Diagnosis().fit(rec)
    assert res.verdict == "mismatch"
    assert "inertia" not in res.effect_names
    sus = {e.name: e for e in res.suspect}
    assert "inertia" in sus and sus["inertia"].at_bound
    np.testing.assert_allclose(sus["inertia"].params["scale"], hi, rtol=0.03)
    assert "bound" in sus["inertia"].explanation and sus["inertia"].improvement > 0.3
    doc = res.to_dict()
    assert all(e["at_bound"] for e in doc["suspect"])
    assert all(set(e) >= {"params", "improvement", "reason", "bounds"} for e in doc["rejected"])


@pytest.mark.slow
def test_every_fitted_effect_reports_bounds_and_fold_values(lag_and_drag):
    res = Diagnosis().fit(lag_and_drag)
    assert {"motor_lag", "drag"} <= set(res.effect_names)
    every = res.effects + res.suspect + res.rejected
    rp = prepare(lag_and_drag)
    assert {e.name for e in every} == {c.name for c in build_library(rp) if c.testable(rp)}
    for e in every:  # bounds in the keys of the fitted parameters, which lie inside them
        assert e.bounds and set(e.bounds) <= set(e.params)
        for k, (lo, hi) in e.bounds.items():
            assert np.all(np.asarray(lo) <= np.asarray(e.params[k]) + 1e-12)
            assert np.all(np.asarray(e.params[k]) <= np.asarray(hi) + 1e-12)
    lag = next(e for e in res.effects if e.name == "motor_lag")
    assert len(lag.folds["tau_s"]) == 5
    assert np.std(lag.folds["tau_s"]) < 0.1 * lag.params["tau_s"]
    assert lag.params["tau_s"] == pytest.approx(0.04, rel=0.15)
    # --effects X always shows X's fit, accepted or not
    only = Diagnosis(DiagnosisConfig(effects=("wind",))).fit(lag_and_drag)
    assert [e.name for e in only.effects + only.suspect + only.rejected] == ["wind"]


@pytest.mark.slow
def test_channel_weights_are_fixed_before_any_fit(lag_and_drag):
    """The noise scale comes from the data and the nominal model only: the same whatever
    library is fitted, so a selected model can never set its own score's weights."""
    a = Diagnosis(DiagnosisConfig(effects=("motor_lag",))).fit(lag_and_drag)
    b = Diagnosis(DiagnosisConfig(effects=("drag", "wind"))).fit(lag_and_drag)
    c = Diagnosis().fit(lag_and_drag)
    assert a.scale == b.scale == c.scale
    assert a.baseline_rmse == b.baseline_rmse == c.baseline_rmse
    rp = prepare(lag_and_drag)
    nominal = fixed_scoring(rp, rp.measured - predict(rp, []))
    np.testing.assert_array_equal(np.asarray(c.scale), nominal.noise)
    # and not the noise scale of the selected model's residual (the circular choice)
    lib = {x.name: x for x in build_library(rp)}
    truth = [(lib["motor_lag"], [0.04]), (lib["drag"], [0.3, 0.3, 0.3])]
    circular = fixed_scoring(rp, rp.measured - predict(rp, truth))
    assert not np.allclose(nominal.noise, circular.noise, rtol=0.05)


def test_per_channel_figures_with_intervals(lag_and_drag):
    res = Diagnosis().fit(lag_and_drag)
    assert set(res.channel_scores) == set(res.channels)
    for ch, v in res.channel_scores.items():
        lo, hi = v["ci95"]
        assert lo <= v["improvement"] + 1e-9 and v["improvement"] <= hi + 1e-9
        assert v["improvement"] == pytest.approx(1 - v["rmse_after"] / v["rmse_before"])
        assert v["rmse_before"] == pytest.approx(res.baseline_rmse[ch])
    # the lag shows in the angular channels, the drag in the translational ones (plainly in
    # the accelerometer, which has no velocity-differencing noise)
    assert res.channel_scores["alpha_x"]["ci95"][0] > 0.5
    assert res.channel_scores["sf_x"]["ci95"][0] > 0.9
    assert res.channel_scores["acc_x"]["ci95"][0] > 0.1
    lo, hi = res.model_ci95
    assert lo < res.model_improvement < hi


def test_a_strong_localised_mismatch_is_never_consistent():
    """An unexplained push for 2 s (about 5x the block noise): the whole-flight RMS stays
    small, the verdict must not."""
    rec = fly(seed=6, duration=10.0)
    v = rec.velocity.copy()
    t = rec.t
    push = np.clip((t - 4.0) / 1.0, 0.0, 1.0) - np.clip((t - 5.0) / 1.0, 0.0, 1.0)
    v[:, 1] += 2.0 * push  # +2 m/s^2 for 1 s, then -2 m/s^2 for 1 s: a bump in velocity
    bumped = dataclasses.replace(rec, velocity=v)
    res = Diagnosis().fit(bumped)
    assert any(w.channel == "acc_y" and w.t0 < 5.0 and w.t1 > 4.0 for w in res.where)
    assert res.verdict == "mismatch"
    z = res.series["baseline"] / np.asarray(res.scale)
    assert np.sqrt(np.mean(z * z)) < 3.0  # a whole-flight RMS threshold would have missed it
    assert Diagnosis().fit(rec).verdict == "consistent"


@pytest.mark.slow
def test_directions_are_reported_in_the_recordings_own_frame(tmp_path):
    rec = fly((fx.Wind((2.0, -1.0, 0.0), k=0.3),), seed=7)
    for frame in ("NED", "ENU"):
        path = tmp_path / f"{frame}.csv"
        write_recording(rec, path, frame=frame)
        res = Diagnosis().fit(read_recording(path))
        wind = next(e for e in res.effects if e.name == "wind")
        F = np.asarray(wind.params["force_N"])
        expected = [0.6, -0.3, 0.0] if frame == "NED" else [-0.3, 0.6, 0.0]
        np.testing.assert_allclose(F[:2], expected[:2], atol=0.08)
        assert frame in wind.explanation
        lo, hi = (np.asarray(x) for x in wind.bounds["force_N"])
        assert np.all(lo <= F) and np.all(F <= hi)
        assert res.to_dict()["frame"] == frame


def test_two_effects_can_enter_in_one_step_as_a_pair(lag_and_drag):
    rp = prepare(lag_and_drag)
    lib = build_library(rp)
    sc = fixed_scoring(rp, rp.measured - predict(rp, []))
    sel = select(rp, lib, sc, pair_top=3)
    names = [s.candidate.name for s in sel.steps]
    assert {"motor_lag", "drag"} <= set(names)
    first_two = sel.steps[:2]
    assert first_two[0].cv is first_two[1].cv  # accepted together, as one pair
    greedy = select(rp, lib, sc, pair_top=0)
    assert greedy.steps[0].cv is not greedy.steps[1].cv


@pytest.mark.slow
def test_measured_rotor_speeds_identify_the_motor_lag():
    """Rotor speeds that follow the command through a 40 ms lag, with the sidecar's k: the
    speed sampled in row k is the rotor's at t_k, reached under the commands before it."""
    k = 1e-5
    rec = fly((fx.MotorLag(0.04),), seed=8)
    lagged = fx.lag_series(rec.thrust_cmd, np.r_[np.diff(rec.t), DT], 0.04)
    lagged = np.vstack((rec.thrust_cmd[:1], lagged[:-1]))  # value at the end of interval k-1
    omega = np.sqrt(np.maximum(lagged, 0.0) / k)
    omega[100:103, 2] = np.nan  # a few telemetry dropouts
    with_rotor = dataclasses.replace(rec, rotor_speed=omega, meta={"rotor_thrust_coefficient": k})
    res = Diagnosis().fit(with_rotor)
    assert {f"rotor_{i}" for i in range(1, 5)} <= set(res.channels)
    lag = next(e for e in res.effects if e.name == "motor_lag")
    assert lag.params["tau_s"] == pytest.approx(0.04, rel=0.05)
    assert "from command to measured rotor speed directly" in lag.explanation
    assert not lag.at_bound
    assert res.channel_scores["rotor_1"]["improvement"] > 0.8
    assert res.scoring["rotor_thrust_coefficient"] == {"value": k, "source": "sidecar"}
