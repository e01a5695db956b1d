"""Effect models (quadfault.model.effects): physics invariants, one model for plant and diagnosis."""

import numpy as np
import pytest

from quadfault.errors import ConfigError
from quadfault.model import effects as fx
from quadfault.model.dynamics import RigidBodyState
from quadfault.model.rotation import cross, euler_zyx_to_rot
from quadfault.model.vehicle import Vehicle


def _state(rng, n=()):
    R = euler_zyx_to_rot(*(rng.uniform(-0.5, 0.5, size=n) for _ in range(3)))
    return RigidBodyState(
        rng.normal(size=n + (3,)), rng.normal(size=n + (3,)), R, rng.normal(size=n + (3,))
    )


@pytest.mark.parametrize(
    "spec, cls, attr, value",
    [
        ("drag=0.3", fx.Drag, "k", (0.3, 0.3, 0.3)),
        ("drag=0.1,0.2,0.3", fx.Drag, "k", (0.1, 0.2, 0.3)),
        ("wind=2,0,0,gust=0.5", fx.Wind, "velocity", (2.0, 0.0, 0.0)),
        ("motor_lag=0.05", fx.MotorLag, "tau", 0.05),
        ("delay=0.02", fx.Delay, "delay", 0.02),
        ("motor_efficiency=1,1,0.7,1", fx.MotorEfficiency, "eta", (1.0, 1.0, 0.7, 1.0)),
        ("thrust_scale=0.9", fx.ThrustScale, "scale", 0.9),
        ("ground_effect=0.12", fx.GroundEffect, "rotor_radius", 0.12),
        ("com_offset=0.01,-0.02", fx.ComOffset, "offset", (0.01, -0.02)),
        ("inertia=1.2", fx.Inertia, "scale", (1.2, 1.2, 1.2)),
        ("blade_flapping=0.05,0.002", fx.BladeFlapping, "k_moment", 0.002),
        ("blade_flapping=0.05", fx.BladeFlapping, "k_moment", 0.0),
        ("rotor_inertia=0.004", fx.RotorInertia, "kappa", 0.004),
        ("battery_thrust=2,v_start=4.2,v_end=3.6", fx.BatteryThrust, "v_ref", 3.9),
        ("thrust_curve=0.1,0.9,0.02", fx.ThrustCurve, "curve", (0.1, 0.9, 0.02)),
        ("mass=1.15", fx.Mass, "scale", 1.15),
        ("rate_damping=0.01", fx.RateDamping, "linear", (0.01, 0.01, 0.01)),
        ("rate_damping=0.01,0.002", fx.RateDamping, "quadratic", (0.002, 0.002, 0.002)),
        ("rate_damping=1,2,3,4,5,6", fx.RateDamping, "quadratic", (4.0, 5.0, 6.0)),
    ],
)
def test_parse_effect(spec, cls, attr, value):
    e = fx.parse_effect(spec)
    assert isinstance(e, cls)
    assert getattr(e, attr) == pytest.approx(value)
    d = e.describe()
    assert d["name"] == spec.split("=")[0] and isinstance(d["params"], dict)


@pytest.mark.parametrize(
    "spec, words",
    [
        ("nothing=1", "unknown effect"),
        ("drag", "NAME=VALUES"),
        ("drag=1,2", "expects 1 or 3"),
        ("wind=1,0,0,color=3", "unknown option"),
        ("delay=-1", "delay"),
        ("drag=x", "not a number"),
        ("motor_lag=0", "tau"),
        ("drag=nan", "finite"),
        ("rate_damping=1,2,3,4", "expects 1 or 2 or 3 or 6"),
        ("mass=0", "mass scale"),
        ("thrust_curve=0,0,0", "b > 0 or c > 0"),
        ("rate_damping=-1", ">= 0"),
        ("battery_thrust=2,v_start=-1", "v_start"),
        ("drag=0.1:0.3", "random generator"),
        ("blade_flapping=x", "not a number"),
    ],
)
def test_parse_effect_errors(spec, words):
    with pytest.raises(ConfigError, match=words):
        fx.parse_effect(spec)


def test_parse_effect_ranges_are_drawn_from_the_generator():
    a = fx.parse_effect("motor_lag=0.02:0.06", rng=np.random.default_rng(5))
    b = fx.parse_effect("motor_lag=0.02:0.06", rng=np.random.default_rng(5))
    assert a == b and 0.02 <= a.tau <= 0.06
    with pytest.raises(ConfigError, match="low <= high"):
        fx.parse_effect("motor_lag=0.06:0.02", rng=np.random.default_rng(5))


def test_every_effect_round_trips_through_its_params():
    rng = np.random.default_rng(6)
    for name in fx.EFFECT_NAMES:
        spec = {
            "wind": "wind=1,2,0",
            "com_offset": "com_offset=0.01,0.02",
            "thrust_curve": "thrust_curve=0.1,0.9,0.02",
            "blade_flapping": "blade_flapping=0.05,0.002",
        }.get(name, f"{name}=0.5:0.9")
        e = fx.parse_effect(spec, rng=rng)
        again = fx.EFFECTS[name].from_params(e.params())
        if name == "wind":  # the diagnosis' model: the steady force
            np.testing.assert_allclose(again.steady_force(), e.steady_force())
            continue
        for key, value in e.params().items():
            np.testing.assert_allclose(again.params()[key], value, err_msg=f"{name}.{key}")


def test_drag_opposes_air_velocity_and_is_linear():
    rng = np.random.default_rng(0)
    s = _state(rng, (50,))
    F = fx.drag_force(s.R, s.v, (0.2, 0.3, 0.5))
    assert np.all(np.einsum("ij,ij->i", F, s.v) <= 1e-12)
    F2 = fx.drag_force(s.R, 2 * s.v, (0.2, 0.3, 0.5))
    np.testing.assert_allclose(F2, 2 * F)
    # isotropic drag does not depend on attitude
    np.testing.assert_allclose(fx.drag_force(s.R, s.v, 0.4), -0.4 * s.v, atol=1e-12)


def test_ground_effect_factor_limits():
    assert fx.ground_effect_factor(100.0, 0.1) == pytest.approx(1.0, abs=1e-6)
    assert fx.ground_effect_factor(0.0, 0.1) == pytest.approx(4.0 / 3.0)
    h = np.linspace(0.05, 2, 50)
    k = fx.ground_effect_factor(h, 0.1)
    assert np.all(np.diff(k) <= 0)  # monotone: more thrust closer to the ground


def test_zoh_mean_matches_numerical_integration():
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.5e-3, 2e-3, 200))
    f = rng.uniform(0, 1, (200, 4))
    c = fx.zoh_cumulative(t, f)
    a, b = t[50] - 0.0123, t[51] - 0.0123
    fine = np.linspace(a, b, 20001)
    j = np.searchsorted(t, fine, side="right") - 1
    num = f[j].mean(axis=0)
    np.testing.assert_allclose(
        fx.zoh_mean(t, f, c, np.array([a]), np.array([b]))[0], num, atol=2e-3
    )


def test_lag_series_steps_equal_one_series_and_reach_a_held_command():
    rng = np.random.default_rng(2)
    f = rng.uniform(0, 2, (300, 4))
    dt = rng.uniform(0.5e-3, 2e-3, 300)
    whole = fx.lag_series(f, dt, 0.03)
    y, steps = None, []
    for k in range(300):  # the plant's call: one row, continuing from the previous thrust
        y = fx.lag_series(f[k], dt[k], 0.03, y)[0]
        steps.append(y)
    np.testing.assert_allclose(whole, steps, rtol=1e-12, atol=1e-14)
    held = fx.lag_series(np.ones((2000, 4)) * 3.0, np.full(2000, 1e-3), 0.05)
    assert held[-1] == pytest.approx(3.0 * np.ones(4))


@pytest.mark.parametrize("effect", [fx.MotorLag(0.04), fx.Delay(0.0123)])
def test_plant_step_equals_series_model(effect):
    """The plant's per-step effect and the diagnosis' series function are the same model."""
    from quadfault.diagnosis.library import Candidate

    rng = np.random.default_rng(3)
    dt = 2e-3
    t = dt * np.arange(400)
    f = rng.uniform(0, 2, (400, 4))
    effect.reset(4)
    s = RigidBodyState.at_rest()
    stepped = np.array([effect.rotor_thrust(f[k], t[k], dt, s) for k in range(400)])
    if isinstance(effect, fx.MotorLag):
        series = fx.lag_series(f, np.full(400, dt), effect.tau)
    else:
        c = fx.zoh_cumulative(t, f)
        series = fx.zoh_mean(t, f, c, t - effect.delay, t + dt - effect.delay)
    np.testing.assert_allclose(stepped, series, rtol=1e-9, atol=1e-12)
    assert Candidate  # the library uses these same functions


def test_body_effects_change_the_flown_vehicle_only():
    from quadfault.model.plant import Plant

    veh = Vehicle()
    plant = Plant(veh, effects=(fx.Inertia((1.3, 0.8, 1.1)), fx.Mass(1.2)))
    plant.reset(RigidBodyState.at_rest())
    np.testing.assert_allclose(
        np.diag(plant.vehicle.inertia), np.diag(veh.inertia) * (1.3, 0.8, 1.1)
    )
    assert plant.vehicle.mass == pytest.approx(1.2 * veh.mass)
    assert plant.vehicle.rotor_max_thrust == veh.rotor_max_thrust  # the rotors are unchanged
    assert plant.nominal_vehicle is veh and veh.mass == 1.0


def test_com_offset_moment_is_r_cross_thrust():
    r = np.array([0.01, -0.03, 0.0])
    M = fx.com_offset_moment(5.0, r[:2])
    np.testing.assert_allclose(M, cross(r, np.array([0.0, 0.0, 5.0])))


@pytest.mark.slow
def test_wind_gusts_are_seeded_and_steady_mean():
    w = fx.Wind((2.0, 0.0, 0.0), gust=0.5, gust_tau=0.5, seed=3)
    s = RigidBodyState.at_rest()

    def run():
        w.reset(4)
        out = []
        for k in range(3000):
            w.rotor_thrust(np.ones(4), k * 1e-2, 1e-2, s)
            out.append(w.air_velocity().copy())
        return np.array(out)

    a, b = run(), run()
    np.testing.assert_array_equal(a, b)
    assert abs(a[:, 0].mean() - 2.0) < 0.15 and 0.3 < a[:, 0].std() < 0.7
    F, M = w.wrench(s, np.ones(4), 0.0)
    assert F.shape == (3,) and np.allclose(M, 0)


def test_simulated_effects_are_truth_and_stripped():
    from quadfault.model.scenarios import named_scenario
    from quadfault.sim.simulator import SimConfig, simulate

    sc = named_scenario("hover", 0.2, 4e-3)
    rec = simulate(sc, config=SimConfig(dt=4e-3), effects=(fx.parse_effect("drag=0.2"),))
    assert rec.meta["effects"] == [fx.parse_effect("drag=0.2").describe()]
    assert "effects" not in rec.without_truth().meta
