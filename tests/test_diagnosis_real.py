"""The diagnosis on real Crazyflie logs (Eschmann et al. 2024, IMU-only, 1 kHz).

Reads ../shared/data/real (never copied into the repository) and skips when it is absent.
The literature and the data README's reference fit give a motor time constant of about
0.07-0.08 s; the issue asks for 0.05-0.11 s. Fits and scores exclude the importer's
calibration segment (``without_calibration``), as benchmarks/real_flights.py does.
"""

from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real"
ESCHMANN = DATA / "eschmann-cf21-sysid"


def _load(name):
    if not (ESCHMANN / f"{name}.csv.gz").exists():
        pytest.skip("../shared/data/real is not available")
    from quadfault.importers import get_importer
    from quadfault.importers.flight_analysis import without_calibration

    return without_calibration(get_importer("eschmann")(ESCHMANN / f"{name}.csv.gz"))


@pytest.mark.slow
def test_eschmann_motor_lag():
    from quadfault.diagnosis import Diagnosis

    res = Diagnosis().fit(_load("log10"))
    assert set(res.untestable) == {"drag", "wind", "ground_effect", "blade_flapping",
                                   "battery_thrust"}
    assert res.verdict == "mismatch"
    timing = [e for e in res.effects if e.name == "motor_lag"]
    assert timing, res.effect_names
    assert 0.05 <= timing[0].params["tau_s"] <= 0.11
    assert timing[0].improvement > 0.0


@pytest.mark.slow
def test_eschmann_motor_lag_on_the_roll_pitch_log():
    """log15 (roll/pitch excitation): the timing class alone explains most of the residual."""
    from quadfault.diagnosis import Diagnosis, DiagnosisConfig

    res = Diagnosis(DiagnosisConfig(effects=("motor_lag",))).fit(_load("log15"))
    assert res.effect_names == ["motor_lag"]
    tau = res.effects[0].params["tau_s"]
    assert 0.05 <= tau <= 0.11
    assert res.effects[0].improvement > 0.3
