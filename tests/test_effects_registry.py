"""The effect registry: one table, every effect's declarations readable from it."""

import numpy as np
import pytest

from quadfault.diagnosis import Diagnosis, DiagnosisConfig
from quadfault.diagnosis.library import build_library, predict_intervals
from quadfault.diagnosis.residuals import prepare
from quadfault.errors import ConfigError
from quadfault.model.effects import chain, parse_effect, registry, rows
from quadfault.model.effects.base import CHANNELS, Compiled, Identifiability
from quadfault.model.scenarios import LinearVoltage, named_scenario
from quadfault.model.trajectory import Lissajous
from quadfault.model.vehicle import Vehicle
from quadfault.sim.simulator import SensorNoise, SimConfig, simulate


def test_every_effect_is_registered_once_with_a_unique_name():
    names = registry.names()
    assert len(set(names)) == len(names) == len(registry.TABLE)
    for k, name in enumerate(names):
        assert registry.code(name) == k
        assert registry.effect_class(name).name == name


@pytest.mark.parametrize("name", registry.names())
def test_every_effect_declares_what_a_recording_needs(name):
    need = registry.identifiability(name)
    assert isinstance(need, Identifiability)
    assert set(need.channels + need.any_of + need.direct) <= set(CHANNELS)
    assert need.note  # a reason a user can read
    if need.timescale is not None:  # a reported parameter of the effect
        assert need.timescale in registry.effect_class(name)().params()


def test_declarations_follow_the_physics():
    """Forces against the velocity need it; a lag needs fast commands and rotor speeds show
    it directly; the battery effect needs the voltage."""
    for name in ("drag", "wind", "blade_flapping"):
        assert "velocity" in registry.identifiability(name).channels
    lag = registry.identifiability("motor_lag")
    assert lag.min_command_rate > 10.0 and "rotor_speed" in lag.direct
    assert registry.identifiability("battery_thrust").columns() == ("vbat",)


def test_unknown_names_are_one_line_errors():
    with pytest.raises(ConfigError, match="unknown effect 'lag'"):
        registry.identifiability("lag")
    with pytest.raises(ValueError, match="unknown channel group"):
        Identifiability(channels=("speed",))


# every registered effect: simulates, packs, and is recovered by the diagnosis -----------
DT = 4e-3
TRAJ = Lissajous(amplitude=(2.0, 1.5, 0.3), frequency=0.15)
#: flights an effect needs beyond the default (the height varying near the ground)
FLIGHTS = {"ground_effect": Lissajous(amplitude=(1.0, 1.0, 0.15), frequency=0.15, altitude=0.35)}


def _fly(effect, seed=1, duration=8.0):
    sc = named_scenario("nominal", duration, DT).replace(trajectory=FLIGHTS.get(effect.name, TRAJ))
    if "battery" in effect.identifiability.channels:  # the voltage the effect follows, logged
        sc = sc.replace(voltage=LinearVoltage(effect.v_start, effect.v_end, effect.duration))
    cfg = SimConfig(dt=DT, sensor_noise=SensorNoise(0.002, 0.005, 0.001, 0.001))
    return simulate(sc, config=cfg, seed=seed, effects=(effect,), thrust_noise=0.02)


@pytest.mark.parametrize("name", registry.names())
def test_every_effect_parses_packs_and_simulates(name):
    cls = registry.effect_class(name)
    effect = parse_effect(cls.example)
    assert type(effect) is cls and type(cls.from_params(effect.params())) is cls
    entry = rows.entry(effect, 4, DT, np.array([-1.0, 1.0, -1.0, 1.0]))
    if entry is None:  # a body effect: it changes the flown vehicle instead
        assert not isinstance(effect, Compiled)
        assert effect.true_vehicle(Vehicle()) != Vehicle()
    else:
        slot_class, params, memory = entry
        assert slot_class is cls and len(params) > 0 and memory >= 0
        built = rows.build([[entry]], 4)
        a = built.param[0, 0]
        assert built.layout.effects[built.slot[0, 0]] is cls
        assert np.all(built.params[0, a : a + len(params)] == params)
    nominal = _fly(parse_effect("thrust_scale=1"), duration=1.0)
    rec = _fly(effect, duration=1.0)
    assert np.all(np.isfinite(rec.position)) and len(rec) == len(nominal)
    assert np.max(np.abs(rec.position - nominal.position)) > 1e-6  # the effect acts


@pytest.mark.slow
def test_vehicles_flying_some_of_a_layouts_slots_fly_as_in_their_own_layout():
    """A vehicle's numbers do not depend on the other slots of its rows' layout (slots it
    does not fly are skipped), nor on a thrust-only and a wrench-only entry trading places."""
    lag, drag = (
        rows.entry(parse_effect("motor_lag=0.05"), 4, 1e-3),
        rows.entry(parse_effect("drag=0.3"), 4, 1e-3),
    )
    wind = rows.entry(parse_effect("wind=1,2,0,gust=0.5,seed=3"), 4, 1e-3)
    delay = rows.entry(parse_effect("delay=0.01"), 4, 1e-3)
    state = ((0.0, 0.0, -1.0), (1.0, -0.5, 0.2), tuple(np.eye(3).ravel()), (0.1, 0.2, -0.3))
    out = []
    for fx, i in (
        (rows.build([[lag, drag]], 4), 0),
        (rows.build([[delay, wind], [drag, lag]], 4), 1),
        (rows.build([[lag, wind, drag]] * 2 + [[lag, drag]], 4), 2),
    ):
        f = np.array([2.0, 2.1, 2.2, 2.3])
        for k in range(3):
            chain.thrust_effects(fx, i, f, k * 1e-3, 1e-3, *state, np.random.default_rng(0))
            f = f + 0.1
        W = chain.wrench_terms(fx, i, f, 0.0)
        out.append((f.copy(), chain.summed_wrench(W, *state, f, 0.0)))
    for other in out[1:]:
        np.testing.assert_array_equal(out[0][0], other[0])
        assert out[0][1] == other[1]
    assert out[0][1][0] != (0.0, 0.0, 0.0)


def test_the_chain_carries_as_many_thrusts_as_the_rows_rotors():
    """Rows are built for a rotor count: a hexacopter's chain scales its six thrusts, and a
    loop whose vehicles have another count refuses the rows with a one-line error."""
    from quadfault.model import closed_loop

    scale = rows.entry(parse_effect("thrust_scale=0.5"), 6, 1e-3)
    fx = rows.build([[scale]], 6)
    state = ((0.0, 0.0, -1.0), (0.0, 0.0, 0.0), tuple(np.eye(3).ravel()), (0.0, 0.0, 0.0))
    f = np.arange(1.0, 7.0)
    chain.thrust_effects(fx, 0, f, 0.0, 1e-3, *state, np.random.default_rng(0))
    np.testing.assert_array_equal(f, 0.5 * np.arange(1.0, 7.0))
    V = closed_loop.Vehicles.empty(1, 4)
    with pytest.raises(ConfigError, match="built for 6 rotors, the vehicles have 4"):
        closed_loop.fly(np.random.default_rng(0), 0, 1, True, None, V, None, None, fx)


def test_rows_are_typed_by_their_layout_and_grow_to_new_effects():
    """Rows carry their layout (an effect per slot) in their compiled type: the loop
    compiles that chain alone. A vehicle given an effect the rows lack grows them, keeping
    the other rows' parameters and memory; a vehicle's own order is kept."""
    import numba

    from quadfault.model.effects import Drag, MotorLag

    lag, drag = (
        rows.entry(parse_effect("motor_lag=0.05"), 4, 1e-3),
        rows.entry(parse_effect("drag=0.3"), 4, 1e-3),
    )
    wind = rows.entry(parse_effect("wind=1,2,0"), 4, 1e-3)
    fx = rows.build([[lag], []], 4)
    assert fx.layout == chain.ChainLayout((MotorLag,), 4)
    assert numba.typeof(fx) != numba.typeof(rows.build([[drag]], 4))
    assert numba.typeof(fx) == numba.typeof(rows.build([[lag]] * 3, 4))
    fx.memory[0, :] = 7.0  # a flight under way
    assert not rows.fits(fx, [lag, drag])
    grown = rows.grown(fx, [wind, lag, drag])
    assert grown.layout.names == ("wind", "motor_lag", "drag")
    assert np.all(grown.memory[0, : fx.memory.shape[1]] == 7.0)
    assert grown.layout.effects[grown.slot[0, 0]] is MotorLag
    assert grown.params[0, grown.param[0, 0]] == 0.05
    rows.write(grown, 1, [drag, lag])  # a wrench-only and a thrust-only entry: any order
    assert grown.layout.names == ("wind", "motor_lag", "drag")
    assert [grown.layout.effects[k] for k in grown.slot[1, :2]] == [Drag, MotorLag]
    assert grown.params[1, grown.param[1, 0]] == 0.3 and grown.params[0, grown.param[0, 0]] == 0.05
    assert not rows.fits(grown, [lag, wind])  # two thrust-stage entries in another order
    assert rows.grown(grown, [lag, wind]).layout.names == ("wind", "motor_lag", "drag", "wind")
    with pytest.raises(ConfigError, match="more room"):
        rows.write(fx, 1, [drag])


@pytest.mark.slow
@pytest.mark.parametrize("name", registry.names())
def test_every_effect_is_recovered_by_the_diagnosis(name):
    """The diagnosis, asked for the effect alone, finds it in a seeded 8 s flight: every
    parameter the example sets within 25 % (or 2 % of its bounds' span), and the fitted effect
    reproduces the true one's signature in the model's channels within 25 % (a parameter the
    example leaves at zero is held by that alone: the flight may barely excite it)."""
    effect = parse_effect(registry.effect_class(name).example)
    rec = _fly(effect).without_truth()
    res = Diagnosis(DiagnosisConfig(effects=(name,))).fit(rec)
    rivals = {  # the effect as one side of a pair this flight cannot tell apart (mass/thrust)
        e["name"]: e["params"]
        for s in res.indistinguishable
        for side in s.get("sets", ())
        for e in side
    }
    if res.effect_names == [name]:
        params = res.effects[0].params
    else:
        assert not res.effect_names and name in rivals, (res.effect_names, res.suspect)
        params = rivals[name]
    rp = prepare(rec)
    (c,) = build_library(rp, (name,))
    want, got = c.x_from_params(effect.params()), c.x_from_params(params)
    span = np.asarray(c.upper) - np.asarray(c.lower)
    set_ = want != 0.0
    assert np.all(np.abs(got - want)[set_] <= (0.25 * np.abs(want) + 0.02 * span)[set_]), (
        got,
        want,
    )
    nominal, truth, fitted = (
        predict_intervals(rp, terms) for terms in ([], [(c, want)], [(c, got)])
    )
    assert np.linalg.norm(fitted - truth) <= 0.25 * np.linalg.norm(truth - nominal)
