"""Per-row tables of the functions of time for the vector env (reference, feed-forward rates,
true efficiency), filled in windows of control steps.

The reference trajectory, the controller's feed-forward rates and the efficiency schedule are
functions of time only. Evaluating them every control step costs one Python call per distinct
trajectory / schedule -- with random scenarios, one per sub-env. Instead each row keeps a window
of :data:`WINDOW` control steps: the reference and feed-forward at the step boundaries
``t = (k S) dt`` and the efficiency at the substeps ``t = (k S + j) dt``, evaluated with one
vectorised call per distinct trajectory (per distinct schedule) and window start, and the
feed-forward arithmetic of :meth:`~quadfault.model.controller.GeometricController.feedforward_rates`
over all refilled rows at once (its times hold the boundaries, so each trajectory is called
once). A row whose step leaves its window, or that was reset, is refilled.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from quad_fault_env.envs.episode_start import RowTrajectories
from quadfault.jit import jit, prange, set_threads
from quadfault.model.controller import ControllerConfig, GeometricController
from quadfault.model.scenarios import at_times
from quadfault.model.vehicle import Vehicle

#: control steps per window (at least)
WINDOW = 16
#: physics steps per window (at least): at a high control rate a window of WINDOW control steps
#: is short, and its refills' Python calls would cost more than the steps they serve
WINDOW_PHYSICS_STEPS = 64


def window_steps(substeps: int) -> int:
    """Control steps per window at ``substeps`` physics steps per control step: WINDOW, or
    more so that a window spans at least :data:`WINDOW_PHYSICS_STEPS` physics steps."""
    return max(WINDOW, -(-WINDOW_PHYSICS_STEPS // max(int(substeps), 1)))


_STALE = np.iinfo(np.int64).min // 2
#: from this many rows a refill of every row runs on the calling thread's numba threads
PARALLEL_MIN_ROWS = 1024


def row_groups(keys: np.ndarray):
    """``[(key, rows), ...]`` of an integer key array (rows sorted)."""
    order = np.argsort(keys, kind="stable")
    sk = keys[order]
    cuts = np.flatnonzero(np.diff(sk)) + 1
    return [(int(keys[idx[0]]), idx) for idx in np.split(order, cuts)]


@jit(_nrt=False)
def _fill_range(dst, src, lo, hi):
    for k in range(lo, hi):
        for i in range(dst.shape[1]):
            for j in range(dst.shape[2]):
                dst[k, i, j] = src[k, j]


@jit(parallel=True)
def _fill_parallel(dst, src):
    for k in prange(dst.shape[0]):
        _fill_range(dst, src, k, k + 1)


def fill_rows(dst: np.ndarray, src: np.ndarray) -> None:
    """``dst[k, i] = src[k]`` for every row ``i``: (K, N, m) C-contiguous from (K, m), on the
    calling thread's numba threads from :data:`PARALLEL_MIN_ROWS` rows (a refill of every
    row's window writes megabytes)."""
    src = np.ascontiguousarray(src, dtype=dst.dtype)
    if dst.shape[1] >= PARALLEL_MIN_ROWS and set_threads(None) > 1:
        _fill_parallel(dst, src)
    else:
        _fill_range(dst, src, 0, dst.shape[0])


def _as_rows(x, n: int) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    return np.broadcast_to(x, (n,) + x.shape[-1:])


class RowTimeTables:
    """Windows of the functions of time, one per row.

    Args:
        n_rows, substeps, dt: the vector env's N, physics substeps per control step and
            physics step [s].
        vehicle, controller: the nominal vehicle and the geometric controller's configuration
            (for the feed-forward rates).
        window: control steps per window (:data:`WINDOW`; the single env's one row takes
            longer windows: fewer refills).
    """

    def __init__(
        self,
        n_rows: int,
        substeps: int,
        dt: float,
        vehicle: Vehicle,
        controller: ControllerConfig,
        window: int = WINDOW,
        feedforward: bool = True,
    ):
        self.S, self.dt, self.window = int(substeps), float(dt), int(window)
        self.vehicle, self.config = vehicle, controller
        #: tabulate b1d and the feed-forward rates (rows 3-5: only a controller reads them)
        self.feedforward = bool(feedforward)
        n_rotors = vehicle.n_rotors
        self.k0 = np.full(n_rows, _STALE, dtype=np.int64)
        #: the physics step of each row's first efficiency row (``k0 S``; what the loop reads)
        self.first = np.full(n_rows, _STALE, dtype=np.int64)
        #: rows: position, velocity, acceleration, b1d, Omega_d, Omega_d' at the boundaries
        #: (without ``feedforward`` only the first three), ``refs[row, k]``: a view of a
        #: table stored step by step (a step's rows of every row side by side: the step reads
        #: them in one sweep over the rows, not one window's page per row)
        #: the same table step by step, ``by_step[k, row]`` (C-contiguous: what a kernel reads)
        self.by_step = np.zeros((self.window + 1, n_rows, 6 if self.feedforward else 3, 3))
        self.refs = self.by_step.transpose(1, 0, 2, 3)
        #: the true efficiency at the substeps, stored substep by substep like ``by_step``
        #: (``eta_by_step[j, row]``: a step reads one contiguous column of every row, not one
        #: cache line from each row's window); ``eta[row, j]`` is a view of it
        self.eta_by_step = np.zeros((self.window * self.S + 1, n_rows, n_rotors))
        self.eta = self.eta_by_step.transpose(1, 0, 2)
        self._rows = np.arange(n_rows)
        self._blocks: dict = {}  # (id, window start) -> (function, its window): _kept

    def invalidate(self, rows) -> None:
        """Forget the windows of ``rows`` (a reset changes their trajectory and schedule)."""
        self.k0[rows] = _STALE
        self.first[rows] = _STALE

    def ensure(
        self,
        k: np.ndarray,
        traj_key,
        sched_key,
        trajectories,
        schedules,
        last: int,
        idle: np.ndarray | None = None,
    ) -> None:
        """Make ``k - k0`` lie in ``[0, last]`` for every row (refilling the rows outside).

        A refilled row joins the others' place in their windows (``k - k0`` of most rows;
        ``idle`` (N,) bool: rows that do not step at the coming step, one place further), so
        a step reads one column of the tables for every row; its window's columns before its
        step ``k`` are never read (filled at t = 0). Rows whose windows all end refill from
        their own step.

        ``trajectories[key]`` / ``schedules[key]`` are the callables of ``traj_key`` /
        ``sched_key`` (N,). Each distinct schedule is evaluated once, on the windows of every
        step its rows refill from, and its rows copied to the rows that follow it; so is each
        distinct trajectory, unless the rows refill from few steps with many trajectories (a
        scenario drawn per row): then once per step, over its trajectories at once (one
        feed-forward call per step). The Python calls grow with the distinct functions of
        time, not with the rows.
        """
        off = k - self.k0
        stale = (off < 0) | (off > last)
        rows = np.flatnonzero(stale)
        if not len(rows):
            return
        live = off[~stale]
        place = np.zeros(len(rows), dtype=np.int64)
        if len(live):
            place += int(np.bincount(live).argmax())
        if idle is not None:
            place += idle[rows]
        place[place > last] = 0
        S, dt, W = self.S, self.dt, self.window
        kr = k[rows] - place  # each refilled row's window start
        keys = traj_key[rows]
        n_keys, n_starts = len(np.unique(keys)), len(np.unique(kr))
        n_pairs = len(np.unique(keys.astype(np.int64) * (1 << 32) + kr))
        if 2 * n_keys <= n_pairs + n_starts:  # one call per trajectory (and feed-forward)
            groups = [
                (rows[idx], [trajectories[key]], np.zeros(len(idx), dtype=np.int64), kr[idx])
                for key, idx in row_groups(keys)
            ]
        else:  # one call per step: its trajectories' feed-forward at once
            groups = []
            for k0, idx in row_groups(kr):
                items, inv = np.unique(keys[idx], return_inverse=True)
                groups.append(
                    (
                        rows[idx],
                        [trajectories[key] for key in items.tolist()],
                        inv.ravel(),
                        np.full(len(idx), k0, dtype=np.int64),
                    )
                )
        for r, items, item, k0s in groups:
            starts, inv = np.unique(k0s, return_inverse=True)
            t = (np.maximum(starts[:, None] + np.arange(W + 1), 0) * S) * dt  # t = (k S) dt
            block = self._kept(
                items, starts, lambda items=items, t=t: self._reference_block(items, t.ravel())
            )
            block = block.reshape(len(items), len(starts), W + 1, *block.shape[2:])
            c = block.shape[-2]
            if len(r) == len(self.k0) and block.shape[:2] == (1, 1) and c == self.by_step.shape[2]:
                fill_rows(self.by_step.reshape(W + 1, len(r), -1), block[0, 0].reshape(W + 1, -1))
            elif len(r) == len(self.k0) and block.shape[:2] == (1, 1):
                self.refs[:, :, :c] = block[0, 0]
            elif block.shape[:2] == (1, 1):
                self.refs[r, :, :c] = block[0, 0]
            else:
                self.refs[r, :, :c] = block[item, inv.ravel()]
        for key, idx in row_groups(sched_key[rows]):
            starts, inv = np.unique(kr[idx], return_inverse=True)
            tsub = np.maximum(starts[:, None] * S + np.arange(W * S + 1), 0) * dt  # (k S + j) dt
            eta = self._kept(
                [schedules[key]],
                starts,
                lambda fn=schedules[key], t=tsub: _as_rows(at_times(fn, t.ravel()), t.size),
            )
            eta = eta.reshape(len(starts), W * S + 1, -1)
            if len(idx) == len(self.k0) and len(starts) == 1:
                fill_rows(self.eta_by_step, eta[0])
            elif len(starts) == 1:
                self.eta[rows[idx]] = eta[0]
            else:
                self.eta[rows[idx]] = eta[inv.ravel()]
        self.k0[rows] = kr
        self.first[rows] = kr * S

    def _kept(self, items, starts: np.ndarray, make):
        """``make()``, the values of the functions of time ``items`` on the windows from
        ``starts``; kept for one function and one window start at or before step 0 (rows
        starting episodes of one scenario: each reset of it evaluates the same window)."""
        if len(items) != 1 or len(starts) != 1 or starts[0] > 0:
            return make()
        key = (id(items[0]), int(starts[0]))
        hit = self._blocks.get(key)
        if hit is None or hit[0] is not items[0]:
            if len(self._blocks) >= 4 * (self.window + 1):
                self._blocks.clear()
            hit = self._blocks[key] = (items[0], make())
        return hit[1]

    def _reference_block(self, items, ts: np.ndarray) -> np.ndarray:
        """(len(items), len(ts), 6 or 3, 3): the reference rows of each trajectory at ``ts``
        (with :attr:`feedforward`: b1d and the feed-forward rates too, over the trajectories
        at once)."""
        traj = RowTrajectories(items, np.arange(len(items)))
        block = np.zeros((len(items), len(ts), 6 if self.feedforward else 3, 3))
        if self.feedforward and self.config.angular_feedforward:  # its times hold ts
            h = self.config.ff_step
            ref = [x[:, :, 1] for x in traj(np.stack((ts - h, ts, ts + h), axis=-1))]
            ctrl = GeometricController(self.vehicle, traj, self.config)
            block[:, :, 4], block[:, :, 5] = ctrl.feedforward_rates(ts)
        else:
            ref = traj(ts)
        for c in range(block.shape[2] if block.shape[2] < 4 else 4):
            block[:, :, c] = ref[c]
        return block

    def references(self, k: np.ndarray, parts: int = 6) -> np.ndarray:
        """(N, parts, 3): the first ``parts`` reference rows at the start of step ``k`` (N,)
        (t = k S dt). When every row is at the same place of its window this is a view of
        the table: read it before the next :meth:`ensure`."""
        off = k - self.k0
        o = int(off[0])
        if (off == o).all():
            ref = self.refs[:, o]
        else:
            ref = self.refs[self._rows, off]
        return ref if parts == ref.shape[1] else ref[:, :parts]

    def efficiency_at(self, k: np.ndarray, j: int) -> np.ndarray:
        """(N, n) true efficiency at substep ``j`` of step ``k`` (N,) (``j = S``: its end), a
        copy."""
        col = (k - self.k0) * self.S + j
        c = int(col[0])
        if (col == c).all():
            return self.eta_by_step[c].copy()
        return self.eta_by_step[col, self._rows]

    def efficiency(self, k: np.ndarray) -> np.ndarray:
        """(N, S + 1, n) true efficiency at step ``k``'s substeps and at its end."""
        j = (k - self.k0)[:, None] * self.S + np.arange(self.S + 1)
        return self.eta[self._rows[:, None], j]


#: control steps per window of :class:`EpisodeTables` (one row: cheap to hold)
EPISODE_WINDOW = 64
_KEY0 = np.zeros(1, dtype=np.int64)


class StepRows(NamedTuple):
    """Views of one control step's rows of the time tables (read them before the next
    step)."""

    #: reference rows (position, velocity, acceleration, b1d, Omega_d, Omega_d') at the
    #: step's start (6, 3)
    start: np.ndarray
    #: the same rows at the step's end (6, 3)
    end: np.ndarray
    #: the true efficiency at the step's substeps and at its end (S + 1, n)
    eta: np.ndarray


class EpisodeTables:
    """The time tables of one episode (the single env): one row of :class:`RowTimeTables`
    whose window follows the control steps by itself.

    :meth:`at` gives a step's rows, refilling the window (from that step) when the step or its
    end lies outside it; :meth:`attach` lets a :class:`~quadfault.model.flight.Flight` fly the
    efficiency table, which the refills keep current.

    Args:
        scenario: the episode's :class:`~quadfault.model.scenarios.Scenario` (its trajectory
            and efficiency schedule).
        substeps, dt, vehicle, controller: as :class:`RowTimeTables`.
        window: control steps per window.
    """

    def __init__(
        self,
        scenario,
        substeps: int,
        dt: float,
        vehicle: Vehicle,
        controller: ControllerConfig,
        window: int = EPISODE_WINDOW,
    ):
        self.scenario = scenario
        self.tables = RowTimeTables(1, substeps, dt, vehicle, controller, window)

    def attach(self, flight) -> None:
        """Fly ``flight``'s vehicle with these tables' true efficiency."""
        flight.use_efficiency(self.tables.eta, self.tables.first)

    def at(self, k: int) -> StepRows:
        """Control step ``k``'s rows (its window refilled from ``k`` when needed)."""
        T, W, S = self.tables, self.tables.window, self.tables.S
        i = k - int(T.k0[0])
        if not 0 <= i < W:
            sc = self.scenario
            T.ensure(
                np.array([k], dtype=np.int64),
                _KEY0,
                _KEY0,
                [sc.trajectory],
                [sc.efficiency],
                W - 1,
            )
            i = k - int(T.k0[0])
        return StepRows(T.refs[0, i], T.refs[0, i + 1], T.eta[0, i * S : i * S + S + 1])


__all__ = [
    "EPISODE_WINDOW",
    "WINDOW",
    "WINDOW_PHYSICS_STEPS",
    "window_steps",
    "EpisodeTables",
    "RowTimeTables",
    "StepRows",
]


class InternTable:
    """Interned hashable objects (trajectories, efficiency schedules): object -> small int."""

    def __init__(self):
        self.items: list = []
        self.index: dict = {}

    def key(self, obj) -> int:
        try:
            k = self.index.get(obj)
        except TypeError:  # unhashable: one entry per object
            k = None
        if k is None:
            k = len(self.items)
            self.items.append(obj)
            try:
                self.index[obj] = k
            except TypeError:
                pass
        return k
