"""What a log can identify is decided before any fit, from its channels and rates.

Synthetic recordings made here: commands held at 10 Hz (no lag or delay can be seen), a
velocity the log flags invalid (no drag or wind), a thrust factor common to every rotor
(``thrust_scale``, never four weak motors) and an assumed mass and inertia.
"""

import dataclasses

import numpy as np
import pytest

from quadfault.diagnosis import Diagnosis, DiagnosisConfig
from quadfault.diagnosis.identifiability import change_period, evidence, gate, invalid_spans
from quadfault.diagnosis.library import build_library
from quadfault.diagnosis.residuals import prepare
from quadfault.errors import RecordingError
from quadfault.model import effects as fx
from quadfault.model.scenarios import named_scenario
from quadfault.model.trajectory import Lissajous
from quadfault.sim.simulator import SensorNoise, SimConfig, simulate

DT = 4e-3
TRAJ = Lissajous(amplitude=(2.0, 1.5, 0.3), frequency=0.15)


def fly(effects=(), seed=1, duration=8.0):
    sc = named_scenario("nominal", duration, DT).replace(trajectory=TRAJ)
    cfg = SimConfig(dt=DT, sensor_noise=SensorNoise(0.002, 0.005, 0.001, 0.001))
    return simulate(
        sc, config=cfg, seed=seed, effects=tuple(effects), thrust_noise=0.02
    ).without_truth()


def held(rec, rate_hz):
    """``rec`` with its rotor commands logged at ``rate_hz`` and held in between (what an
    importer makes of a slow output topic on a faster time base)."""
    idx = np.searchsorted(rec.t, np.floor(rec.t * rate_hz) / rate_hz, side="left")
    return dataclasses.replace(rec, thrust_cmd=rec.thrust_cmd[idx])


@pytest.fixture(scope="module")
def plain():
    return fly()


def test_the_command_period_is_the_time_between_changes(plain):
    assert change_period(plain.t, plain.thrust_cmd) == pytest.approx(DT, rel=0.01)
    assert change_period(plain.t, held(plain, 10.0).thrust_cmd) == pytest.approx(0.1, rel=0.05)
    flat = np.ones((len(plain.t), 4))
    assert change_period(plain.t, flat) == float("inf")


def test_the_importers_stream_rate_counts_where_interpolation_hides_it(plain):
    """An importer that interpolates a slow stream onto a fast time base records the stream's
    own rate; the slower of it and the changes counts."""
    meta = {**plain.meta, "import": {"stream_rates_hz": {"u": 10.0}}}
    ev = evidence(dataclasses.replace(plain, meta=meta))
    assert ev.command_period == pytest.approx(0.1)
    meta = {**plain.meta, "import": {"stream_rates_hz": {"u": 1000.0}}}
    assert evidence(dataclasses.replace(plain, meta=meta)).command_period == pytest.approx(DT)


def test_commands_at_10_hz_cannot_show_a_lag_or_delay(plain):
    res = Diagnosis().fit(held(plain, 10.0))
    skipped = {n["name"]: n["reason"] for n in res.not_identifiable}
    assert {"motor_lag", "delay"} <= set(skipped)
    assert "10 Hz" in skipped["motor_lag"] and "needs 20 Hz" in skipped["motor_lag"]
    fitted = {e.name for e in res.effects + res.suspect + res.rejected}
    assert not fitted & {"motor_lag", "delay"}
    doc = res.to_dict()
    assert {"name": "motor_lag", "reason": skipped["motor_lag"]} in doc["not_identifiable"]
    assert doc["evidence"]["command_rate_hz"] == pytest.approx(10.0, rel=0.05)


def test_a_lag_shorter_than_two_command_periods_is_never_accepted(plain):
    """At 50 Hz a lag is identifiable from 0.04 s up (two command periods); at 25 Hz from
    0.08 s; the library keeps that floor. At 4 Hz no lag is identifiable."""
    rp = prepare(held(plain, 50.0))
    lib, skipped = gate(build_library(rp), evidence(held(plain, 50.0)))
    lag = next(c for c in lib if c.name == "motor_lag")
    assert lag.resolvable == pytest.approx(0.04, rel=0.05)
    assert not {"motor_lag", "delay"} & {s["name"] for s in skipped}
    from quadfault.diagnosis.identifiability import too_short

    assert "shorter than 2 command periods" in too_short(lag, [0.02])
    assert too_short(lag, [0.06]) == ""
    ev = evidence(held(plain, 25.0))
    assert ev.shortest_time_constant == pytest.approx(0.08, rel=0.05)


@pytest.fixture(scope="module")
def drag_flight():
    return fly((fx.Drag(0.3),), seed=2)


@pytest.mark.filterwarnings("error::RuntimeWarning")  # numpy's warnings never reach users
def test_an_invalid_velocity_gives_no_drag_or_wind(drag_flight):
    t0, t1 = float(drag_flight.t[0]), float(drag_flight.t[-1])
    rec = dataclasses.replace(
        drag_flight, meta={**drag_flight.meta, "invalid": {"velocity": [[t0, t1]]}}
    )
    res = Diagnosis().fit(rec)
    skipped = {n["name"]: n["reason"] for n in res.not_identifiable}
    assert {"drag", "wind"} <= set(skipped) and "invalid" in skipped["drag"]
    assert not {"drag", "wind"} & set(res.effect_names)
    assert not any(c.startswith("acc_") for c in res.channels)  # diagnosed from the IMU
    assert any(c.startswith("sf_") for c in res.channels)


def test_a_short_invalid_span_is_left_out_and_named(drag_flight):
    rec = dataclasses.replace(
        drag_flight, meta={**drag_flight.meta, "invalid": {"velocity": [[2.0, 3.0]]}}
    )
    spans = invalid_spans(rec)
    assert spans == {"velocity": ((2.0, 3.0),)}
    rp = prepare(rec, exclude=[(2.0, 3.0, "x")])
    assert not np.any((rp.block_t > 2.05) & (rp.block_t < 2.95))
    res = Diagnosis(DiagnosisConfig(effects=("drag",))).fit(rec)
    reasons = [e["reason"] for e in res.scoring["excluded"]]
    assert any("flagged invalid" in r for r in reasons)
    assert "drag" in res.effect_names


def test_a_0_1_validity_column_flags_spans_and_a_bad_sidecar_entry_is_one_line(drag_flight):
    flag = ((drag_flight.t < 1.0) | (drag_flight.t > 1.5)).astype(float)
    rec = dataclasses.replace(drag_flight, extra={"velocity_valid": flag})
    ((a, b),) = invalid_spans(rec)["velocity"]
    assert a == pytest.approx(1.0, abs=DT) and b == pytest.approx(1.5, abs=2 * DT)
    bad = dataclasses.replace(drag_flight, meta={"invalid": {"velocity": [["x"]]}})
    with pytest.raises(RecordingError, match="invalid.velocity"):
        invalid_spans(bad)


@pytest.fixture(scope="module")
def common_factor():
    return fly((fx.ThrustScale(0.85),), seed=4)


def test_a_common_thrust_factor_is_not_four_weak_motors(common_factor):
    res = Diagnosis(DiagnosisConfig(effects=("motor_efficiency",))).fit(common_factor)
    assert "motor_efficiency" not in res.effect_names
    why = next(e.reason for e in res.rejected + res.suspect if e.name == "motor_efficiency")
    assert "do not differ" in why and "thrust_scale" in why
    res = Diagnosis(DiagnosisConfig(effects=("motor_efficiency", "thrust_scale"))).fit(
        common_factor
    )
    assert res.effect_names == ["thrust_scale"]
    assert res.effects[0].params["scale"] == pytest.approx(0.85, abs=0.02)


@pytest.fixture(scope="module")
def weak_rotor():
    return fly((fx.MotorEfficiency((0.8, 0.8, 0.6, 0.8)),), seed=5)


def test_one_weak_rotor_is_reported_relative_to_the_others(weak_rotor):
    """Every rotor at 0.8 of nominal and rotor 3 at 0.6: a common factor and one rotor 25 %
    weaker than the others; the efficiency is reported relative to the median rotor."""
    rec = weak_rotor
    res = Diagnosis(DiagnosisConfig(effects=("motor_efficiency",))).fit(rec)
    assert res.effect_names == ["motor_efficiency"]
    np.testing.assert_allclose(res.effects[0].params["eta"], [1.0, 1.0, 0.75, 1.0], atol=0.03)
    assert "eta_absolute" not in res.effects[0].params
    assert "relative to the median rotor" in res.effects[0].explanation


@pytest.fixture(scope="module")
def com_offset_flight():
    return fly((fx.ComOffset((0.005, -0.003)),), seed=7)


def test_a_centre_of_mass_offset_is_not_a_weak_rotor(com_offset_flight):
    """Healthy rotors, the CoM 6 mm off centre: in hover a per-rotor efficiency pattern fits
    it too, but not better than the vehicle's own imbalance on the same held-out folds, so
    it is never accepted: the rejection says which rotor looks weakest and that one flight
    cannot tell."""
    res = Diagnosis(DiagnosisConfig(effects=("motor_efficiency",))).fit(com_offset_flight)
    assert "motor_efficiency" not in res.effect_names
    eff = next(e for e in res.rejected if e.name == "motor_efficiency")
    k = int(np.argmin(eff.params["eta"]))
    assert min(eff.params["eta"]) < 0.98  # the pattern is there ...
    assert eff.reason.startswith(f"vehicle imbalance: rotor {k + 1} looks weakest")
    assert "com_offset" in eff.reason
    assert "one flight cannot tell a weak rotor from the vehicle's own imbalance" in eff.reason
    assert "--baseline" in eff.reason
    # ... and the default library names the cause, never a weak rotor alone: accepted, or
    # beside the weak rotor it cannot be told from
    res = Diagnosis().fit(com_offset_flight)
    assert "motor_efficiency" not in res.effect_names
    found = [e.params for e in res.effects if e.name == "com_offset"]
    found += [
        e["params"]
        for n in res.indistinguishable
        for one in n.get("sets", ())
        for e in one
        if e["name"] == "com_offset"
    ]
    assert found
    np.testing.assert_allclose(found[0]["offset_m"], [0.005, -0.003], atol=0.001)


def test_a_weak_rotor_in_maneuvers_is_told_from_the_vehicles_imbalance():
    """Rotor 3 at 0.7 over a Lissajous flight: the rotors' commands vary relative to each
    other, and the per-rotor pattern explains the held-out data better than a CoM offset
    with a yaw trim."""
    res = Diagnosis(DiagnosisConfig(effects=("motor_efficiency",))).fit(
        fly((fx.MotorEfficiency((1.0, 1.0, 0.7, 1.0)),), seed=6)
    )
    assert res.effect_names == ["motor_efficiency"]
    eta = res.effects[0].params["eta"]
    assert int(np.argmin(eta)) == 2
    np.testing.assert_allclose(eta, [1.0, 1.0, 0.7, 1.0], atol=0.03)


def test_the_healthy_pattern_of_several_flights_and_its_spread():
    from quadfault.model.effects.motor_efficiency import EfficiencyCandidate, healthy_pattern

    eta, spread = healthy_pattern([(1.0, 1.1, 0.8, 1.0)])
    np.testing.assert_allclose(eta, [1.0, 1.1, 0.8, 1.0])
    assert spread == ()
    flights = [(1.0, 1.1, 0.8, 1.0), (2.0, 2.2, 1.76, 2.0), (1.0, 1.1, 0.84, 1.0)]
    eta, spread = healthy_pattern(flights)  # a common factor is not a difference
    np.testing.assert_allclose(eta, [1.0, 1.1, 0.8 * (1.1 * 1.05) ** (1 / 3), 1.0], rtol=1e-12)
    sd3 = np.std(np.log([0.8, 0.88, 0.84]), ddof=1)
    np.testing.assert_allclose(spread, [0.0, 0.0, sd3, 0.0], atol=1e-12)
    cand = EfficiencyCandidate(
        "motor_efficiency",
        ("a",) * 4,
        (0.2,) * 4,
        (1.5,) * 4,
        (1.0,) * 4,
        ((1.0,) * 4,),
        "thrust",
        spread=spread,
    )
    np.testing.assert_allclose(cand.tolerance(), [0.05, 0.05, 3 * sd3, 0.05])


def test_assumed_mass_and_inertia_say_what_depends_on_them(drag_flight):
    rec = dataclasses.replace(
        drag_flight, meta={**drag_flight.meta, "assumed": ["mass", "inertia"]}
    )
    res = Diagnosis(DiagnosisConfig(effects=("drag", "motor_lag"))).fit(rec)
    a = res.to_dict()["assumptions"]
    assert a["assumed"] == ["mass", "inertia"]
    assert a["depends"].get("drag") == ["mass"]
    assert "time constants" in a["note"] and "ratios between rotors" in a["note"]
    assert Diagnosis(DiagnosisConfig(effects=("drag",))).fit(drag_flight).assumptions == {}


def test_a_healthy_baseline_flight_separates_damage_from_the_vehicles_own_imbalance(
    weak_rotor, tmp_path
):
    """Rotor 3 is 25 % weaker than the others. Against a baseline in which it was already
    that weak (the vehicle's own imbalance) nothing is accepted; against a baseline of equal
    rotors it is, relative to the baseline."""
    import json

    from quadfault.diagnosis.cli import baseline_eta

    same = Diagnosis(
        DiagnosisConfig(effects=("motor_efficiency",), baseline_eta=(1.0, 1.0, 0.75, 1.0))
    ).fit(weak_rotor)
    assert "motor_efficiency" not in same.effect_names
    why = next(e.reason for e in same.rejected if e.name == "motor_efficiency")
    assert "match the healthy vehicle" in why
    spread = Diagnosis(
        DiagnosisConfig(  # healthy flights whose rotor 3 varies by 10 %
            effects=("motor_efficiency",),
            baseline_eta=[(1.0, 1.0, 0.85, 1.0), (1.0, 1.0, 1.0, 1.0)],
        )
    ).fit(weak_rotor)
    assert "motor_efficiency" not in spread.effect_names
    why = next(e.reason for e in spread.rejected if e.name == "motor_efficiency")
    assert "match the healthy vehicle (2 flights)" in why
    other = Diagnosis(
        DiagnosisConfig(effects=("motor_efficiency",), baseline_eta=(1.0, 1.05, 1.0, 0.95))
    ).fit(weak_rotor)
    p = other.effects[0].params
    assert p["baseline_flights"] == 1 and "baseline_spread" not in p
    np.testing.assert_allclose(p["eta"][2] / p["eta"][0], 0.75, atol=0.03)
    np.testing.assert_allclose(p["eta_flight"], [1.0, 1.0, 0.75, 1.0], atol=0.03)
    path = tmp_path / "healthy.json"
    path.write_text(other.to_json())
    assert baseline_eta(path) == pytest.approx(tuple(p["eta_flight"]))
    path.write_text(json.dumps({"effects": []}))
    with pytest.raises(RecordingError, match="no motor_efficiency fit"):
        baseline_eta(path)
    with pytest.raises(Exception, match="4 positive numbers"):
        DiagnosisConfig(baseline_eta=(1.0, 0.0, 1.0, 1.0))


def test_the_report_lists_what_was_not_identifiable_and_the_assumed_constants():
    from quadfault.diagnosis.report_text import markdown
    from quadfault.diagnosis.result import DiagnosisResult

    res = DiagnosisResult(
        verdict="consistent",
        baseline_rmse={},
        model_rmse={},
        model_improvement=0.0,
        not_identifiable=({"name": "motor_lag", "reason": "rotor commands logged at 10 Hz"},),
        assumptions={
            "assumed": ["mass"],
            "depends": {"drag": ["mass"]},
            "independent": ["motor_lag"],
            "note": "the vehicle's mass is assumed",
        },
    )
    text = markdown(res, "flight.csv")
    assert "## Not identifiable from this log" in text
    assert "- **motor_lag**: rotor commands logged at 10 Hz" in text
    assert "- drag depends on the assumed mass" in text
    assert "## Not identifiable" not in markdown(
        DiagnosisResult(
            verdict="consistent", baseline_rmse={}, model_rmse={}, model_improvement=0.0
        ),
        "f.csv",
    )


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_the_uncertainty_of_a_parameter_without_signal_does_not_overflow():
    """diag(pinv(H)) of the fit's normal matrix, scaled so that a parameter whose column is
    a few subnormal numbers (no signal) gives a huge finite uncertainty, not numpy's
    'overflow in divide'; equal to numpy's pinv elsewhere."""
    from quadfault.diagnosis.fit import _pinv_diag_sqrt

    rng = np.random.default_rng(0)
    for k in range(50):
        J = rng.normal(size=(30, 3)) * 10.0 ** rng.integers(-8, 8)
        J[:, 1] *= k % 2
        M = J.T @ J
        ref = np.sqrt(np.maximum(np.diag(np.linalg.pinv(M)), 1e-300))
        np.testing.assert_allclose(_pinv_diag_sqrt(M, 1e-300), ref, rtol=1e-9)
    sd = _pinv_diag_sqrt(np.diag([1e-310, 0.0, 0.0]), 1e-300)
    assert np.all(np.isfinite(sd)) and sd[0] > 1e150 and sd[1] == pytest.approx(1e-150)
    sd = _pinv_diag_sqrt(np.diag([1e-310, 0.0, 1.0]), 1e-300)  # cut as pinv cuts it
    np.testing.assert_allclose(sd, [1e-150, 1e-150, 1.0])


@pytest.mark.slow
def test_an_implausible_battery_voltage_is_not_fitted():
    """The importer flags a voltage that is not the pack's (``meta.import.battery``): the
    diagnosis names battery_thrust as not identifiable with that reason instead of fitting
    the thrust to it."""
    effect = fx.BatteryThrust(exponent=2.0, v_start=4.2, v_end=3.7)
    rec = simulate(named_scenario("nominal", duration=4.0), seed=0, effects=(effect,))
    rec = dataclasses.replace(rec, vbat=4.2 - 0.5 * rec.t / effect.duration)  # as simulate's CLI
    why = "5.80-5.90 V per cell in flight on 1 cell: outside 3-4.35 V"
    flagged = dataclasses.replace(
        rec, meta={**rec.meta, "import": {"battery": {"plausible": False, "why": why}}}
    )
    config = DiagnosisConfig(effects=("battery_thrust", "thrust_scale"))
    res = Diagnosis(config).fit(flagged)
    skipped = {n["name"]: n["reason"] for n in res.not_identifiable}
    assert "battery_thrust" in skipped and why in skipped["battery_thrust"]
    assert "battery_thrust" not in res.effect_names
    assert "battery_thrust" in {c.name for c in build_library(prepare(rec), ("battery_thrust",))}
