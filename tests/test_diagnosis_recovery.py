"""Diagnosis recovers each library effect from a seeded simulated recording.

Short flights (8 s at 250 Hz, Lissajous, sensor and thrust noise) keep the suite fast; the
slower cases carry the ``slow`` marker.
"""

import numpy as np
import pytest

from quadfault.diagnosis import Diagnosis
from quadfault.diagnosis.library import EQUIVALENT
from quadfault.model import effects as fx
from quadfault.model.scenarios import named_scenario
from quadfault.model.trajectory import Lissajous
from quadfault.sim.simulator import SensorNoise, SimConfig, simulate

DT = 4e-3
FAST_TRAJ = Lissajous(amplitude=(2.0, 1.5, 0.3), frequency=0.15)
LOW_TRAJ = Lissajous(amplitude=(1.0, 1.0, 0.15), frequency=0.15, altitude=0.35)


def fly(effects=(), seed=1, duration=8.0, traj=FAST_TRAJ):
    sc = named_scenario("nominal", duration, DT).replace(trajectory=traj)
    cfg = SimConfig(dt=DT, sensor_noise=SensorNoise(0.002, 0.005, 0.001, 0.001))
    return simulate(sc, config=cfg, seed=seed, effects=tuple(effects), thrust_noise=0.02)


_CACHE = {}


def diagnose(key, effects, **kw):
    if key not in _CACHE:
        rec = fly(effects, **kw)
        _CACHE[key] = Diagnosis().fit(rec.without_truth())
    return _CACHE[key]


def test_effect_free_flight_is_consistent():
    res = diagnose("none", ())
    assert res.verdict == "consistent"
    assert res.effects == ()
    assert res.model_improvement == 0.0
    assert set(res.baseline_rmse) == {
        "acc_x",
        "acc_y",
        "acc_z",
        "sf_x",
        "sf_y",
        "sf_z",
        "alpha_x",
        "alpha_y",
        "alpha_z",
    }


def test_drag_recovered():
    res = diagnose("drag", (fx.Drag((0.3, 0.3, 0.3)),))
    assert res.verdict == "mismatch"
    top = res.effects[0]
    assert top.name == "drag"
    k = np.array(top.params["k_N_s_per_m"])
    np.testing.assert_allclose(k[:2], 0.3, rtol=0.1)
    assert res.model_improvement > 0.1
    p = res.prediction["position_rmse_m"]
    assert p["model"][-1] < 0.5 * p["nominal"][-1]  # held-out open-loop prediction improves


@pytest.mark.slow
def test_two_effects_recovered():
    res = diagnose("eff+drag", (fx.MotorEfficiency((1.0, 0.85, 1.0, 1.0)), fx.Drag(0.3)))
    names = res.effect_names
    assert set(names[:2]) == {"motor_efficiency", "drag"}
    eta = res.effects[names.index("motor_efficiency")].params["eta"]
    np.testing.assert_allclose(eta, [1.0, 0.85, 1.0, 1.0], atol=0.03)
    k = res.effects[names.index("drag")].params["k_N_s_per_m"]
    np.testing.assert_allclose(k[:2], 0.3, rtol=0.1)
    assert res.model_improvement > 0.5


CASES = {
    "motor_lag": ((fx.MotorLag(0.05),), {}, lambda p: abs(p["tau_s"] - 0.05) < 0.0075),
    "delay": ((fx.Delay(0.03),), {}, lambda p: abs(p["delay_s"] - 0.03) < 0.004),
    "motor_efficiency": (
        (fx.MotorEfficiency((1.0, 1.0, 0.8, 1.0)),),
        {},
        lambda p: np.allclose(p["eta"], [1, 1, 0.8, 1], atol=0.03),
    ),
    "thrust_scale": ((fx.ThrustScale(0.9),), {}, lambda p: abs(p["scale"] - 0.9) < 0.02),
    "wind": (
        (fx.Wind((2.0, -1.0, 0.0), k=0.3),),
        {},
        lambda p: np.allclose(p["force_N"][:2], [0.6, -0.3], atol=0.08),
    ),
    "ground_effect": (
        (fx.GroundEffect(0.3),),
        {"traj": LOW_TRAJ},
        lambda p: abs(p["rotor_radius_m"] - 0.3) < 0.045,
    ),
    "com_offset": (
        (fx.ComOffset((0.01, -0.02)),),
        {},
        lambda p: np.allclose(p["offset_m"], [0.01, -0.02], atol=0.002),
    ),
    "inertia": (
        (fx.Inertia((1.6, 1.6, 1.0)),),
        {},
        lambda p: np.allclose(p["scale"][:2], 1.6, rtol=0.25),
    ),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CASES))
def test_each_effect_recovered(name):
    effects, kw, check = CASES[name]
    res = diagnose(name, effects, **kw)
    assert res.verdict == "mismatch"
    top = res.effects[0]
    assert EQUIVALENT.get(top.name, top.name) == EQUIVALENT.get(name, name)
    if top.name == name:
        assert check(top.params), top.params
    assert top.improvement > 0.05
    assert all(0.0 <= e.improvement <= 1.0 for e in res.effects)
