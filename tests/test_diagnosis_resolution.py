"""A motor lag shorter than two command periods is below what the log resolves; another effect
that only takes up part of its signal (an inertia scaled up: the lag attenuates the fast part
of the commanded moments) is not named in its place.

Synthetic flights of a 47 g quadrotor logged at 250 Hz (8 ms resolve a time constant), whose
fast closed-loop moments make a 5 ms lag look like an inertia 1.6-1.7 times nominal when
nothing checks it; a true inertia error on the same vehicle is still found.
"""

import numpy as np
import pytest

from quadfault.diagnosis import Diagnosis, DiagnosisConfig
from quadfault.diagnosis.report_text import markdown
from quadfault.model import effects as fx
from quadfault.model.controller import ControllerConfig
from quadfault.model.scenarios import named_scenario
from quadfault.model.trajectory import Lissajous
from quadfault.model.vehicle import PAPER_YAW_SIGNS, Vehicle
from quadfault.sim.simulator import SensorNoise, SimConfig, simulate

DT = 4e-3  # 250 Hz: two command periods are 8 ms
D, DY = 0.065, 0.07
SMALL = Vehicle.from_rotors(
    [(D, DY), (D, -DY), (-D, -DY), (-D, DY)],
    PAPER_YAW_SIGNS,
    0.0037,
    mass=0.047,
    inertia=(7.8e-5, 1.0e-4, 1.6e-4),
    gravity=9.81,
    thrust_to_weight=2.4,
)
TRAJ = Lissajous(amplitude=(0.58, 0.39, 0.067), frequency=0.146, altitude=1.5, yaw_rate=0.19)


def fly(effect, seed=1):
    sc = named_scenario("nominal", 12.0, DT).replace(trajectory=TRAJ)
    # the plain allocation inverse: these flights' fast yaw moments are part of the signal
    plain = ControllerConfig(yaw_release=False)
    cfg = SimConfig(
        dt=DT, sensor_noise=SensorNoise(0.005, 0.0065, 0.0012, 0.0017), controller=plain
    )
    return simulate(
        sc,
        vehicle=SMALL,
        config=cfg,
        seed=seed,
        effects=() if effect is None else (effect,),
        thrust_noise=0.012,
    ).without_truth()


#: a library without inertia: nothing else takes up the lag's signal
NO_INERTIA = DiagnosisConfig(effects=("motor_lag", "delay", "drag", "mass", "thrust_scale"))


@pytest.fixture(scope="module")
def sub_sample_lag():
    return Diagnosis().fit(fly(fx.MotorLag(0.005)))


def test_a_lag_below_the_resolution_is_not_named_as_inertia(sub_sample_lag):
    res = sub_sample_lag
    assert "inertia" not in res.effect_names
    assert not {"motor_lag", "delay"} & set(res.effect_names)  # below the floor: never named
    rejected = {e.name: e for e in res.rejected}
    assert "shorter than 2 command periods" in rejected["motor_lag"].reason
    assert rejected["inertia"].reason.startswith(
        "indistinguishable in this log from a motor_lag of"
    )
    # both named, neither accepted: the mismatch is there, the log cannot say which
    assert res.verdict == "mismatch"
    pair, lacks = res.indistinguishable
    assert pair["names"] == ["inertia", "motor_lag"]
    assert lacks["names"] == ["motor_lag", "delay"]  # and the lag itself is missing
    assert "8.0 ms" in pair["reason"]
    assert res.to_dict()["indistinguishable"] == [pair, lacks]
    assert "## Indistinguishable in this log" in markdown(res, "flight.csv")
    assert "- **inertia or motor_lag**" in markdown(res, "flight.csv")


def test_a_lag_below_the_resolution_that_explains_the_flight_is_a_mismatch():
    """Nothing else tried: the lag explains most of the held-out residual, the log cannot
    say which time constant it is, and the verdict says the model does not match."""
    res = Diagnosis(NO_INERTIA).fit(fly(fx.MotorLag(0.005)))
    assert res.effect_names == [] and res.suspect == ()
    rejected = {e.name: e for e in res.rejected}
    assert "shorter than 2 command periods" in rejected["motor_lag"].reason  # never named
    assert res.verdict == "mismatch"
    (lacks,) = res.to_dict()["indistinguishable"]
    assert lacks["names"] == ["motor_lag", "delay"]
    fig = lacks["held_out"]
    assert fig["time_constant_s"] == pytest.approx(0.005, rel=0.2)
    assert fig["shortest_time_constant_s"] == pytest.approx(0.008, rel=0.01)
    assert fig["command_rate_hz"] == pytest.approx(250.0, rel=0.01)
    # the bar of every effect, and the held-out gain the rejected lag itself reports
    assert fig["improvement"] >= 0.05 and fig["ci95_low"] > 0.0
    assert fig["improvement"] == pytest.approx(rejected["motor_lag"].improvement, abs=0.02)
    assert fig["best_channel"] >= fig["improvement"]
    for part in (
        "a time constant below the resolution (5.0 ms as a motor_lag",
        "commands at 250 Hz resolve 8.0 ms",
        f"explains {fig['improvement']:.1%}",
        "cannot tell motor_lag from delay or measure it",
    ):
        assert part in lacks["reason"]
    assert "- **motor_lag or delay**" in markdown(res, "flight.csv")


def test_a_healthy_flight_of_the_same_vehicle_stays_consistent():
    res = Diagnosis(NO_INERTIA).fit(fly(None))
    assert res.verdict == "consistent"
    assert res.indistinguishable == () and res.effect_names == []


def test_a_true_inertia_error_on_the_same_vehicle_is_still_found():
    res = Diagnosis().fit(fly(fx.Inertia((1.5, 1.5, 1.2))))
    assert res.effect_names == ["inertia"]
    scale = np.asarray(res.effects[0].params["scale"])
    assert np.allclose(scale, [1.5, 1.5, 1.2], rtol=0.03)
    assert res.indistinguishable == ()


def test_at_1_khz_the_same_lag_is_resolved_and_named():
    """The floor is the log's, not the lag's: commands at 1 kHz resolve 2 ms."""
    sc = named_scenario("nominal", 12.0, 1e-3).replace(trajectory=TRAJ)
    cfg = SimConfig(dt=1e-3, sensor_noise=SensorNoise(0.005, 0.0065, 0.0012, 0.0017))
    rec = simulate(
        sc, vehicle=SMALL, config=cfg, seed=1, effects=(fx.MotorLag(0.005),), thrust_noise=0.012
    ).without_truth()
    res = Diagnosis().fit(rec)
    assert res.effect_names[:1] == ["motor_lag"]
    assert res.effects[0].params["tau_s"] == pytest.approx(0.005, rel=0.1)


def test_only_the_best_time_constant_decides_whether_one_is_unresolved():
    """The check applies when the best timing fit (by BIC) is below the floor; a worse timing
    fit below the floor beside a resolvable best one does not make it apply."""
    from types import SimpleNamespace

    from quadfault.diagnosis.identifiability import evidence, gate
    from quadfault.diagnosis.library import build_library
    from quadfault.diagnosis.residuals import prepare
    from quadfault.diagnosis.resolution import unresolved

    rec = fly(fx.MotorLag(0.005))
    lib, _ = gate(build_library(prepare(rec), ("motor_lag", "delay", "inertia")), evidence(rec))
    c = {x.name: x for x in lib}
    assert c["motor_lag"].resolvable == pytest.approx(0.008, rel=0.01)

    def fit(x):
        return SimpleNamespace(x=[np.array(x)])

    short = [
        (-90.0, c["motor_lag"], fit([0.005])),
        (-80.0, c["inertia"], fit([1.6] * 3)),
        (-50.0, c["delay"], fit([0.002])),
    ]
    un = unresolved(short, cur_bic=0.0, margin=10.0)
    assert un.name == "motor_lag" and un.floor == pytest.approx(0.008, rel=0.01)
    assert float(un.candidate.upper[0]) == pytest.approx(un.floor)
    assert "5.0 ms" in un.describe() and "8.0 ms" in un.describe()
    resolved_best = [(-90.0, c["motor_lag"], fit([0.02])), (-50.0, c["delay"], fit([0.002]))]
    assert unresolved(resolved_best, cur_bic=0.0, margin=10.0) is None
    assert unresolved(short, cur_bic=-85.0, margin=10.0) is None  # lowers BIC by 5 only
