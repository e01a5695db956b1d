"""Physics of the effects: invariants of each pure function, and one model for the plant and
the diagnosis (the library with the true parameters reproduces a simulated flight)."""

import numpy as np
import pytest

from quadfault.diagnosis.library import build_library, predict
from quadfault.diagnosis.residuals import prepare
from quadfault.model import effects as fx
from quadfault.model.dynamics import RigidBodyState
from quadfault.model.effects.candidate import PublicContext
from quadfault.model.rotation import euler_zyx_to_rot
from quadfault.model.scenarios import LinearVoltage, named_scenario
from quadfault.model.trajectory import Lissajous
from quadfault.model.vehicle import Vehicle
from quadfault.sim.simulator import SimConfig, simulate


@pytest.mark.parametrize(
    "curve", [(0.01, 0.5, 0.3), (0.0, 0.0, 2e-5), (0.2, 1.5, 0.0), (0.0, 1.2, -0.05)]
)
def test_curve_command_inverts_the_curve(curve):
    u = np.linspace(0.05, 3.0, 50)
    f = fx.curve_thrust(curve, u)
    np.testing.assert_allclose(fx.curve_command(curve, f), u, rtol=1e-9)
    assert fx.curve_command(curve, curve[0] - 1.0) == 0.0  # below the curve: no command


def test_curve_from_changes_is_relative_to_hover():
    nominal, fh = (0.0, 0.0, 1e-5), 2.45
    uh = fx.curve_command(nominal, fh)
    np.testing.assert_allclose(fx.curve_from_changes(nominal, fh, (0, 0, 0)), nominal)
    c = fx.curve_from_changes(nominal, fh, (0.1, -0.2, 0.3))
    assert fx.curve_thrust(c, uh) == pytest.approx(1.1 * fh)
    # slope change d1: d(f' - f)/dx at x = 1 is f_h d1; curvature: second derivative 2 f_h d2
    x = np.array([0.999, 1.0, 1.001])
    df = fx.curve_thrust(c, x * uh) - fx.curve_thrust(nominal, x * uh)
    assert (df[2] - df[0]) / 0.002 == pytest.approx(-0.2 * fh, rel=1e-6)
    assert (df[2] - 2 * df[1] + df[0]) / 1e-6 == pytest.approx(2 * 0.3 * fh, rel=1e-4)
    # the identity nominal: f' = f for no change, and the recurve never goes negative
    np.testing.assert_allclose(fx.recurve([0.0, 1.0, 2.0], (0, 1, 0), (0, 1, 0)), [0, 1, 2])
    assert np.all(fx.recurve(np.linspace(0, 3, 20), (0, 1, 0), (-1.0, 1.0, 0.0)) >= 0)


def test_blade_flapping_opposes_inplane_airspeed_and_pitches_up_forward():
    rng = np.random.default_rng(0)
    R = euler_zyx_to_rot(*(rng.uniform(-0.6, 0.6, 30) for _ in range(3)))
    v, T = rng.normal(size=(30, 3)), rng.uniform(1, 20, 30)
    F, M = fx.blade_flapping_wrench(R, v, T, 0.05, 0.004)
    Fb = np.einsum("nji,nj->ni", R, F)
    vb = np.einsum("nji,nj->ni", R, v)
    np.testing.assert_allclose(Fb[:, 2], 0.0, atol=1e-12)  # in the rotor plane only
    np.testing.assert_allclose(Fb[:, :2], -0.05 * T[:, None] * vb[:, :2])
    np.testing.assert_allclose(M, 0.004 * T[:, None] * np.c_[-vb[:, 1], vb[:, 0], 0 * T])
    # level, flying forward (+x body, FRD): nose-up pitch moment (+My)
    _, M1 = fx.blade_flapping_wrench(np.eye(3), np.array([2.0, 0, 0]), 10.0, 0.05, 0.004)
    assert M1[1] > 0 and M1[0] == 0


def test_rate_damping_removes_rotational_energy():
    rng = np.random.default_rng(1)
    w = rng.normal(scale=3, size=(100, 3))
    M = fx.rate_damping_moment(w, (0.01, 0.02, 0.03), (0.001, 0.002, 0.0))
    assert np.all(np.einsum("ij,ij->i", M, w) <= 0)
    np.testing.assert_allclose(
        fx.rate_damping_moment(-w, (0.01, 0.02, 0.03), (0.001, 0.002, 0.0)), -M
    )


def test_battery_factor_is_one_at_the_reference_and_a_power_law():
    assert fx.battery_factor(11.5, 11.5, 2.0) == pytest.approx(1.0)
    assert fx.battery_factor(11.0, 12.0, 2.0) == pytest.approx((11.0 / 12.0) ** 2)


@pytest.mark.slow
def test_rotor_inertia_hook_gives_kappa_times_the_thrust_step_over_the_step():
    """Through the plant protocol: the yaw moment over a physics step is
    ``kappa sum_i s_i df_i / dt`` for the step of produced thrust, the same at every
    integrator stage of the step, zero when the thrust holds; the signs come from the flown
    vehicle's allocation."""
    veh = Vehicle()
    e = fx.RotorInertia(0.004)
    e.reset(4)
    assert e.true_vehicle(veh) is veh
    s = RigidBodyState.at_rest()
    dt = 1e-3
    f0 = np.full(4, veh.hover_thrust)
    f1 = f0 + np.array([0.2, 0.0, 0.3, 0.0])
    e.rotor_thrust(f0, 0.0, dt, s)
    np.testing.assert_allclose(e.wrench(s, f0, 0.0)[1], 0.0)  # no step before the first
    e.rotor_thrust(f1, dt, dt, s)
    want = 0.004 * (np.sign(veh.allocation[3]) @ (f1 - f0)) / dt
    for _ in range(4):  # every RK stage of the step
        F, M = e.wrench(s, f1, dt)
        np.testing.assert_allclose(F, 0.0)
        np.testing.assert_allclose(M, [0.0, 0.0, want])
    e.rotor_thrust(f1, 2 * dt, dt, s)
    np.testing.assert_allclose(e.wrench(s, f1, 2 * dt)[1], 0.0)
    assert want < 0  # rotors 1 and 3 carry yaw sign -1 in the paper's layout


def test_rotor_inertia_gyroscopic_moment_is_minus_w_cross_the_rotors_momentum():
    """With ``momentum`` the spinning rotors carry ``h = -sum_i s_i momentum sqrt(f_i)``
    along body z: nil for a healthy hover (the momenta cancel), and the moment ``-w x h``
    at every stage -- perpendicular to w and to z, so it does no work and no yaw."""
    veh = Vehicle()
    e = fx.RotorInertia(0.0, momentum=0.02)
    e.reset(4)
    e.true_vehicle(veh)
    w = np.array([0.7, -1.3, 9.0])
    s = RigidBodyState.at_rest()._replace(w=w)
    f_hover = np.full(4, veh.hover_thrust)
    e.rotor_thrust(f_hover, 0.0, 1e-3, s)
    np.testing.assert_allclose(e.wrench(s, f_hover, 0.0)[1], 0.0, atol=1e-15)
    f = np.array([0.0, 3.0, 1.0, 3.0])  # rotor 1 stopped
    e.rotor_thrust(f, 1e-3, 1e-3, s)
    e.rotor_thrust(f, 2e-3, 1e-3, s)  # hold: no speed-change reaction
    h = -0.02 * (np.sign(veh.allocation[3]) @ np.sqrt(f))
    assert h == pytest.approx(float(fx.rotor_momentum(f, np.sign(veh.allocation[3]), 0.02)))
    M = e.wrench(s, f, 2e-3)[1]
    np.testing.assert_allclose(M, -np.cross(w, [0.0, 0.0, h]), rtol=1e-12)
    assert M @ w == pytest.approx(0.0, abs=1e-12) and M[2] == 0.0


def test_thrust_rate_telescopes_over_blocks():
    rng = np.random.default_rng(2)
    f, dt = rng.normal(size=(50, 4)), rng.uniform(1e-3, 3e-3, 50)
    rate = fx.thrust_rate(f, dt)
    np.testing.assert_allclose(np.sum(rate[10:20] * dt[10:20, None], axis=0), f[19] - f[9])


TRAJ = Lissajous(amplitude=(2.0, 1.5, 0.3), frequency=0.2, yaw_rate=0.3)
LOW = Lissajous(amplitude=(1.0, 1.0, 0.15), frequency=0.15, altitude=0.35)
ONE_MODEL = [
    fx.MotorEfficiency((1, 0.8, 1, 1)),
    fx.ThrustScale(0.9),
    fx.Drag((0.3, 0.2, 0.4)),
    fx.MotorLag(0.05),
    fx.Delay(0.013),
    fx.Wind((2.0, -1.0, 0.0), k=(0.3,) * 3),
    fx.GroundEffect(0.3),
    fx.ComOffset((0.01, -0.02)),
    fx.Inertia((1.3, 0.8, 1.2)),
    fx.BladeFlapping(0.05, 0.005),
    fx.RotorInertia(0.005),
    fx.BatteryThrust(2.0, 12.0, 11.0, 3.0),
    fx.ThrustCurve((0.3, 0.8, 0.03)),
    fx.Mass(1.15),
    fx.RateDamping((0.07, 0.05, 0.1), (0.01, 0.01, 0.02)),
]


@pytest.mark.slow
@pytest.mark.parametrize("effect", ONE_MODEL, ids=[e.name for e in ONE_MODEL])
def test_library_with_the_true_parameters_reproduces_the_plant(effect):
    """Noise-free flight with one effect: the diagnosis' model of that effect at its true
    parameters (``Candidate.x_from_params``) removes > 99 % of the nominal model's residual in
    every channel the effect acts on (98 % in the accelerometer's) -- the plant and the library run the same physics."""
    traj = LOW if effect.name == "ground_effect" else TRAJ
    volt = LinearVoltage(12.0, 11.0, 3.0) if effect.name == "battery_thrust" else None
    sc = named_scenario("nominal", 3.0, 4e-3).replace(trajectory=traj, voltage=volt)
    rec = simulate(
        sc, config=SimConfig(dt=4e-3), seed=0, effects=(effect,), thrust_noise=0.0
    ).without_truth()
    rp = prepare(rec)
    cand = next(c for c in build_library(rp, fx.EFFECT_NAMES) if c.name == effect.name)
    x = cand.x_from_params(effect.params())
    before = np.sqrt(np.mean((rp.measured - predict(rp, [])) ** 2, axis=0))
    after = np.sqrt(np.mean((rp.measured - predict(rp, [(cand, x)])) ** 2, axis=0))
    acting = before > max(1e-3, 1e-3 * before.max())
    assert acting.any()
    # the accelerometer samples the state at a step's start, the model the interval's
    # midpoint: state-dependent forces differ by O(dt / 2) there
    tol = np.array([0.02 if c.startswith("sf") else 0.01 for c in rp.channels])
    assert np.all(after[acting] < tol[acting] * before[acting]), after / before


def test_every_candidate_reports_bounds_in_its_public_keys():
    sc = named_scenario("nominal", 1.0, 4e-3).replace(
        trajectory=TRAJ, voltage=LinearVoltage(12.0, 11.0, 1.0)
    )
    rec = simulate(sc, config=SimConfig(dt=4e-3), seed=0, thrust_noise=0.0).without_truth()
    rp = prepare(rec)
    lib = build_library(rp, fx.EFFECT_NAMES)
    assert {c.name for c in lib} == set(fx.EFFECT_NAMES)
    for c in lib:
        x = np.asarray(c.x0, dtype=float)
        params, _ = c.public(x, np.zeros(c.size), PublicContext(rp.vehicle, {}))
        bounds = c.public_bounds()
        assert set(bounds) <= set(params), c.name
        for key, (lo, hi) in bounds.items():
            assert np.all(np.asarray(lo) <= np.asarray(params[key]) + 1e-12), (c.name, key)
            assert np.all(np.asarray(params[key]) <= np.asarray(hi) + 1e-12), (c.name, key)
        np.testing.assert_allclose(c.x_from_params(params), x, atol=1e-12, err_msg=c.name)
    bounds = {c.name: c.public_bounds() for c in lib}
    assert bounds["motor_lag"] == {"tau_s": [1e-4, 0.3]}
    assert bounds["inertia"] == {"scale": [0.5, 2.0]}
    m, g = rp.vehicle.mass, rp.vehicle.gravity
    assert bounds["wind"]["force_N"][1] == pytest.approx([0.5 * m * g] * 2 + [0.25 * m * g])
