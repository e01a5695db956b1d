"""Per-vehicle random generators as a table a compiled kernel reads without reference counts.

The closed loop draws each vehicle's noise from that vehicle's own ``numpy.random.Generator``
(so a flight is a function of its seed). A kernel can take Generators in a numba typed list,
but every ``gens[i]`` then copies the Generator's native form and takes and drops a
reference on its (separately allocated) reference count: about 35 ns per vehicle with the
batch in cache and 80 ns at 16,384 vehicles -- as much as a physics step of RKMK4. At one
physics step per call (an RL environment) that is paid once per vehicle-step.

A :class:`GeneratorTable` holds instead, per vehicle, the addresses numba's own unboxing of
a Generator reads (the bit generator's state and its ``next_uint64`` / ``next_uint32`` /
``next_double`` functions, ``BitGenerator.ctypes``), and keeps the Generators alive;
:func:`generator_at` rebuilds the Generator's native form from a row with no reference
count. The draws are numba's own ``Generator`` methods on the same bit-generator state:
the same numbers, in the same order, as drawing from the Generator itself (tested).
"""

from __future__ import annotations

import copy
import ctypes

import numpy as np

from quadfault.jit import _numba

#: the fields of a row: numba's ``NumPyRandomBitGeneratorType`` members, in its order
FIELDS = (
    "state_address",
    "state",
    "fnptr_next_uint64",
    "fnptr_next_uint32",
    "fnptr_next_double",
    "bit_generator",
)


class GeneratorTable(np.ndarray):
    """(N, 6) uint64 addresses of N Generators' bit generators (:data:`FIELDS`); the
    Generators themselves in :attr:`generators` (held: the addresses stay valid while the
    table lives). A kernel takes it as a plain array."""

    generators: list

    def __array_finalize__(self, obj):
        self.generators = getattr(obj, "generators", None)

    # a pickled or deep copy is the table of the copied generators (never these addresses)
    def __reduce__(self):
        return generator_table, (self.generators,)

    def __deepcopy__(self, memo):
        return generator_table(copy.deepcopy(self.generators, memo))

    def put(self, rows, generators) -> None:
        """Vehicles ``rows`` draw from ``generators`` from now on."""
        for i, g in zip(np.atleast_1d(np.asarray(rows, dtype=np.int64)).tolist(), generators):
            self[i] = _addresses(g)
            self.generators[i] = g


def _addresses(gen: np.random.Generator) -> tuple:
    c = gen.bit_generator.ctypes
    fn = lambda f: ctypes.cast(f, ctypes.c_void_p).value  # noqa: E731
    return (
        c.state_address,
        c.state.value,
        fn(c.next_uint64),
        fn(c.next_uint32),
        fn(c.next_double),
        c.bit_generator.value,
    )


def generator_table(generators) -> GeneratorTable:
    """The table of ``generators`` (one ``numpy.random.Generator`` per vehicle)."""
    generators = list(generators)
    for g in generators:
        if not isinstance(g, np.random.Generator):
            raise TypeError(
                f"a generator table holds numpy.random.Generator objects, got {type(g).__name__}"
            )
    out = np.array([_addresses(g) for g in generators], dtype=np.uint64).reshape(-1, 6)
    table = out.view(GeneratorTable)
    table.generators = generators
    return table


def generator_at_python(table: GeneratorTable, i: int) -> np.random.Generator:
    """Vehicle ``i``'s Generator (the interpreted loop's :func:`generator_at`)."""
    return table.generators[i]


def _compiled_generator_at():
    nb = _numba()
    if nb is None:
        return generator_at_python
    from numba.core import cgutils, types
    from numba.extending import intrinsic, register_jitable

    gen_type = nb.typeof(np.random.default_rng(0))
    bitgen_type = types.NumPyRandomBitGeneratorType("bit_generator")

    @intrinsic
    def _from_row(typingctx, row):
        """A Generator's native form from a row of addresses (no parent object, no
        reference count: the table's Generators own the state)."""

        def codegen(context, builder, sig, args):
            data = context.make_array(sig.args[0])(context, builder, args[0]).data
            bg = cgutils.create_struct_proxy(bitgen_type)(context, builder)
            bg.parent = cgutils.get_null_value(bg.parent.type)
            for k, name in enumerate(FIELDS):
                setattr(bg, name, builder.load(cgutils.gep(builder, data, k)))
            g = cgutils.create_struct_proxy(gen_type)(context, builder)
            g.bit_generator = bg._getvalue()
            g.meminfo = cgutils.get_null_value(g.meminfo.type)
            g.parent = cgutils.get_null_value(g.parent.type)
            return g._getvalue()

        return gen_type(row), codegen

    @register_jitable(inline="always")
    def generator_at(table, i):
        return _from_row(table[i])

    return generator_at


#: ``generator_at(table, i)``: vehicle ``i``'s Generator in a compiled kernel (for as long
#: as the table lives); interpreted, the table's own Generator
generator_at = _compiled_generator_at()

__all__ = ["FIELDS", "GeneratorTable", "generator_at", "generator_at_python", "generator_table"]
