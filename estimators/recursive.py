"""The Python side of the recursive estimators whose whole state is one compiled filter
(:mod:`estimators.rls`, :mod:`estimators.ukf`): sample checks, the offline loop over a
recording, and the batch of N filters the vector environment runs.

A recursive estimator module gives five compiled kernels over the flat state of
:class:`estimators.state.FlatState` (``offsets``, ``fs``, ``ks``) and its constants
``const``; all of them run the module's one step function on row ``i`` of the state:

* ``reset(const, offsets, n, fs, ks, rows, eta0)``: forget the rows, start them from ``eta0`` (N, n);
* ``update(t, p, v, R, w, f, const, offsets, fs, ks) -> code``: one sample into row 0;
* ``run(t, p, v, R, w, f, const, offsets, fs, ks, eta, sd, code)``: every row of a recording;
* ``update_rows(t, p, v, R, w, f, const, offsets, fs, ks, code)``: one sample per row, N rows;
* ``estimate(offsets, n, fs, ks, eta, sd)``: every row's estimate and sd (N, n) (NaN sd
  where the filter has none yet).

:class:`RecursiveEstimator` and :class:`BatchedRecursive` are the same wrappers for every
such module; a subclass names the kernels, the configuration class, the state's declared
layout (pieces, dimensions, counters) and its constants.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict

import numpy as np

from estimators.accelerometer import NO_ACCEL, recording_accel, warn_missing
from estimators.base import (
    STATUSES,
    BatchedEstimate,
    Estimate,
    EstimateSeries,
    Sample,
    batch_accel,
    batch_arrays,
    batch_eta0,
    check_num,
    command_limit,
    reset_rows,
    run_rows,
    sample_accel,
    sample_arrays,
)
from estimators.state import FlatState, Layout
from quadfault.errors import ConfigError
from quadfault.io.recording import Recording
from quadfault.model.vehicle import Vehicle

_ROW0 = np.zeros(1, dtype=np.int64)


def per_rotor(value, n: int, owner: str) -> np.ndarray:
    """One value or ``n`` values as ``n`` finite floats (clean error otherwise)."""
    try:
        out = np.broadcast_to(np.asarray(value, dtype=float), (n,)).copy()
    except (TypeError, ValueError):
        raise ConfigError(f"{owner} must be one value or {n}, got {value!r}") from None
    if not np.all(np.isfinite(out)):
        raise ConfigError(f"{owner} must be finite, got {value!r}")
    return out


def recording_arrays(recording: Recording, n: int, name: str):
    """``(t, p, v, R, w, f)`` of ``recording`` (never its truth), float64, contiguous;
    clean errors for what an estimator cannot run on. Non-finite rows are left to the
    estimator (``bad_sample``)."""
    if not isinstance(recording, Recording):
        raise ConfigError(f"run() needs a Recording, got {type(recording).__name__}")
    where = recording.path or "recording"
    if not recording.has_pose:
        raise ConfigError(
            f"{where}: the {name} estimator needs position, velocity and "
            "attitude columns (px..pz, vx..vz, qw..qz); this recording is "
            "IMU-only"
        )
    if len(recording) == 0:
        raise ConfigError(f"{where}: the recording is empty")
    if recording.thrust_cmd.shape[1] != n:
        raise ConfigError(
            f"{where}: {recording.thrust_cmd.shape[1]} rotor commands, the vehicle has {n} rotors"
        )
    return tuple(
        np.ascontiguousarray(a, dtype=np.float64)
        for a in (
            recording.t,
            recording.position,
            recording.velocity,
            recording.rotation,
            recording.omega,
            recording.thrust_cmd,
        )
    )


class _Kernels:
    """What a subclass names: the configuration class, the kernels, the state's declared
    layout and its constants."""

    name = ""
    config_class: type = object
    #: ``kernels()`` -> the module's (reset, update, run, update_rows, estimate)
    kernels: Callable[[], tuple]

    #: the float state's declared pieces (:class:`estimators.state.Layout`)
    floats: Layout = None

    @staticmethod
    def dims(n: int) -> dict:  # pragma: no cover - every subclass defines it
        """The layout's dimensions for ``n`` rotors (name -> int)."""
        raise NotImplementedError

    #: the int counters (:func:`estimators.state.fields`)
    counters = None

    @staticmethod
    def constants(vehicle: Vehicle, cfg) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    #: index in ``const`` of the command's upper clip [N] (the recording may lift it)
    fmax_index: int = None

    #: the kernels take the accelerometer reading after the command (``update(t, p, v, R,
    #: w, f, a, ...)``, ``a`` NaN where a sample has none) and the configuration has an
    #: ``accelerometer`` mode (:mod:`estimators.accelerometer`)
    reads_accel: bool = False

    def _setup(self, vehicle, config, num: int) -> None:
        cls = type(self).__name__
        if not isinstance(vehicle, Vehicle):
            raise ConfigError(f"{cls} needs a Vehicle, got {type(vehicle).__name__}")
        self.vehicle = vehicle
        self.config = self.config_class() if config is None else config
        if not isinstance(self.config, self.config_class):
            raise ConfigError(
                f"config must be a {self.config_class.__name__}, got {type(self.config).__name__}"
            )
        self.n_rotors = vehicle.n_rotors
        self._eta0_default = per_rotor(
            self.config.eta0, self.n_rotors, f"{self.config_class.__name__}.eta0"
        )
        self._const = self.constants(vehicle, self.config)
        self._state = FlatState(
            self.floats.shapes(**self.dims(self.n_rotors)),
            num,
            self.counters.size,
            self.floats.pieces,
        )
        (self._k_reset, self._k_update, self._k_run, self._k_rows, self._k_estimate) = (
            self.kernels()
        )
        self._said_missing = False  # the accelerometer asked for and missing: said once

    def describe(self) -> dict:
        """JSON-ready description of the configuration (for sidecars and reports)."""
        cfg = asdict(self.config)
        for k, v in cfg.items():
            if isinstance(v, tuple):
                cfg[k] = list(v)
        cfg["eta0"] = self._eta0_default.tolist()
        return cfg


class RecursiveEstimator(_Kernels):
    """One filter (implements :class:`estimators.base.OnlineEstimator`)."""

    def __init__(self, vehicle: Vehicle, config=None):
        self._setup(vehicle, config, 1)
        self._eta = np.empty((1, self.n_rotors))
        self._sd = np.empty((1, self.n_rotors))
        self.reset()

    def reset(self, eta0=None) -> None:
        """Forget everything; start from ``eta0`` (default: the configuration's)."""
        eta = self._eta0_default if eta0 is None else np.asarray(eta0, dtype=float)
        if eta.shape != (self.n_rotors,) or not np.all(np.isfinite(eta)):
            raise ConfigError(f"eta0 must be {self.n_rotors} finite values, got {eta0!r}")
        st = self._state
        self._k_reset(self._const, st.offsets, self.n_rotors, st.floats, st.ints, _ROW0, eta[None])

    def update(self, sample: Sample) -> Estimate:
        """One sample in (the command it carries is held until the next one); the estimate."""
        t, p, v, R, w, f = sample_arrays(sample, self.n_rotors, self.name)
        st = self._state
        if self.reads_accel:
            a = sample_accel(sample, self.name)
            if a is None:
                a = NO_ACCEL
                if self.config.accelerometer == "on" and not self._said_missing:
                    self._said_missing = True
                    warn_missing(self.name, f"the sample at t = {t}")
            args = (t, p, v, R, w, f, a)
        else:
            args = (t, p, v, R, w, f)
        code = self._k_update(*args, self._const, st.offsets, st.floats, st.ints)
        self._k_estimate(st.offsets, self.n_rotors, st.floats, st.ints, self._eta, self._sd)
        sd = None if np.isnan(self._sd[0, 0]) else self._sd[0].copy()
        return Estimate(t=t, eta=self._eta[0].copy(), sd=sd, status=STATUSES[code])

    def run(self, recording: Recording, progress: bool = False) -> EstimateSeries:
        """Estimates at every row of ``recording`` (the first row is ``warmup``), from the
        configuration's initial efficiency; the filter is left at the recording's end."""
        start = time.perf_counter()
        arrays = recording_arrays(recording, self.n_rotors, self.name)
        if self.reads_accel:
            arrays += (recording_accel(recording, self.config.accelerometer, self.name),)
        const = self._const.copy()
        const[self.fmax_index] = command_limit(recording, self.vehicle)
        self.reset()
        return run_filter(self, self._k_run, arrays, const, progress, start)


def run_filter(est, kernel, arrays, const, progress: bool, start: float) -> EstimateSeries:
    """The series of a single filter ``est`` (its ``_state``, ``n_rotors``, ``name`` and
    ``describe()``) over the recording's ``arrays`` (:func:`recording_arrays`): its ``run``
    kernel ``kernel(t, p, v, R, w, f, const, offsets, fs, ks, eta, sd, code)`` over chunks
    of rows (:func:`estimators.base.run_rows`); ``start`` is the ``time.perf_counter()`` of the call."""
    st = est._state
    eta, sd, code = run_rows(
        kernel, arrays, (const, st.offsets, st.floats, st.ints), est.n_rotors, est.name, progress
    )
    return EstimateSeries(
        t=arrays[0].copy(),
        eta=eta,
        sd=sd,
        status=np.asarray(STATUSES)[code],
        estimator=est.name,
        config=est.describe(),
        seconds=time.perf_counter() - start,
    )


class BatchedRecursive(_Kernels):
    """N filters updated together (one ``prange`` over the single filter's step): row i fed
    vehicle i's samples gives the single filter's estimates (:mod:`estimators.batched`)."""

    def __init__(self, vehicle: Vehicle, num: int, config=None):
        self._setup(vehicle, config, check_num(num))
        self.num = self._state.ints.shape[0]
        self._code = np.zeros(self.num, dtype=np.int64)
        self.reset()

    def reset(self, mask=None, eta0=None) -> None:
        """Forget the rows in ``mask`` (default all); start them from ``eta0`` ((n,) or
        (N, n), default the configuration's)."""
        rows = reset_rows(self.num, mask)
        n = self.n_rotors
        eta = batch_eta0(self._eta0_default if eta0 is None else eta0, self.num, n)
        st = self._state
        self._k_reset(self._const, st.offsets, n, st.floats, st.ints, rows, eta)

    def update(self, t, p, v, R, w, f, accel=None):
        """One sample per vehicle (``accel`` (N, 3): their accelerometer readings, or
        None); the :class:`estimators.base.BatchedEstimate`."""
        n = self.n_rotors
        t, p, v, R, w, f = batch_arrays(self.num, n, t, p, v, R, w, f)
        accel = batch_accel(self.num, accel)
        st = self._state
        args = (t, p, v, R, w, f)
        if self.reads_accel:
            if accel is None:
                if self.config.accelerometer == "on" and not self._said_missing:
                    self._said_missing = True
                    warn_missing(self.name, "a batch of samples")
                accel = np.full((self.num, 3), np.nan)
            args += (accel,)
        self._k_rows(*args, self._const, st.offsets, st.floats, st.ints, self._code)
        eta, sd = np.empty((self.num, n)), np.empty((self.num, n))
        self._k_estimate(st.offsets, n, st.floats, st.ints, eta, sd)
        return BatchedEstimate(t.copy(), eta, sd, self._code.copy())


__all__ = [
    "BatchedRecursive",
    "RecursiveEstimator",
    "per_rotor",
    "recording_arrays",
    "run_filter",
]
