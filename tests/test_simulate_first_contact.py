"""``quadfault simulate`` as a new user meets it: the paper's scenarios fly as the paper flies
them (no upper thrust limit unless ``--max-thrust``), and a flight that loses the vehicle or
goes below the ground ends there, with the reason in the sidecar and a warning."""

from __future__ import annotations

import contextlib
import io
import json
from dataclasses import replace

import numpy as np
import pytest

from quadfault.cli import main
from quadfault.io.recording import read_recording
from quadfault.model.scenarios import named_scenario
from quadfault.model.vehicle import Vehicle
from quadfault.sim.simulator import LOST_CONTROL_ERROR, flight_end, simulate


def _cli(argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in argv])
        except SystemExit as exc:
            code = exc.code
    return code, err.getvalue()


def _tracking_error(rec, scenario):
    return np.linalg.norm(rec.position - scenario.trajectory(rec.t).position, axis=1)


@pytest.mark.slow
def test_the_readme_example_stays_physical_for_80_s(tmp_path):
    """The README's example flies the paper's combined scenario unsaturated: the rotor at
    eta = 0.5 gets more than thrust-to-weight 2 and the vehicle stays on the circle."""
    out = tmp_path / "flight.csv"
    code, err = _cli(
        [
            "simulate",
            "--scenario",
            "combined",
            "--duration",
            "80",
            "--seed",
            "0",
            "--out",
            out,
            "--quiet",
        ]
    )
    assert code == 0 and "warning" not in err
    rec = read_recording(out)
    assert len(rec) == 80_000 and "end" not in rec.meta
    scenario = named_scenario("combined", 80.0)
    assert _tracking_error(rec, scenario).max() < 0.5
    assert (-rec.position[:, 2]).min() > 0.5  # the circle flies at 1 m
    assert rec.thrust_cmd.min() >= 0 and rec.thrust_cmd.max() > Vehicle().rotor_max_thrust
    # with the limit asked for and the plain mixer, the same flight loses the vehicle and
    # ends at the ground; the yaw-releasing mixer holds it
    limited = tmp_path / "limited.csv"
    code, err = _cli(
        [
            "simulate",
            "--scenario",
            "combined",
            "--duration",
            "80",
            "--seed",
            "0",
            "--max-thrust",
            Vehicle().rotor_max_thrust,
            "--mixer",
            "plain",
            "--out",
            limited,
            "--quiet",
        ]
    )
    assert code == 0 and err.startswith("warning: the controller lost the vehicle below the ground")
    cut = read_recording(limited)
    end = json.loads(limited.with_suffix(".json").read_text())["end"]
    assert end["reason"] == "below_ground" and end["planned_duration"] == 80.0
    assert 40.0 < end["t"] < 80.0 and cut.t[-1] == pytest.approx(end["t"], abs=1e-9)
    altitude = -cut.position[:, 2]
    assert altitude[-1] < 0.0 <= altitude[:-1].min()  # stops at the first row underground
    # the controller's commands up to the event: demands of a vehicle still in the air
    assert np.abs(cut.thrust_cmd).max() < 5 * Vehicle().rotor_max_thrust
    code, _ = _cli(["estimate", limited, "--out", tmp_path / "est.csv", "--quiet"])
    assert code == 0
    held = tmp_path / "held.csv"
    limit = ["--max-thrust", Vehicle().rotor_max_thrust, "--out", held, "--quiet"]
    code, err = _cli(["simulate", "--scenario", "combined", "--duration", "80", *limit])
    assert code == 0 and "warning" not in err
    assert _tracking_error(read_recording(held), scenario).max() < 0.5


def test_a_falling_flight_ends_at_the_ground_and_no_saturation_still_works(tmp_path):
    out = tmp_path / "fall.csv"
    code, err = _cli(
        [
            "simulate",
            "--scenario",
            "hover",
            "--duration",
            "3",
            "--max-thrust",
            "2.0",
            "--out",
            out,
            "--quiet",
        ]
    )  # below hover thrust: it falls
    assert code == 0 and "below the ground" in err and len(err.strip().splitlines()) == 1
    rec = read_recording(out)
    assert rec.meta["end"]["reason"] == "below_ground" and 0.3 < rec.t[-1] < 2.0
    free = tmp_path / "free.csv"
    code, err = _cli(
        [
            "simulate",
            "--scenario",
            "clipping",
            "--duration",
            "2",
            "--no-saturation",
            "--out",
            free,
            "--quiet",
        ]
    )
    assert code == 0 and err == "" and len(read_recording(free)) == 2000
    code, err = _cli(
        [
            "simulate",
            "--scenario",
            "hover",
            "--duration",
            "1",
            "--max-thrust",
            "-1",
            "--out",
            tmp_path / "bad.csv",
            "--quiet",
        ]
    )
    assert code == 2 and "max_thrust must be positive" in err and "Traceback" not in err


def test_flight_end_reasons():
    scenario = named_scenario("hover", 1.0)
    rec = simulate(scenario, seed=0)
    assert flight_end(rec, scenario) is None
    drift = rec.position.copy()
    drift[600:, 0] += LOST_CONTROL_ERROR + 0.1
    assert flight_end(replace(rec, position=drift), scenario) == (600, "lost_control")
    low = rec.position.copy()
    low[700:, 2] = 0.01  # NED: 1 cm below the ground at altitude 0
    moved = replace(rec, position=low)
    assert flight_end(moved, scenario) == (700, "below_ground")
    assert flight_end(moved, scenario.replace(ground_altitude=None)) is None
    assert flight_end(moved, scenario.replace(ground_altitude=-0.5)) is None


def test_stop_at_loss_is_the_same_flight_cut_at_the_event():
    scenario = named_scenario("hover", 3.0)
    weak = Vehicle(max_thrust=2.0)  # below hover thrust: it falls
    full = simulate(scenario, vehicle=weak, seed=4)
    cut = simulate(scenario, vehicle=weak, seed=4, stop_at_loss=True)
    row, reason = flight_end(full, scenario)
    assert len(cut) == row + 1 and cut.meta["end"] == {
        "reason": reason,
        "t": full.t[row],
        "planned_duration": 3.0,
    }
    for name in ("t", "position", "velocity", "quaternion", "omega", "thrust_cmd", "eta_true"):
        np.testing.assert_array_equal(getattr(cut, name), getattr(full, name)[: row + 1])
    assert "end" not in simulate(scenario, seed=4, stop_at_loss=True).meta


def test_an_effect_without_a_scenario_flies_the_nominal_scenario_and_says_so(tmp_path):
    out = tmp_path / "drag.csv"
    code, err = _cli(
        ["simulate", "--effect", "drag=0.3", "--duration", "0.5", "--out", out, "--quiet"]
    )
    assert code == 0 and err == ""  # --quiet: no note
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["scenario"] == "nominal" and not side.get("fault_windows")
    code, err = _cli(
        ["simulate", "--effect", "drag=0.3", "--duration", "0.5", "--out", out, "--force"]
    )
    assert code == 0 and err.count("\n") == 1 and "nominal scenario" in err, err
    code, err = _cli(["simulate", "--duration", "0.5", "--out", out, "--force", "--quiet"])
    assert code == 0 and json.loads(out.with_suffix(".json").read_text())["scenario"] == "combined"
