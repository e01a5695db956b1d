"""Flying on three rotors: the detector that switches, the relaxed-hover controller, and the
fallback controller with an estimator in the loop."""

import numpy as np
import pytest

from agents.rollout import fly
from quadfault.errors import ConfigError
from quadfault.model.dynamics import RigidBodyState
from quadfault.model.effects import parse_effect
from quadfault.model.flight import Flight
from quadfault.model.plant import Plant
from quadfault.model.relaxed_hover import (
    ROTOR_LOSS_EFFECTS,
    SpinPhysics,
    hover_state,
    rotor_loss_vehicle,
)
from quadfault.model.relaxed_hover_control import (
    RelaxedHoverController,
    RotorLossDetector,
    RotorLossSwitch,
)
from quadfault.model.scenarios import AbruptFault, ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.model.trajectory import Hover

VEHICLE = rotor_loss_vehicle()


def test_detector_isolates_one_rotor_holds_and_latches():
    sw = RotorLossSwitch(RotorLossDetector(threshold=0.15, others=0.5, hold=0.002))
    assert sw.update([1.0, 0.3, 1.0, 1.0], 0.0) == -1  # a partial loss: no switch
    assert sw.update([0.1, 0.1, 1.0, 1.0], 0.001) == -1  # two low: not isolated
    assert sw.update([1.0, 1.0, 0.05, 1.0], 0.002) == -1
    assert sw.update([1.0, 1.0, 0.05, 1.0], 0.003) == -1
    assert sw.update([1.0, 1.0, 0.04, 0.9], 0.004) == 2
    assert (sw.first_seen, sw.switched) == (0.002, 0.004)
    assert sw.update([1.0, 1.0, 1.0, 1.0], 0.005) == 2  # latched
    assert RotorLossSwitch().update([np.nan, 0.0, 1.0, 1.0], 0.0) == -1
    with pytest.raises(ConfigError, match="threshold"):
        RotorLossDetector(threshold=0.6, others=0.5)


def test_relaxed_hover_controller_brings_the_spinning_vehicle_back_to_its_point():
    """From the relaxed hover displaced by 0.3 m, the controller (at 1 kHz, the named
    vehicle's physics) returns to within 5 cm in 4 s, the lost rotor commanded 0."""
    lost = 1
    ctrl = RelaxedHoverController(VEHICLE, lost, SpinPhysics.of(ROTOR_LOSS_EFFECTS), 1e-3)
    p, v, R, w = hover_state(VEHICLE, ctrl.hover)
    plant = Plant(VEHICLE, effects=tuple(parse_effect(s) for s in ROTOR_LOSS_EFFECTS))
    plant.reset(RigidBodyState(p + np.array([0.3, 0.0, 0.0]), v, R, w))
    flight = Flight(plant, record_accel=False)
    flight.reset(np.random.default_rng(0))
    eta = np.ones(4)
    eta[lost] = 0.0
    flight.plan(4000, lambda t: eta)
    target = np.array([0.0, 0.0, -1.0])
    for _ in range(4000):
        s = flight.state()
        f = ctrl.command(s.p, s.v, s.R, s.w, target)
        assert f[lost] == 0.0 and np.all(f <= VEHICLE.rotor_max_thrust)
        flight.step(f, 1)
    assert np.linalg.norm(flight.state().p - target) < 0.1


def test_fallback_switches_on_the_estimate_and_survives_a_complete_loss():
    """Rotor 3 stops at 2 s: the oracle's estimate isolates it at once, the switch follows
    after the detector's hold, and the vehicle survives the 6 s flight."""
    fault = AbruptFault(motor=3, onset=2.0, level=0.0)
    sc = Scenario("loss", 6.0, EfficiencySchedule(ConstantEfficiency(), (fault,)), Hover())
    f = fly(sc, "relaxed-hover", "truth", 0, vehicle=VEHICLE, effects=ROTOR_LOSS_EFFECTS)
    assert not f.metrics.crashed
    assert f.switch["rotor"] == 2
    assert 2.0 <= f.switch["switched"] <= 2.01
    assert f.modes.get("relaxed-hover", 0) > 3000
    assert np.all(f.f_cmd[f.t > 2.1, 2] == 0.0)  # the lost rotor is not asked for thrust


def test_complete_loss_task_flies_the_named_vehicle_with_the_relaxed_hover_base():
    """The registered id: the complete-loss vehicle, level 0, the relaxed-hover base; its
    zero-action episode with the oracle's estimate switches after the onset and survives."""
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env

    import quad_fault_env  # noqa: F401

    env = gym.make("QuadFaultRotorLossComplete-v0", estimator="truth")
    u = env.unwrapped
    assert u.vehicle.thrust_to_weight == 2.75 and u.allocation == "relaxed-hover"
    check_env(u, skip_render_check=True)
    env.reset(seed=0)
    fault = u.scenario.efficiency.faults[0]
    assert fault.level == 0.0 and 3.0 <= fault.onset <= 6.0
    done = False
    while not done:
        _, _, term, trunc, _ = env.step(np.zeros(4))
        done = term or trunc
    assert not term
    sw = u.relaxed.switches[0]
    assert sw.lost == fault.motor - 1 and fault.onset <= sw.switched <= fault.onset + 0.03
    with pytest.raises(ConfigError, match="residual"):
        gym.make("QuadFaultRotorLossComplete-v0", action_mode="wrench")


def test_held_after_loss_counts_the_late_error_and_the_flights_end():
    from agents.metrics import held_after_loss

    t = np.arange(0.0, 10.0, 0.01)
    e = np.where(t < 4.5, 1.5, 0.3)  # 1.5 m until 1.5 s after a loss at 3 s
    assert held_after_loss(t, e, 3.0, 10.0)
    assert not held_after_loss(t, e, 2.0, 10.0)  # still 1.5 m at 2 s after the loss
    assert not held_after_loss(t[:600], e[:600], 3.0, 10.0)  # ended (crashed) at 6 s


def test_the_switch_holds_longer_with_noisy_sensors():
    """A noisy estimate dips below the threshold for milliseconds before any loss: the
    default detector of noisy sensors waits NOISY_HOLD, noise-free sensors keep the fast
    default; the env and fly() choose it from the sensors they fly."""
    import gymnasium as gym

    import quad_fault_env  # noqa: F401
    from quadfault.model.relaxed_hover_control import NOISY_HOLD
    from quadfault.model.sensor_presets import as_sensor_noise
    from quadfault.model.sensors import SensorNoise

    quiet = RotorLossDetector.for_sensors(SensorNoise())
    assert quiet == RotorLossDetector() and quiet.hold < NOISY_HOLD
    assert RotorLossDetector.for_sensors(as_sensor_noise("px4")).hold == NOISY_HOLD
    assert RotorLossDetector.for_sensors(SensorNoise(0.01, 0, 0, 0)).hold == NOISY_HOLD
    env = gym.make("QuadFaultRotorLossComplete-v0", sensor_noise="crazyflie")
    assert env.unwrapped.relaxed.detector.hold == NOISY_HOLD
    assert gym.make("QuadFaultRotorLossComplete-v0").unwrapped.relaxed.detector == quiet
