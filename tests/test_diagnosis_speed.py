"""Diagnosis fast paths give the same answers as the slow ones; calibration rows are not scored;
the inertia instrumental-variable check separates feedback bias from a real effect."""

import dataclasses
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.optimize import least_squares

from quadfault.diagnosis import Diagnosis
from quadfault.diagnosis.fit import Linearisation, fit, linearisation, solve_linear
from quadfault.diagnosis.library import build_library, predict
from quadfault.diagnosis.residuals import noise_scale, prepare
from quadfault.diagnosis.select import iv_slope
from quadfault.errors import RecordingError
from quadfault.model import effects as fx
from quadfault.model.scenarios import named_scenario
from quadfault.model.trajectory import Lissajous
from quadfault.model.vehicle import PAPER_YAW_SIGNS, Vehicle
from quadfault.sim.simulator import SensorNoise, SimConfig, simulate


@pytest.fixture(scope="module")
def drag_recording():
    sc = named_scenario("nominal", 6.0, 4e-3).replace(
        trajectory=Lissajous(amplitude=(2.0, 1.5, 0.3), frequency=0.2)
    )
    cfg = SimConfig(dt=4e-3, sensor_noise=SensorNoise(0.002, 0.005, 0.001, 0.001))
    return simulate(
        sc, config=cfg, seed=4, effects=(fx.Drag(0.3),), thrust_noise=0.02
    ).without_truth()


@pytest.mark.parametrize("kind", ["uniform", "short_last", "jitter"])
@pytest.mark.parametrize("tau", [1e-4, 0.04, 0.6])
def test_lag_scan_matches_the_plant_recursion(kind, tau):
    rng = np.random.default_rng(3)
    n = 3001
    dt = {
        "uniform": np.full(n, 0.004),
        "short_last": np.r_[np.full(n - 1, 0.004), 0.003],
        "jitter": 0.004 + 1e-4 * rng.random(n),
    }[kind]
    f = rng.random((n, 4))
    y, oracle = f[0].copy(), np.empty_like(f)  # the plant's recursion, one step at a time
    for k in range(n):
        y = y + (1.0 - math.exp(-dt[k] / tau)) * (f[k] - y)
        oracle[k] = y
    np.testing.assert_allclose(fx.lag_series(f, dt, tau), oracle, rtol=0, atol=1e-12)


def test_irls_solution_equals_scipy_least_squares():
    rng = np.random.default_rng(0)
    B, p = 400, 3
    phi = rng.normal(size=(B, 6, p))
    base = rng.normal(size=(B, 6))
    x_true = np.array([0.5, -1.0, 2.0])
    meas = base + phi @ x_true + 0.3 * rng.standard_t(2, size=(B, 6))  # heavy tails
    lin = SimpleNamespace(phi=phi, base=base, x0=np.zeros(p))
    scale = np.linspace(0.5, 2.0, 6)
    mask = np.arange(B) % 5 != 0
    lo, hi = np.array([-5.0, -5.0, -5.0]), np.array([5.0, 5.0, 1.5])  # third bound active
    sol = solve_linear(lin, meas, scale, mask, np.zeros(p), lo, hi)

    def fun(x):
        return ((meas - base - phi @ x)[mask] / scale).ravel()

    ref = least_squares(
        fun,
        np.zeros(p),
        bounds=(lo, hi),
        loss="soft_l1",
        f_scale=2.0,
        xtol=1e-14,
        ftol=1e-14,
        gtol=1e-14,
    )
    np.testing.assert_allclose(sol.x, ref.x, atol=2e-6)
    assert sol.x[2] == pytest.approx(1.5)
    np.testing.assert_allclose(sol.fun, fun(sol.x), atol=1e-12)


def test_affine_effects_use_a_verified_linear_model(drag_recording):
    rp = prepare(drag_recording)
    lib = {c.name: c for c in build_library(rp)}
    scale = noise_scale(rp, rp.measured - predict(rp, []))
    lin = linearisation(rp, [lib["drag"], lib["wind"]], [], np.zeros(6), scale)
    assert lin is not None and lin.exact
    x = np.array([0.2, 0.3, 0.1, 0.05, -0.02, 0.01])
    exact = predict(rp, [(lib["drag"], x[:3]), (lib["wind"], x[3:])])
    np.testing.assert_allclose(lin.at(x), exact, atol=1e-9 * np.max(np.abs(exact)))
    # not affine: thrust gain times CoM offset, or a lag
    assert (
        linearisation(
            rp, [lib["motor_efficiency"], lib["com_offset"]], [], np.r_[np.ones(4), 0.0, 0.0], scale
        )
        is None
    )
    assert linearisation(rp, [lib["motor_lag"]], [], [0.05], scale) is None
    # a non-affine model fails the verification even if declared affine
    probe = Linearisation(rp, [lib["motor_lag"]], [], np.array([0.05]), exact=True, scale=scale)
    assert not probe.exact
    # the drag fit recovers the simulated coefficient through the surrogate
    f = fit(rp, [lib["drag"]], scale)
    np.testing.assert_allclose(f.x[0][:2], 0.3, rtol=0.1)


def test_calibration_segment_is_fitted_on_but_not_scored(drag_recording):
    plain = Diagnosis().fit(drag_recording)
    rec = dataclasses.replace(drag_recording, meta={"calibration": {"segment": [0.0, 2.0]}})
    res = Diagnosis().fit(rec)
    sc = res.scoring
    cal = [e for e in sc["excluded"] if "calibration" in e["reason"]]
    assert [[e["t0"], e["t1"]] for e in cal] == [[0.0, 2.0]]
    assert sc["excluded_fraction"] == pytest.approx(2.0 / drag_recording.duration, rel=1e-6)
    assert sc["blocks"] == plain.scoring["blocks"]
    assert sc["scored_blocks"] < sc["blocks"] and sc["scored_blocks"] == pytest.approx(
        sc["blocks"] * 4 / 6, abs=3
    )
    assert res.effect_names[:1] == ["drag"]
    assert res.baseline_rmse != plain.baseline_rmse  # scored on other blocks
    doc = json.loads(res.to_json())
    assert doc["scoring"]["excluded"][0]["t0"] == 0.0


@pytest.mark.parametrize("segment", [[3.0, 1.0], "0-2", [0.0, math.inf]])
def test_malformed_calibration_segment_is_a_clear_error(drag_recording, segment):
    rec = dataclasses.replace(drag_recording, meta={"calibration": {"segment": segment}})
    with pytest.raises(RecordingError, match="calibration"):
        Diagnosis().fit(rec)


@pytest.mark.slow
def test_heavy_vehicle_thrust_noise_inertia_bias_is_caught_by_the_iv_check():
    """Closed loop, 1.2 kg, thrust noise 0.045, no effect: least squares puts the inertia scale
    at ~1.4 (feedback bias); the IV slope of that fit is ~0 and the diagnosis stays
    consistent."""
    m, d = 1.222, 0.2 * 1.222 ** (1 / 3)
    veh = Vehicle.from_rotors(
        [(d, d), (d, -d), (-d, -d), (-d, d)],
        PAPER_YAW_SIGNS,
        0.045 * d,
        mass=m,
        inertia=(0.32 * m * d * d, 0.32 * m * d * d, 0.58 * m * d * d),
        gravity=9.81,
        thrust_to_weight=2.3,
    )
    sc = named_scenario("nominal", 12.0, 4e-3).replace(
        trajectory=Lissajous(amplitude=(1.6, 1.1, 0.2), frequency=0.18)
    )
    cfg = SimConfig(dt=4e-3, sensor_noise=SensorNoise(0.002, 0.005, 0.001, 0.001))
    rec = simulate(sc, vehicle=veh, config=cfg, seed=0, thrust_noise=0.045).without_truth()
    rp = prepare(rec)
    inertia = next(c for c in build_library(rp) if c.name == "inertia")
    base = predict(rp, [])
    scale = noise_scale(rp, rp.measured - base)
    f = fit(rp, [inertia], scale)
    assert np.all(f.x[0][:2] > 1.2)  # the bias is real and large
    sig = (predict(rp, f.terms) - base) / scale
    assert sig.any()
    slope, se = iv_slope(
        rp, [], f.terms, scale, (rp.measured - base) / scale, rp.channel_index("alpha")
    )
    assert slope + 2 * se < 0.5
    res = Diagnosis().fit(rec)
    assert "inertia" not in res.effect_names
    assert res.verdict == "consistent"


@pytest.mark.parametrize("n,window", [(600, 25), (31, 31), (300, 5)])
def test_numpy_savgol_matches_scipy(n, window):
    from scipy.signal import savgol_coeffs as ref_coeffs
    from scipy.signal import savgol_filter as ref_filter

    from quadfault.diagnosis.locate import savgol_coeffs, savgol_filter

    z = np.random.default_rng(n).normal(size=(n, 6)).cumsum(axis=0)
    np.testing.assert_allclose(
        savgol_filter(z, window), ref_filter(z, window, 2, axis=0, mode="interp"), atol=1e-10
    )
    np.testing.assert_allclose(savgol_coeffs(window), ref_coeffs(window, 2), atol=1e-14)
