"""The effect protocol's defaults, the identifiability record and the parameter checks shared
by every effect class."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

import quadfault.model.effects.rows as rows
from quadfault import layout as named
from quadfault.errors import ConfigError
from quadfault.model.effects.chain import kernels


def vector(value, n, what) -> tuple:
    """``value`` as ``n`` finite floats (a scalar is repeated); a one-line error otherwise."""
    try:
        arr = np.asarray(value, dtype=float).ravel()
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be numeric, got {value!r}") from None
    if arr.size == 1 and n > 1:
        arr = np.repeat(arr, n)
    if arr.size != n or not np.all(np.isfinite(arr)):
        raise ConfigError(f"{what} needs {n} finite values, got {value!r}")
    return tuple(float(x) for x in arr)


def number(value, what, lo=-np.inf, hi=np.inf, *, open_lo=False) -> float:
    """``value`` as a finite float in ``[lo, hi]`` (``(lo, hi]`` with ``open_lo``)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be a number, got {value!r}") from None
    low_ok = x > lo if open_lo else x >= lo
    if not (np.isfinite(x) and low_ok and x <= hi):
        raise ConfigError(
            f"{what} must be in {'(' if open_lo else '['}{lo:g}, {hi:g}], got {value!r}"
        )
    return x


#: recording channel groups an :class:`Identifiability` names -> the recording columns
#: (``quadfault-recording/1``) each stands for
CHANNELS = {
    "position": ("px", "py", "pz"),
    "velocity": ("vx", "vy", "vz"),
    "attitude": ("qw", "qx", "qy", "qz"),
    "body_rate": ("wx", "wy", "wz"),
    "accelerometer": ("ax", "ay", "az"),
    "battery": ("vbat",),
    "rotor_speed": ("omega1", "omega2", "omega3", "omega4"),
}


#: the nominal vehicle's constants an importer may assume (a sidecar's ``assumed`` list)
ASSUMABLE = ("mass", "inertia", "geometry", "torque_coefficient")


@dataclass(frozen=True)
class Identifiability:
    """What a recording needs for an effect to be identifiable from it (a declaration: the
    diagnosis' gate reads it and skips, with a reason, the effects a log cannot reveal).

    Attributes:
        channels: channel groups (keys of :data:`CHANNELS`) that must all be present and
            valid, e.g. ``("velocity",)`` for a force against the velocity.
        any_of: alternatives: at least one of these channel groups must be present (empty:
            no alternative needed).
        min_command_rate: lowest rate of the commands (or of the measured rotor speeds, when
            ``direct`` names them) at which the effect can show [Hz]; None: any rate.
        timescale: the reported parameter key (e.g. ``"tau_s"``) of a time the samples must
            resolve: a value shorter than about one command interval cannot be told from
            zero (None: the effect has no time scale).
        direct: channel groups that show the effect directly (e.g. measured rotor speeds
            show a motor lag without going through the body's response).
        excitation: what the flight must do for the effect to show (free text, empty: any
            flight).
        note: one line for a user: why these channels.
        scales_with: the nominal vehicle's constants its fitted value scales with (of
            :data:`ASSUMABLE`), so a result rests on them when a log's importer assumed them
            (ratios between rotors and time constants scale with none).
    """

    channels: tuple = ()
    any_of: tuple = ()
    min_command_rate: float | None = None
    timescale: str | None = None
    direct: tuple = ()
    excitation: str = ""
    note: str = ""
    scales_with: tuple = ()

    def __post_init__(self):
        for group in (*self.channels, *self.any_of, *self.direct):
            if group not in CHANNELS:
                raise ValueError(
                    f"unknown channel group {group!r}; choose from {', '.join(CHANNELS)}"
                )
        for const in self.scales_with:
            if const not in ASSUMABLE:
                raise ValueError(
                    f"unknown vehicle constant {const!r}; choose from {', '.join(ASSUMABLE)}"
                )

    def columns(self) -> tuple:
        """The recording columns :attr:`channels` stands for."""
        return tuple(c for group in self.channels for c in CHANNELS[group])


#: the pose channels a force in the world frame needs
POSE = ("position", "velocity", "attitude")


class Effect:
    """An unmodelled physical effect of the true plant: the one effect type, with default
    (no-op) plant hooks. The built-in effects are frozen dataclasses deriving it, one module
    each (the registry, :mod:`quadfault.model.effects.registry`, lists them); an effect
    written in Python may derive it too, or be any object with these methods.

    Protocol (called by :class:`quadfault.model.plant.Plant`): ``reset(n_rotors)`` at the start of a
    flight; ``rotor_thrust(f, t, dt, state)`` once per physics step (produced rotor thrusts
    [N] for the step starting at ``t``); ``wrench(state, f, t)`` at every integrator stage
    (extra force, world [N], and moment, body [N m]); ``true_vehicle(vehicle)`` once at reset
    (the rigid body the plant flies; the controller and the recording keep the nominal one).

    Class attributes: ``name`` (canonical snake_case), ``order`` (the canonical position of
    the effect in the chain command -> thrust -> wrench -> body, used to sort a model's
    effects so that it means the same physics as the diagnosis' library),
    ``identifiability`` (:class:`Identifiability`: what a recording needs to reveal it),
    ``explanation`` (one line the diagnosis reports), ``equivalent`` (the class of effects
    the data cannot always tell it from, or None) and the ``--effect`` syntax: ``values``
    (the allowed counts of positional values), ``syntax`` (their meaning, for errors) and
    ``options`` (keyword options -> type); :meth:`from_values` maps them to the fields;
    ``parameter`` names the field of a one-parameter effect and its reported key;
    ``example`` is a spec the diagnosis recovers from a short simulated flight (the registry's
    test flies every one).
    """

    name: ClassVar[str] = ""
    order: ClassVar[int] = 0
    identifiability: ClassVar[Identifiability] = Identifiability()
    explanation: ClassVar[str] = ""
    equivalent: ClassVar[str | None] = None
    values: ClassVar[tuple] = (1,)
    syntax: ClassVar[str] = ""
    example: ClassVar[str] = ""
    options: ClassVar[dict] = {}
    #: ``(field, reported key)`` of a one-parameter effect: the defaults of :meth:`params`,
    #: :meth:`from_params` and :meth:`from_values` then serve (one value, or a tuple field)
    parameter: ClassVar[tuple | None] = None

    def reset(self, n_rotors: int) -> None:
        pass

    def rotor_thrust(self, f, t, dt, state):
        return f

    def wrench(self, state, f, t):
        return np.zeros(np.shape(state.p)), np.zeros(np.shape(state.w))

    def true_vehicle(self, vehicle):
        return vehicle

    def params(self) -> dict:
        """The parameters the diagnosis reports, by key (a tuple field as a list)."""
        field, key = self._parameter()
        value = getattr(self, field)
        return {key: list(value) if isinstance(value, tuple) else value}

    @classmethod
    def from_params(cls, params: dict) -> Effect:
        """The effect from its ``params()`` (the keys the diagnosis reports)."""
        field, key = cls._parameter()
        return cls(**{field: param(params, key, cls.name)})

    @classmethod
    def from_values(cls, values: list, options: dict) -> Effect:
        """The effect from the ``--effect`` syntax: positional ``values`` (a count allowed
        by :attr:`values`) and keyword ``options`` (checked against :attr:`options`)."""
        field, _ = cls._parameter()
        return cls(**{field: values[0] if cls.values == (1,) else tuple(values)}, **options)

    @classmethod
    def _parameter(cls) -> tuple:
        """``(field, reported key)`` of a one-parameter effect (:attr:`parameter`); an effect
        with several parameters overrides :meth:`params`, :meth:`from_params` and
        :meth:`from_values` instead."""
        if cls.parameter is None:
            raise NotImplementedError(
                f"effect {cls.name}: declare `parameter` or override "
                "params / from_params / from_values"
            )
        return cls.parameter

    @classmethod
    def candidate(cls, ctx):
        """The diagnosis' candidate of this effect for a recording
        (:class:`~quadfault.model.effects.candidate.LibraryContext`), bounds scaled to its
        nominal vehicle."""
        raise NotImplementedError

    @classmethod
    def fit_note(cls, params: dict, selected) -> str:
        """Sentences the diagnosis adds to this effect's explanation when it is accepted with
        the reported ``params`` beside the ``selected`` effect names ("" for none)."""
        return ""

    def describe(self) -> dict:
        """JSON-able ``{"name", "params"}`` (stored as truth in a recording's meta)."""
        return {"name": self.name, "params": self.params()}


#: the physics step a standalone effect's chain is built for when ``wrench`` comes first [s]
_STANDALONE_DT = 1e-3


class Compiled(Effect):
    """An effect with an entry in the compiled effect chain (:mod:`quadfault.model.effects.chain`).

    Its module declares the entry's layout by name (:func:`quadfault.layout.fields`):
    ``PARAMETERS``, the parameters the kernels read (an entry named like a field of the
    dataclass takes that field's value; :meth:`parameters` gives the others), and
    ``MEMORY``, the vehicle's memory the kernels keep from step to step (zeros at a flight's
    start). Its kernels read both by name: ``thrust_step`` (the thrust stage, once per
    physics step: the rotors' thrusts in, as a tuple, the new tuple out;
    :mod:`quadfault.model.effects.kernels`) and/or ``wrench_term`` with ``wrench_stage``
    (the step's numbers, then the force and moment at each RK stage). :meth:`pack` lays the
    parameters out from the declaration. The closed loop runs that entry compiled, from the
    plant's rows; the protocol methods here run the same entry for one vehicle from Python
    (its memory -- lag, delay, gusts -- kept on the object from one call to the next and
    cleared by ``reset``). ``rotor_thrust`` takes the loop's generator as ``gen`` (a wind
    without a seed draws its gusts from it; alone, from a generator seeded 0)."""

    @classmethod
    def layouts(cls) -> tuple:
        """``(PARAMETERS, MEMORY)``: the entry's declared layouts (its module's)."""
        module = kernels(cls)
        return module.PARAMETERS, getattr(module, "MEMORY", NO_MEMORY)

    def parameters(self, n_rotors: int, dt: float, yaw_signs=None) -> dict:
        """The values of the ``PARAMETERS`` entries by name on a vehicle with ``n_rotors``
        flown at physics step ``dt`` [s] (``yaw_signs``: the flown rotors' yaw-torque
        signs); by default each entry's dataclass field. An effect with derived entries
        overrides this."""
        rows, _ = self.layouts()
        return {key: getattr(self, key) for key in rows._fields[:-1]}

    def memory_rest(self, values: dict, n_rotors: int) -> int:
        """The length of an open (``REST``) last ``MEMORY`` entry for these parameter
        ``values`` (0: none)."""
        return 0

    def pack(self, n_rotors: int, dt: float, yaw_signs=None) -> tuple[tuple, int]:
        """``(parameters, memory slots)`` of this effect's entry on a vehicle with
        ``n_rotors`` flown at physics step ``dt`` [s] (``yaw_signs``: the flown rotors'
        yaw-torque signs), laid out as its module declares."""
        rows, memory = self.layouts()
        values = self.parameters(n_rotors, dt, yaw_signs)
        try:
            x = named.pack(rows, n_rotors, **values)
        except ConfigError as e:
            raise ConfigError(f"effect {self.name}: {e}") from None
        return tuple(x.tolist()), named.size(memory, n_rotors, self.memory_rest(values, n_rotors))

    @classmethod
    def stream_seed(cls, params) -> int | None:
        """The seed of the entry's own random stream (``params``: its parameters), or None
        when it draws from the vehicle's generator (or never)."""
        return None

    @classmethod
    def lost(cls, memory) -> bool:
        """Whether the entry (``memory``: its memory slots) lost history it needed."""
        return False

    def reset(self, n_rotors: int) -> None:
        for key in ("_single", "_fallback"):
            self.__dict__.pop(key, None)

    def _yaw_signs(self, n_rotors: int):
        return None

    def chain(self, n_rotors: int, dt: float):
        """This effect's one-vehicle chain (:class:`quadfault.model.effects.rows.Single`), built at
        the first call after ``reset``."""
        single = self.__dict__.get("_single")
        if single is None:
            single = rows.single(self, n_rotors, dt, self._yaw_signs(n_rotors))
            self.__dict__["_single"] = single  # frozen dataclass: memory beside the fields
            self.__dict__["_fallback"] = np.random.default_rng(0)
        return single

    def memory(self) -> dict | None:
        """The entry's memory now, by name (:func:`quadfault.layout.unpack`; None before the
        first step of a flight)."""
        single = self.__dict__.get("_single")
        if single is None:
            return None
        return named.unpack(self.layouts()[1], single.rows.memory[0, single.rows.mem[0, 0] :])

    def rotor_thrust(self, f, t, dt, state, gen=None):
        out = np.array(f, dtype=float).ravel()
        single = self.chain(len(out), dt)
        single.rotor_thrust(
            out,
            t,
            dt,
            state.p,
            state.v,
            state.R,
            state.w,
            self.__dict__["_fallback"] if gen is None else gen,
        )
        return out

    def wrench(self, state, f, t):
        F, M = self.chain(len(np.ravel(f)), _STANDALONE_DT).wrench(
            state.p, state.v, state.R, state.w, f, t
        )
        return np.array(F), np.array(M)

    def __getstate__(self):  # the memory stays behind (a copy starts a new flight)
        return {k: v for k, v in self.__dict__.items() if k not in ("_single", "_fallback")}


#: the memory of an entry that keeps none
NO_MEMORY = named.fields("NoMemory")


def param(params: dict, key: str, name: str):
    """``params[key]``, or a one-line error naming the effect and the key."""
    if not isinstance(params, dict) or key not in params:
        raise ConfigError(f"effect {name}: params need {key!r}")
    return params[key]
