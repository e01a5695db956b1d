"""Effects the closed loop hides: a concealed inertia, whose fit the controller's reaction to
its own disturbances inflates (the instrumental-variable check rejects it), is named in
``indistinguishable`` with the time constants it trades with, never dropped as if absent;
the same flights without it raise nothing."""

import json

import numpy as np
import pytest

from quadfault.diagnosis import Diagnosis
from quadfault.diagnosis.feedback import IV_MIN, PARTLY_MIN, PARTLY_Z, partly_real
from quadfault.model import effects as fx
from quadfault.model.scenarios import named_scenario
from quadfault.model.trajectory import Circle, Hover, Lissajous
from quadfault.sim.simulator import SensorNoise, SimConfig, simulate

DT = 1.0 / 250.0  # what users record


def fly(traj, effects, seed, duration=30.0):
    """``quadfault simulate --trajectory ...`` at 250 Hz with the simulator's defaults."""
    sc = named_scenario("nominal", duration, DT).replace(trajectory=traj)
    cfg = SimConfig(dt=DT, sensor_noise=SensorNoise())
    return simulate(sc, config=cfg, seed=seed, effects=tuple(effects)).without_truth()


def named(doc, name) -> list:
    """The ``indistinguishable`` entries (with their sets) that hold ``name``."""
    return [n for n in doc["indistinguishable"] if "sets" in n and name in n["names"]]


def test_partly_real_needs_a_slope_clearly_above_zero_and_below_acceptance():
    assert partly_real(0.3, 0.03)
    assert not partly_real(0.3, 0.3 / PARTLY_Z)  # not PARTLY_Z se above 0
    assert not partly_real(0.9 * PARTLY_MIN, 0.001)  # too little of it is real
    assert not partly_real(IV_MIN, 0.01)  # accepted by the check itself
    assert not partly_real(float("nan"), 0.01)
    assert not partly_real(None, None)


@pytest.mark.slow
@pytest.mark.parametrize("traj", [Lissajous(), Circle()], ids=["lissajous", "circle"])
def test_a_concealed_inertia_is_named_and_the_effect_free_flight_is_quiet(traj):
    res = Diagnosis().fit(fly(traj, (fx.Inertia((1.4, 1.4, 1.4)),), seed=5))
    doc = json.loads(res.to_json())
    accepted = [e["name"] for e in doc["effects"]]
    hidden = named(doc, "inertia")
    assert "inertia" in accepted or hidden, (accepted, doc["indistinguishable"])
    assert res.verdict == "mismatch"
    for entry in hidden:
        assert set(entry["held_out"]["iv_slope"]) == set(entry["names"])
        for name in entry["names"]:
            assert entry["held_out"]["improvement"][name] > 0.0
            assert PARTLY_MIN <= entry["held_out"]["iv_slope"][name] < IV_MIN
        for one in entry["sets"]:
            for e in one:  # every reported parameter inside its own bounds
                for key, (lo, hi) in e["bounds"].items():
                    v = np.asarray(e["params"][key], dtype=float)
                    assert np.all(v >= np.asarray(lo) - 1e-9) and np.all(v <= np.asarray(hi) + 1e-9)
        assert entry["summary"] and entry["separate_by"]
        for e in doc["rejected"]:  # the rejected fit says where its real part went
            if e["name"] in entry["names"]:
                assert "see indistinguishable" in e["reason"]
    assert "cannot tell them apart" in res.summary()

    quiet = Diagnosis().fit(fly(traj, (), seed=5))
    assert quiet.verdict == "consistent"
    assert not quiet.effects and not quiet.indistinguishable


@pytest.mark.slow
def test_no_effect_is_accepted_at_a_bound_the_whole_flight_asks_for():
    """A hover with a 14 mm CoM offset: an inertia fit pinned at its bound (x2) changes each
    sample by less than the noise but improves the whole flight; it is a suspect, never an
    accepted effect."""
    rec = fly(Hover(), (fx.ComOffset((-0.0083, 0.0110)),), seed=0, duration=20.0)
    doc = json.loads(Diagnosis().fit(rec).to_json())
    for e in doc["effects"]:
        assert not e["at_bound"], e
        for key, (lo, hi) in e["bounds"].items():
            v = np.asarray(e["params"][key], dtype=float)
            span = np.abs(np.asarray(hi, dtype=float) - np.asarray(lo, dtype=float))
            assert np.all(np.minimum(np.abs(v - lo), np.abs(v - hi)) > 1e-6 * span), e
    assert "inertia" not in [e["name"] for e in doc["effects"]]
