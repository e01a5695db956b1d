"""Named layouts (quadfault.layout): start rows derived from declared counts, packing and
unpacking by name, the open counts (one value per rotor, or any length) bound at packing."""

import numpy as np
import pytest

from quadfault.errors import ConfigError
from quadfault.layout import REST, ROTORS, fields, pack, size, unpack


def test_a_per_rotor_entry_is_sized_by_the_rotor_count():
    rows = fields("Memory", "started", ("gust", 3), ("thrust", ROTORS))
    assert (rows.started, rows.gust, rows.thrust, rows.size) == (0, 1, 4, 4)
    assert size(rows, n_rotors=6) == 10
    out = pack(rows, n_rotors=6, started=1.0, gust=(1, 2, 3), thrust=np.arange(6.0))
    np.testing.assert_array_equal(out, [1, 1, 2, 3, 0, 1, 2, 3, 4, 5])
    back = unpack(rows, out)
    assert back["started"] == 1.0 and list(back["gust"]) == [1, 2, 3]
    assert list(back["thrust"]) == [0, 1, 2, 3, 4, 5]
    with pytest.raises(ConfigError, match="Memory.thrust: 4 values expected, got 6"):
        pack(rows, n_rotors=4, started=1.0, gust=(1, 2, 3), thrust=np.arange(6.0))
    with pytest.raises(ConfigError, match="needs the rotor count"):
        size(rows)


def test_open_counts_are_last_only_and_fixed_layouts_have_their_size():
    with pytest.raises(ValueError, match="only the last"):
        fields("Bad", ("thrust", ROTORS), "a")
    with pytest.raises(ValueError, match="positive int"):
        fields("Bad", ("a", -1))
    fixed = fields("Fixed", "a", ("b", 2))
    assert size(fixed, n_rotors=4) == size(fixed) == 3
    knots = fields("Knots", "head", ("knots", REST))
    assert size(knots, rest=7) == 8
