"""Flight-phase mask: what is not free flight is found, named and excluded; free flight is not.

A synthetic log is stitched from two simulated flights with a landing (idle rotors on the
ground), a motors-off stretch and a tumble (impact, then lying upside down) in between and
after; the real-data checks read ../shared/data/real and skip when it is absent.
"""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from quadfault.diagnosis import Diagnosis, DiagnosisConfig
from quadfault.diagnosis.phases import flight_phases
from quadfault.diagnosis.residuals import prepare
from quadfault.io.recording import Recording
from quadfault.model.scenarios import named_scenario
from quadfault.model.trajectory import Lissajous
from quadfault.sim.simulator import SensorNoise, SimConfig, simulate

DT = 4e-3
DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real"


def _flight(seed, duration=4.0):
    sc = named_scenario("nominal", duration, DT).replace(
        trajectory=Lissajous(amplitude=(1.5, 1.0, 0.2), frequency=0.2)
    )
    cfg = SimConfig(dt=DT, sensor_noise=SensorNoise(0.002, 0.005, 0.001, 0.001, 0.02))
    return simulate(sc, config=cfg, seed=seed, thrust_noise=0.02).without_truth()


def _still(rec, seconds, f, sf_z, rng, w=0.0, sf_norm=None):
    """Rows of a body at rest at the ground (z = 0, level): commands ``f`` [N per rotor],
    accelerometer (0, 0, sf_z) (or random directions of norm ``sf_norm``), rates ``w``."""
    n = int(round(seconds / DT))
    sf = np.tile([0.0, 0.0, sf_z], (n, 1)) + 0.02 * rng.standard_normal((n, 3))
    if sf_norm is not None:
        d = rng.standard_normal((n, 3))
        sf = sf_norm * d / np.linalg.norm(d, axis=1, keepdims=True)
    return {
        "position": np.tile([rec.position[-1, 0], rec.position[-1, 1], 0.0], (n, 1)),
        "velocity": np.zeros((n, 3)),
        "quaternion": np.tile([1.0, 0, 0, 0], (n, 1)),
        "omega": w * rng.standard_normal((n, 3)) + 1e-4 * rng.standard_normal((n, 3)),
        "thrust_cmd": np.full((n, 4), f),
        "accel": sf,
    }


def _stitch(parts, vehicle):
    cols = ("position", "velocity", "quaternion", "omega", "thrust_cmd", "accel")
    data = {c: np.concatenate([p[c] for p in parts]) for c in cols}
    n = len(data["omega"])
    return Recording(t=DT * np.arange(n), vehicle=vehicle, **data)


def _as_parts(rec):
    return {
        c: getattr(rec, c)
        for c in ("position", "velocity", "quaternion", "omega", "thrust_cmd", "accel")
    }


@pytest.fixture(scope="module")
def stitched():
    a, b = _flight(1), _flight(2)
    g = a.vehicle.gravity
    idle = 0.3 * a.vehicle.weight / 4
    rng = np.random.default_rng(0)
    parts = [
        _as_parts(a),
        _still(a, 1.0, idle, -g, rng),  # landed, rotors idle
        _still(a, 1.5, 0.0, -g, rng),  # motors off on the ground
        _still(a, 0.5, idle, -g, rng),  # idle again before take-off
        _as_parts(b),
        _still(b, 0.2, idle, 0.0, rng, w=15.0, sf_norm=8 * g),  # impact, tumbling
        _still(b, 0.8, 0.0, g, rng),
    ]  # lying upside down, motors off
    n = [len(p["omega"]) for p in parts]
    edges = DT * np.cumsum([0] + n)
    return _stitch(parts, a.vehicle), edges


def test_landing_motors_off_and_tumble_are_masked_and_named(stitched):
    rec, edges = stitched
    spans = flight_phases(prepare(rec))
    reasons = " ".join(s.reason for s in spans)
    assert "motors off" in reasons and "supported" in reasons and "impact" in reasons

    def covered(t0, t1):
        t = np.linspace(t0, t1, 200)
        return np.mean([any(s.t0 <= x <= s.t1 for s in spans) for x in t])

    assert covered(edges[1] + 0.05, edges[4] - 0.05) == 1.0  # ground, motors off, ground
    assert covered(edges[5] + 0.02, rec.t[-1]) == 1.0  # the tumble to the end
    assert covered(edges[0], edges[1]) < 0.15  # the flights stay (margins only)
    assert covered(edges[4], edges[5]) < 0.15


def test_the_mask_is_in_the_json_and_no_mask_overrides_it(stitched):
    rec, edges = stitched
    res = Diagnosis().fit(rec)
    sc = res.scoring
    assert sc["excluded"] and all(set(e) == {"t0", "t1", "reason"} for e in sc["excluded"])
    expected = (edges[4] - edges[1] + edges[7] - edges[5]) / rec.duration
    assert sc["excluded_fraction"] == pytest.approx(expected, abs=0.1)
    assert res.verdict == "consistent" or all(e.name != "thrust_scale" for e in res.effects)
    raw = Diagnosis(DiagnosisConfig(mask=False)).fit(rec)
    assert raw.scoring["excluded"] == [] and raw.scoring["excluded_fraction"] == 0.0
    assert raw.scoring["scored_blocks"] > sc["scored_blocks"]
    assert raw.verdict == "mismatch"  # the ground and the tumble are not free flight


def test_nothing_is_masked_on_a_clean_flight():
    rec = _flight(3, duration=8.0)
    assert flight_phases(prepare(rec)) == ()
    res = Diagnosis().fit(rec)
    assert res.scoring["excluded"] == [] and res.scoring["excluded_fraction"] == 0.0


def test_a_deliberate_short_motor_cut_in_flight_is_data():
    """Half a second or less with the motors off in the air (free fall) is flight."""
    rec = _flight(4, duration=6.0)
    f = rec.thrust_cmd.copy()
    k0 = int(3.0 / DT)
    f[k0 : k0 + int(0.25 / DT)] = 0.0
    cut = dataclasses.replace(rec, thrust_cmd=f)
    assert flight_phases(prepare(cut)) == ()


def _import(kind, rel, tmp_path):
    path = DATA / rel
    if not path.exists():
        pytest.skip("../shared/data/real is not available")
    from quadfault.io.importers import get_importer

    return get_importer(kind)(path)


def test_real_pad_landing_and_crash_are_masked(tmp_path):
    pad = _import(
        "crazypad", "crazypad-cf21-faults/motor_data/normal_flight/E8_log00.csv.gz", tmp_path
    )
    spans = flight_phases(prepare(pad))
    assert len(spans) == 1 and "motors off" in spans[0].reason
    assert 5.0 < spans[0].t1 - spans[0].t0 < 7.5  # ~5 s on the pad plus take-off and landing
    crash = _import("eschmann", "eschmann-cf21-sysid/log10.csv.gz", tmp_path)
    spans = flight_phases(prepare(crash))
    assert [s.reason for s in spans] == ["impact (crash, hard landing)"]
    assert spans[0].t1 == pytest.approx(crash.t[-1]) and spans[0].t1 - spans[0].t0 < 0.6
