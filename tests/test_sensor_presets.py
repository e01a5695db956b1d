"""Every preset's numbers are the measurement that produced them: the logs of
``../shared/data/real`` measured again (benchmarks/sensor_noise.py, through the importers) give
each number of each preset (skipped where the logs are absent); and the measurement finds
the noise the simulator was given."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest

from quadfault.model.sensor_presets import MEASURED_ON, PRESETS
from quadfault.model.sensors import MODEL_FIELDS, STREAMS

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import sensor_noise  # noqa: E402

REAL = Path(os.environ.get("QUADFAULT_REAL_DATA", ROOT.parent / "shared" / "data" / "real"))

#: preset -> (Crazyflie data set name or None, folder, file pattern): the logs of MEASURED_ON
SOURCES = {
    "crazyflie": ("nanodrone", "nanodrone-cf21bl", "*.csv.gz"),
    "indiflight": (None, "indiflight-throws-early", "*.BFL"),
    "px4": (None, "px4-uavcan-fmuv3", "*.ulg"),
}


def test_every_measured_preset_names_its_logs_and_command():
    assert set(PRESETS) == {"none", *SOURCES}
    for name, (_, folder, _) in SOURCES.items():
        assert folder in MEASURED_ON[name] and "benchmarks/sensor_noise.py" in MEASURED_ON[name]


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SOURCES))
def test_a_preset_is_what_its_logs_measure(name):
    dataset, folder, pattern = SOURCES[name]
    logs = sorted((REAL / folder).glob(pattern))
    if not logs:
        pytest.skip(f"real data not available ({REAL / folder} is absent)")
    numbers = sensor_noise.preset_numbers(sensor_noise.measure_files(logs, dataset))
    preset = PRESETS[name]
    for s in STREAMS:
        got = preset.stream(s)
        for key in ("white", *MODEL_FIELDS):
            want = numbers[s][key]
            if key == "tau" and numbers[s]["markov"] == 0.0:
                continue  # (no coloured noise: its time does not matter)
            assert got[key] == pytest.approx(want, rel=0.01, abs=1e-12), (name, s, key)


def test_the_measurement_finds_the_noise_it_was_given(tmp_path):
    """A simulated flight (the paper's circle) with known sensors, measured like a log: the
    rates, the white noise and the latency of velocity after the accelerometer come back."""
    from quadfault.io.recording import write_recording
    from quadfault.model.scenarios import named_scenario
    from quadfault.model.sensors import SensorNoise
    from quadfault.sim.simulator import SimConfig, simulate

    noise = SensorNoise(
        0.002,
        0.004,
        0.001,
        0.01,
        0.05,
        rate=(100.0, 100.0, 250.0, 500.0, 500.0),
        latency=(0.0, 0.02, 0.0, 0.0, 0.0),
    )
    rec = simulate(named_scenario("combined", 20.0), config=SimConfig(sensor_noise=noise), seed=2)
    write_recording(rec, tmp_path / "sim.csv")
    [(_, m)] = sensor_noise.measure_files([tmp_path / "sim.csv"])
    for s, rate in zip(STREAMS, noise.rate):
        assert m[s]["rate"] == pytest.approx(rate, rel=0.02), s
    assert m["accel"]["white"] == pytest.approx(0.05, rel=0.15)
    # the controller flies on the noisy gyro: the true rate takes some of its noise too
    assert 1.0 < m["gyro"]["white"] / 0.01 < 1.35
    assert m["position"]["white"] == pytest.approx(0.002, rel=0.15)
    assert m["velocity"]["latency"] == pytest.approx(0.02, abs=0.004)
    assert abs(m["attitude"]["latency"]) < 0.004
    assert np.isfinite(m["attitude"]["markov"])


def test_an_imu_only_log_gives_its_rates_and_white_noise_and_says_what_it_cannot():
    """A synthetic IMU-only recording: a gyro held at 250 Hz with white noise, an
    accelerometer quantised to 0.01 m/s^2 every row; no pose, so no bias and no coloured part."""
    from quadfault.diagnosis.sensor_noise import measure_noise
    from quadfault.io.recording import Recording
    from quadfault.model.vehicle import Vehicle

    rng = np.random.default_rng(0)
    t = np.arange(20_000) * 1e-3
    motion = np.stack([np.sin(2 * np.pi * 0.5 * t + k) for k in range(3)], axis=1)
    gyro = motion + 0.01 * rng.standard_normal((len(t), 3))
    gyro = gyro[(np.arange(len(t)) // 4) * 4]  # held: a new sample every 4 rows
    accel = np.round((motion + 0.05 * rng.standard_normal((len(t), 3))) / 0.01) * 0.01
    rec = Recording(
        t=t, omega=gyro, thrust_cmd=np.ones((len(t), 4)), vehicle=Vehicle(), accel=accel
    )
    m = measure_noise(rec)
    assert set(m) == {"gyro", "accel"}
    assert m["gyro"]["rate"] == pytest.approx(250.0, rel=0.01)
    assert m["gyro"]["white"] == pytest.approx(0.01, rel=0.1)
    assert m["gyro"]["white_check"] == pytest.approx(1.0, abs=0.15)
    assert m["accel"]["rate"] == pytest.approx(1000.0, rel=0.01)
    assert m["accel"]["white"] == pytest.approx(0.05, rel=0.1)
    assert m["gyro"]["bias"] is None and any("bias not measured" in n for n in m["gyro"]["notes"])


def test_a_stream_the_importer_derived_is_not_measured():
    """A velocity the importer differentiated from the position (its ``meta.import.missing``
    says so) is no measurement: left out, and the position has nothing to be checked against."""
    from dataclasses import replace

    from quadfault.diagnosis.sensor_noise import measure_noise
    from quadfault.io.recording import Recording
    from quadfault.model.vehicle import Vehicle

    rng = np.random.default_rng(1)
    t = np.arange(5000) * 0.01
    p = np.stack([np.sin(0.3 * t + k) for k in range(3)], axis=1)
    p = p + 0.001 * rng.standard_normal(p.shape)
    v = np.gradient(p, t, axis=0)
    rec = Recording(
        t=t,
        omega=np.zeros((len(t), 3)),
        thrust_cmd=np.ones((len(t), 4)),
        vehicle=Vehicle(),
        position=p,
        velocity=v,
        quaternion=np.tile([1.0, 0.0, 0.0, 0.0], (len(t), 1)),
    )
    logged = measure_noise(rec)
    assert logged["velocity"]["white"] > 0 and logged["position"]["markov"] is not None
    meta = {"import": {"missing": ["velocity (differentiated from position)"]}}
    m = measure_noise(replace(rec, meta=meta))
    assert m["velocity"]["white"] is None and "derived by the importer" in m["velocity"]["notes"][0]
    assert m["position"]["white"] == pytest.approx(0.001, rel=0.15)
    assert m["position"]["markov"] is None
