"""A new effect written the way docs/effects.md ("Writing a new effect") says: one module and
one registry row. The module below declares its layout by name, its kernel reads every
value by that name, and the simulator flies it compiled -- one vehicle, and a batch with
per-vehicle parameters -- with the physics a numpy oracle gives."""

import ast
import hashlib
import importlib
import sys
import textwrap

import numpy as np
import pytest

from quadfault.model.effects import registry

#: the newcomer's module: rotors that wear with the impulse they deliver,
#: ``f_i' = f_i (1 - k W_i)``, ``W_i`` the impulse of rotor i so far [N s]
MODULE = '''
"""``rotor_wear``: each rotor loses thrust with the impulse it delivered."""

from dataclasses import dataclass
from typing import ClassVar

from quadfault.jit import jit
from quadfault.layout import ROTORS, fields
from quadfault.model.effects.base import Compiled, number
from quadfault.model.effects.kernels import replaced

PARAMETERS = fields("RotorWearParameters", "rate")
MEMORY = fields("RotorWearMemory", ("impulse", ROTORS))


@jit(inline="always")
def thrust_step(x, q, f, t, dt, p, gen, streams, i):
    """Each thrust times ``1 - rate W``; then the step's impulse added to ``W``."""
    out = f
    for r in range(len(f)):
        y = f[r] * (1.0 - x[PARAMETERS.rate] * q[MEMORY.impulse + r])
        q[MEMORY.impulse + r] += y * dt
        out = replaced(out, r, y)
    return out


@dataclass(frozen=True)
class RotorWear(Compiled):
    """Thrust lost per unit of impulse delivered, ``rate`` [1/(N s)]."""

    rate: float = 0.01
    name: ClassVar[str] = "rotor_wear"
    order: ClassVar[int] = 2
    syntax: ClassVar[str] = "RATE [1/(N s)]"
    parameter: ClassVar[tuple] = ("rate", "rate_per_N_s")

    def __post_init__(self):
        number(self.rate, "rotor_wear rate [1/(N s)]", 0.0, 1.0)
'''


#: the module's name, after its text (numba's cache keeps the loops compiled for its
#: effect under this name: an edited module is another one)
NAME = "newcomer_wear_" + hashlib.sha256(MODULE.encode()).hexdigest()[:12]


@pytest.fixture
def wear(tmp_path, monkeypatch):
    """The newcomer's module imported, and its one registry row added."""
    (tmp_path / f"{NAME}.py").write_text(textwrap.dedent(MODULE), encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module(NAME)
    cls = module.RotorWear
    monkeypatch.setattr(registry, "TABLE", registry.TABLE + (cls,))
    monkeypatch.setitem(registry.EFFECTS, cls.name, cls)
    yield module
    sys.modules.pop(NAME, None)


def test_the_kernel_names_every_value_it_reads():
    """Every index into the parameters ``x`` or the memory ``q`` starts from a declared name."""
    tree = ast.parse(textwrap.dedent(MODULE))
    kernel = next(n for n in tree.body if isinstance(n, ast.FunctionDef))
    reads = [n for n in ast.walk(kernel) if isinstance(n, ast.Subscript)]
    into = [n for n in reads if isinstance(n.value, ast.Name) and n.value.id in ("x", "q")]
    assert len(into) == 3
    for n in into:
        names = {a.value.id for a in ast.walk(n.slice) if isinstance(a, ast.Attribute)}
        assert names & {"PARAMETERS", "MEMORY"}, ast.unparse(n)


def test_the_layout_gives_pack_and_the_widths(wear):
    effect = wear.RotorWear(0.02)
    assert effect.pack(4, 1e-3) == ((0.02,), 4)  # the rate; one impulse per rotor
    assert effect.pack(6, 1e-3) == ((0.02,), 6)
    assert effect.params() == {"rate_per_N_s": 0.02}


def _oracle(f_cmd, rate, dt, steps):
    out, impulse = [], np.zeros_like(f_cmd)
    for _ in range(steps):
        y = f_cmd * (1.0 - rate * impulse)
        impulse = impulse + y * dt
        out.append(y)
    return np.array(out)


def test_the_python_protocol_runs_the_compiled_entry(wear):
    """``rotor_thrust`` from Python runs the entry, its memory kept between calls."""
    from quadfault.model.dynamics import RigidBodyState

    effect, dt = wear.RotorWear(0.05), 0.01
    state = RigidBodyState(np.zeros(3), np.zeros(3), np.eye(3), np.zeros(3))
    f = np.array([2.0, 2.5, 3.0, 3.5])
    got = [effect.rotor_thrust(f, k * dt, dt, state) for k in range(50)]
    np.testing.assert_allclose(got, _oracle(f, 0.05, dt, 50), rtol=1e-13)
    np.testing.assert_allclose(effect.memory()["impulse"], np.sum(got, axis=0) * dt, rtol=1e-12)
    effect.reset(4)
    np.testing.assert_array_equal(effect.rotor_thrust(f, 0.0, dt, state), f)


@pytest.mark.slow
def test_the_simulator_flies_it_compiled_one_vehicle_and_a_batch(wear):
    """A worn vehicle sinks below the nominal one at a hover command; a batch flies each
    vehicle's own rate, and a vehicle with rate 0 flies as without the effect."""
    from quadfault.model import closed_loop
    from quadfault.model.effects import rows
    from quadfault.model.plant import Plant
    from quadfault.model.sensors import SensorNoise
    from quadfault.model.vehicle import Vehicle

    vehicle, dt, steps = Vehicle(), 1e-3, 400
    plant = Plant(vehicle, effects=(wear.RotorWear(0.05),), dt=dt, n_vehicles=3)
    plant.assign([1], (wear.RotorWear(0.0),))
    plant.assign([2], ())
    assert isinstance(plant.hook, rows.C.EffectRows)  # compiled, not the interpreted loop
    V = plant.vehicles
    V.f_cmd[:] = vehicle.hover_thrust
    N = len(V.p)
    C = closed_loop.constants(plant, SensorNoise())
    T = closed_loop.Tables(np.zeros(N, np.int64), np.ones((N, steps, 4)), np.zeros((N, 0, 6, 3)))
    gens = closed_loop.generators([np.random.default_rng(k) for k in range(N)])
    closed_loop.sense_rows(gens, np.arange(N), C, V)
    done = closed_loop.fly_batch(
        gens,
        np.ones(N, bool),
        np.zeros(N, np.int64),
        steps,
        True,
        C,
        V,
        T,
        closed_loop.Records.none(N, 4),
        fx=plant.hook,
    )
    assert list(done) == [steps] * N
    np.testing.assert_allclose(V.f[0], _oracle(V.f_cmd[0], 0.05, dt, steps)[-1], rtol=1e-12)
    np.testing.assert_array_equal(V.p[1], V.p[2])  # rate 0 == no effect
    assert V.p[0, 2] > V.p[1, 2] + 1e-4  # NED: the worn vehicle sinks
