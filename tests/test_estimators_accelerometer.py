"""The accelerometer's specific force as the regressions' thrust rows (IRLS, RLS): the rows
measure the thrust better than differenced velocity under a real vehicle's sensors, the
estimators fall back to the velocity rows (saying so when asked) without one, and the online,
offline and batched forms agree through held streams."""

from __future__ import annotations

import dataclasses
import json
import math
import warnings

import numpy as np
import pytest

from estimators.accelerometer import AccelerometerMissing
from estimators.base import samples
from estimators.batched import BatchedIRLS
from estimators.irls import IRLSConfig, SlidingWindowIRLS
from estimators.registry import make_estimator
from estimators.residuals import segment_terms
from estimators.rls import BatchedRLS, RecursiveLeastSquares, RLSConfig
from quadfault.cli import main as cli
from quadfault.errors import ConfigError
from quadfault.model.scenarios import AbruptFault, ConstantEfficiency, EfficiencySchedule, Scenario
from quadfault.model.trajectory import Circle
from quadfault.sim.simulator import SimConfig, simulate

WEAK = EfficiencySchedule(ConstantEfficiency(), (AbruptFault(motor=3, onset=0.0, level=0.8),))


def _fly(preset, duration, seed):
    return simulate(
        Scenario("weak", duration, WEAK, Circle()),
        config=SimConfig(saturate=False, sensor_noise=preset),
        seed=seed,
        thrust_noise=0.07,
    )


@pytest.fixture(scope="module")
def indiflight():
    """6 s of the circle under the indiflight preset (coloured velocity noise of 0.18 m/s,
    streams held at 105-504 Hz), rotor 3 at 0.8."""
    return _fly("indiflight", 6.0, seed=2)


def test_the_accelerometer_rows_measure_the_thrust_better_than_differenced_velocity(indiflight):
    """At the true efficiency, the thrust rows' residual is sensor noise and thrust noise
    only: an order of magnitude less from the accelerometer than from the velocity."""
    rec = indiflight
    f = np.clip(rec.thrust_cmd, 0.0, None)
    seg = segment_terms(
        rec.vehicle,
        rec.t,
        rec.position,
        rec.velocity,
        rec.rotation,
        rec.omega,
        f,
        IRLSConfig().segment_weights,
    )
    eta = rec.eta_true[:-1]
    model = np.einsum("kaj,kj->ka", seg.J[:, 0:3], eta)
    from_velocity = (seg.r0[:, 0:3] + model) / seg.dt[:, None]
    fresh = np.r_[True, np.any(rec.accel[1:-1] != rec.accel[:-2], axis=1)]  # no held reading
    from_accel = (
        np.einsum("kab,kb->ka", rec.rotation[:-1], rec.accel[:-1]) + model / seg.dt[:, None]
    )
    v_err = np.sqrt(np.mean(from_velocity**2))
    a_err = np.sqrt(np.mean(from_accel[fresh] ** 2))
    assert a_err < 0.1 * v_err, (a_err, v_err)


@pytest.mark.slow
@pytest.mark.parametrize(
    "make,off,on",
    [
        (SlidingWindowIRLS, IRLSConfig(), IRLSConfig(accelerometer="on")),
        (
            SlidingWindowIRLS,
            IRLSConfig.improved(accelerometer="off"),
            IRLSConfig.improved(),
        ),
        (RecursiveLeastSquares, RLSConfig(), RLSConfig(accelerometer="on")),
    ],
)
def test_the_accelerometer_rows_beat_the_velocity_rows_under_indiflight(indiflight, make, off, on):
    rec = indiflight.without_truth()
    late = indiflight.t >= 2.0
    truth = indiflight.eta_true[late]

    def errors(cfg):
        e = make(rec.vehicle, cfg).run(rec).eta[late] - truth
        return math.sqrt(np.mean(e**2)), abs(np.mean(e[:, [0, 1, 3]]))

    (rmse_off, bias_off), (rmse_on, bias_on) = errors(off), errors(on)
    assert rmse_on < 0.9 * rmse_off, (rmse_on, rmse_off)  # (the paper's IRLS: 0.053 vs 0.063)
    assert bias_on < bias_off, (bias_on, bias_off)  # the healthy rotors' mean error


@pytest.fixture(scope="module")
def crazyflie():
    """1.5 s under the crazyflie preset: every stream held at 100 Hz (the accelerometer too)."""
    return _fly("crazyflie", 1.5, seed=4).without_truth()


@pytest.mark.parametrize(
    "single,batched,config",
    [
        (SlidingWindowIRLS, BatchedIRLS, IRLSConfig.improved()),
        (SlidingWindowIRLS, BatchedIRLS, IRLSConfig(accelerometer="on")),
        (RecursiveLeastSquares, BatchedRLS, RLSConfig(accelerometer="on")),
    ],
)
def test_online_offline_and_batched_agree_through_held_accelerometer_readings(
    crazyflie, single, batched, config
):
    rec = crazyflie
    assert np.mean(np.all(rec.accel[1:] == rec.accel[:-1], axis=1)) > 0.8  # held at 100 Hz
    vehicle = rec.vehicle.replace(max_thrust=math.inf)  # unsaturated, as run() reads it
    est = single(vehicle, config)
    rows = list(samples(rec))
    online = np.array([est.update(s).eta for s in rows])
    offline = single(vehicle, config).run(rec)
    np.testing.assert_array_equal(offline.eta, online)
    batch = batched(vehicle, 2, config)
    fields = ("t", "p", "v", "R", "w", "f")
    for k, s in enumerate(rows):
        out = batch.update(*(np.array([getattr(s, a)] * 2) for a in fields), accel=[s.accel] * 2)
        np.testing.assert_array_equal(out.eta[1], online[k])
    # the option really changed the rows: the same flight through the velocity rows differs
    velocity = single(vehicle, dataclasses.replace(config, accelerometer="off")).run(rec)
    assert np.max(np.abs(velocity.eta - offline.eta)) > 1e-3


@pytest.mark.parametrize(
    "make,config",
    [
        (SlidingWindowIRLS, IRLSConfig.improved),
        (SlidingWindowIRLS, IRLSConfig),
        (RecursiveLeastSquares, RLSConfig),
    ],
)
def test_without_an_accelerometer_the_velocity_rows_are_used_and_said_once(crazyflie, make, config):
    bare = dataclasses.replace(crazyflie, accel=None)
    velocity = make(bare.vehicle, config(accelerometer="off")).run(bare)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "auto" falls back silently
        auto = make(bare.vehicle, config(accelerometer="auto")).run(bare)
    np.testing.assert_array_equal(auto.eta, velocity.eta)
    est = make(bare.vehicle, config(accelerometer="on"))
    with pytest.warns(AccelerometerMissing, match="no accelerometer") as said:
        asked = est.run(bare)
        online = [est.update(s) for s in list(samples(bare))[:50]]
    np.testing.assert_array_equal(asked.eta, velocity.eta)
    assert len(said) == 2  # once for the recording, once for the online samples
    assert all(np.all(np.isfinite(e.eta)) for e in online)


def test_the_option_is_checked_and_the_paper_keeps_the_velocity_rows():
    assert IRLSConfig().accelerometer == "off" and RLSConfig().accelerometer == "off"
    assert IRLSConfig.improved().accelerometer == "auto"
    assert IRLSConfig(accelerometer=True).accelerometer == "on"
    for make in (IRLSConfig, RLSConfig):
        with pytest.raises(ConfigError, match="accelerometer must be one of off, auto, on"):
            make(accelerometer="yes")


def test_the_cli_takes_the_option_and_notes_a_missing_accelerometer(tmp_path, capsys, crazyflie):
    from quadfault.io.recording import write_recording

    path = tmp_path / "bare.csv"
    write_recording(dataclasses.replace(crazyflie, accel=None), path)
    out = tmp_path / "est.csv"
    args = ["estimate", str(path), "--estimator", "irls", "--out", str(out), "--quiet"]
    assert cli(args + ["--accelerometer", "on"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("quadfault estimate: note: irls: ")
    assert json.loads(out.with_suffix(".json").read_text())["config"]["accelerometer"] == "on"
    assert cli(args + ["--accelerometer", "auto", "--force"]) == 0
    assert capsys.readouterr().err == ""
    with pytest.raises(SystemExit) as bad:  # a mode that is none of off, auto, on
        cli(args + ["--accelerometer", "yes", "--force"])
    assert bad.value.code == 2 and "invalid choice: 'yes'" in capsys.readouterr().err
    with pytest.raises(ConfigError, match="'accelerometer' applies to"):
        make_estimator("none", crazyflie.vehicle, accelerometer="on")
