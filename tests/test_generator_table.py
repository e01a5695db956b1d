"""The generator table: a kernel's draws through it are the Generators' own."""

import copy
import pickle

import numpy as np
import pytest

from quadfault.jit import jit
from quadfault.model.generator_table import generator_at, generator_at_python, generator_table


@jit
def _draws(table, rows, out):
    for r in range(rows.shape[0]):
        g = generator_at(table, rows[r])
        out[r, 0] = g.standard_normal()
        out[r, 1] = g.normal(0.0, 2.0)
        out[r, 2] = g.uniform(-1.0, 1.0)


def _expected(gens, rows):
    return np.array(
        [
            [gens[i].standard_normal(), gens[i].normal(0.0, 2.0), gens[i].uniform(-1.0, 1.0)]
            for i in rows
        ]
    )


def test_kernel_draws_equal_the_generators_and_advance_their_state():
    rows = np.array([3, 0, 3, 1, 2], dtype=np.int64)
    table = generator_table([np.random.default_rng(s) for s in range(4)])
    out = np.empty((len(rows), 3))
    _draws(table, rows, out)
    twins = [np.random.default_rng(s) for s in range(4)]
    np.testing.assert_array_equal(out, _expected(twins, rows))
    # the table's generators moved on: their next numbers follow the kernel's
    assert [g.standard_normal() for g in table.generators] == [g.standard_normal() for g in twins]


def test_put_swaps_a_vehicles_generator():
    table = generator_table([np.random.default_rng(s) for s in range(3)])
    table.put([1], [np.random.default_rng(42)])
    out = np.empty((3, 3))
    _draws(table, np.arange(3), out)
    twins = [np.random.default_rng(0), np.random.default_rng(42), np.random.default_rng(2)]
    np.testing.assert_array_equal(out, _expected(twins, range(3)))
    assert generator_at_python(table, 1) is table.generators[1]


def test_only_generators():
    with pytest.raises(TypeError, match="numpy.random.Generator"):
        generator_table([np.random.RandomState(0)])


@pytest.mark.parametrize("clone", [copy.deepcopy, lambda t: pickle.loads(pickle.dumps(t))])
def test_a_copy_draws_from_the_copied_generators(clone):
    table = generator_table([np.random.default_rng(s) for s in range(2)])
    twin = clone(table)
    assert twin.generators is not table.generators
    out = np.empty((2, 3))
    _draws(twin, np.arange(2), out)
    np.testing.assert_array_equal(
        out, _expected([np.random.default_rng(s) for s in range(2)], range(2))
    )
    # the original's generators did not move
    assert [g.standard_normal() for g in table.generators] == [
        np.random.default_rng(s).standard_normal() for s in range(2)
    ]
