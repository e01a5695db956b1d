"""The vector env's step as one compiled call over the sub-envs.

Per sub-env ``i`` of :class:`~quad_fault_env.vector.QuadFaultVectorEnv`, :func:`step_vehicle`
runs what the single env's ``step`` runs, in its order, with the definitions it uses:

    action -> commands   :func:`~quad_fault_env.envs.config.action_commands_row` (residual
                         mode: the geometric controller on the measurement first)
    physics              :func:`quadfault.model.closed_loop.fly_vehicle`, the substeps of
                         one control step (sensors, motors, effects, RKMK4)
    termination          :func:`~quad_fault_env.envs.config.termination_code` on the truth
    truncation           the scenario's duration, ``max_episode_steps``
    measurement          the end-of-step sensors (a terminated vehicle shows its truth)
    reward               :func:`~quad_fault_env.envs.config.reward_row`
    observation          :func:`~quad_fault_env.observation.observation_row`

A sub-env that ended at the previous step (gymnasium's next-step autoreset) was reset before
the call: it flies nothing, earns 0, and its observation is the reset one. The functions of
time come from the env's per-row windows (:mod:`quad_fault_env.time_tables`); the call counts
the rows whose next step leaves its window, so the env refills tables only when some do.

Threads: from :data:`PARALLEL_MIN_VEHICLES` vehicles on, and when the calling thread may use
more than one numba thread (``quadfault.jit.threads``), the vehicles run in tasks of
:data:`CHUNK` that the threads claim one after the other (an atomic counter: a thread slowed
by another process on its core takes fewer); below, on the calling thread (a parallel launch
costs more than it saves). The flights are the same either way: each vehicle draws from its
own generator.

Someone changing what the env computes changes the row functions named above, each in its
own module; this module only strings them together.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from quad_fault_env.envs.config import (
    action_commands_row,
    reward_row,
    row3,
    row33,
    termination_code,
)
from quad_fault_env.observation import observation_row
from quadfault.jit import _numba, jit, prange
from quadfault.model.closed_loop import fly_vehicle, measure_vehicle
from quadfault.model.controller import (
    controller_tuples,
    geometric_control,
    rotor_commands,
)
from quadfault.model.generator_table import generator_at

#: vehicles per task of the parallel step (each thread claims the next task when done)
CHUNK = 256
#: below this many vehicles the step runs on the calling thread
PARALLEL_MIN_VEHICLES = 512
#: ``StepConstants.estimate``: the estimate arrays are left as they are (the nominal belief,
#: or a batched estimator updated after the call) / the oracle: the true efficiency
ESTIMATE_KEPT, ESTIMATE_TRUTH = 0, 1


class StepConstants(NamedTuple):
    """What is fixed over the env's life (scalars and arrays only: a ``prange`` takes no
    tuple inside a tuple; the row functions' tuples are formed inside the call)."""

    substeps: int  # physics steps per control step
    mode: int  # the action mode's index in ACTION_MODES; -1: commands set by the caller
    compensate: bool
    residual_scale: float
    moment_scale: np.ndarray  # (3,)
    f_max: float  # the nominal rotor limit of the action mapping [N]
    allocation_inverse: np.ndarray  # (n, 4) nominal
    reward: np.ndarray  # (6,) RewardConfig.params
    limits: np.ndarray  # (3,) TerminationLimits.params
    at: np.ndarray  # the observation's slot starts, bounds and fills (ObservationLayout)
    low: np.ndarray
    high: np.ndarray
    fill: np.ndarray
    estimate: int  # ESTIMATE_KEPT / ESTIMATE_TRUTH
    j_last: int  # the oracle's substep (the estimator's last sample of a step)
    limit_steps: int  # max_episode_steps (a huge number without one)
    window: int  # control steps per time-table window
    observe: bool  # write the observations (False: the env writes them after its estimator)
    next_step: bool  # next-step autoreset: mark the sub-envs that end for a reset


class StepRows(NamedTuple):
    """The per-sub-env arrays the step reads and updates."""

    action: np.ndarray  # (N, 4) the checked actions
    steps: np.ndarray  # (N,) control steps of the episode (updated)
    max_steps: np.ndarray  # (N,) the scenario's duration in control steps
    resetting: np.ndarray  # (N,) bool: reset before this call (next-step autoreset)
    table_k0: np.ndarray  # (N,) the control step of each row's window start
    refs: np.ndarray  # (window + 1, N, 3 or 6, 3) references at the steps' starts, step by step
    eta_table: np.ndarray  # (N, window S + 1, n) true efficiency at the substeps
    eta_hat: np.ndarray  # (N, n) the estimate (updated by the oracle)
    eta_sd: np.ndarray  # (N, n)
    times: np.ndarray  # (N, records) the times of the records the estimator reads [s]


class StepOut(NamedTuple):
    """What the step writes per sub-env."""

    code: np.ndarray  # (N,) termination code (REASONS; 0: none)
    terminated: np.ndarray  # (N,) bool
    truncated: np.ndarray  # (N,) bool
    reward: np.ndarray  # (N,)
    obs: np.ndarray  # (N, size) float32


@jit(inline="always")
def _ref3(refs, i, k, c):
    """Reference row ``c`` (0 position, 1 velocity, 2 acceleration) of sub-env ``i`` at its
    window's step ``k``, 3 numbers."""
    return (refs[k, i, c, 0], refs[k, i, c, 1], refs[k, i, c, 2])


@jit(inline="always")
def _reference_row(refs, i, k):
    """Sub-env ``i``'s six reference rows at its window's step ``k`` as the 3-tuples of
    ``geometric_control`` (as ``controller.reference_row`` reads a row's own table)."""
    return (
        _ref3(refs, i, k, 0),
        _ref3(refs, i, k, 1),
        _ref3(refs, i, k, 2),
        _ref3(refs, i, k, 3),
        _ref3(refs, i, k, 4),
        _ref3(refs, i, k, 5),
    )


@jit(inline="always")
def _minus3(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@jit(inline="always")
def observe_vehicle(i, S, R, V, obs):
    """Sub-env ``i``'s observation at its step ``R.steps[i]`` into ``obs[i]``."""
    k = R.steps[i] - R.table_k0[i]
    observation_row(
        _minus3(row3(V.mp, i), _ref3(R.refs, i, k, 0)),
        _minus3(row3(V.mv, i), _ref3(R.refs, i, k, 1)),
        row33(V.mR, i),
        row3(V.mw, i),
        R.eta_hat[i],
        R.eta_sd[i],
        _ref3(R.refs, i, k, 2),
        (S.at, S.low, S.high, S.fill),
        obs[i],
    )


@jit(inline="always")
def _carried_records(i, V, rec):
    """The estimator's records of a vehicle that flies nothing: its carried measurement."""
    for r in range(rec.p.shape[1]):
        for k in range(3):
            rec.p[i, r, k] = V.mp[i, k]
            rec.v[i, r, k] = V.mv[i, k]
            rec.w[i, r, k] = V.mw[i, k]
            for m in range(3):
                rec.R[i, r, k, m] = V.mR[i, k, m]
        for m in range(V.f_cmd.shape[1]):
            rec.f_cmd[i, r, m] = V.f_cmd[i, m]


@jit(inline="always")
def _commands(i, S, R, K, V, row):
    """Sub-env ``i``'s rotor commands from its action into ``V.f_cmd[i]`` (residual mode:
    the geometric controller on the measurement first)."""
    f_cmd = V.f_cmd[i]
    if K is not None:
        gains, nominal = controller_tuples(K)
        u = geometric_control(
            row3(V.mp, i),
            row3(V.mv, i),
            row33(V.mR, i),
            row3(V.mw, i),
            _reference_row(R.refs, i, row),
            gains,
            nominal,
        )
        rotor_commands(u[0], u[1], K.allocation_inverse, f_cmd, K.yaw_release)
    ms = S.moment_scale
    action_commands_row(
        R.action[i],
        f_cmd,  # the controller's commands (each read before it is overwritten)
        R.eta_hat[i],
        (S.mode, S.compensate, S.residual_scale, (ms[0], ms[1], ms[2])),
        S.f_max,
        S.allocation_inverse,
        f_cmd,
    )


@jit(inline="always")
def step_vehicle(i, S, R, Out, K, gens, C, V, T, rec, fx, k_phys, dt):
    """Sub-env ``i``'s control step (see the module docstring); returns whether its next step
    leaves its time-table window, and whether its episode ended (0 or 1 each)."""
    k = R.steps[i]
    ended = False
    if R.resetting[i]:  # reset before the call: its reset observation, nothing flown
        Out.code[i], Out.terminated[i], Out.truncated[i], Out.reward[i] = 0, False, False, 0.0
        _carried_records(i, V, rec)
    else:
        row = k - R.table_k0[i]
        if S.mode >= 0:
            _commands(i, S, R, K, V, row)
        k0 = k_phys[i]
        for r in range(R.times.shape[1]):
            R.times[i, r] = (k0 + r * rec.stride) * dt
        fly_vehicle(i, gens, k0, k0 + S.substeps, False, C, None, V, T, rec, fx, None)
        k_phys[i] = k0 + S.substeps
        if S.estimate == ESTIMATE_TRUTH:
            for m in range(R.eta_hat.shape[1]):
                R.eta_hat[i, m] = R.eta_table[i, row * S.substeps + S.j_last, m]
                R.eta_sd[i, m] = 0.0
        k += 1
        R.steps[i] = k
        p, v = row3(V.p, i), row3(V.v, i)
        p_ref = _ref3(R.refs, i, row + 1, 0)
        lim = S.limits
        code = termination_code(p, row33(V.R, i), p_ref, (lim[0], lim[1], lim[2]))
        terminated = code != 0
        # the scenario's end truncates an episode that goes on; max_episode_steps any
        # episode, as gymnasium's TimeLimit around the single env
        truncated = (not terminated and k >= R.max_steps[i]) or k >= S.limit_steps
        ended = terminated or truncated
        Out.code[i], Out.terminated[i], Out.truncated[i] = code, terminated, truncated
        if terminated:  # the agent sees the true state of a terminated episode
            for m in range(3):
                V.mp[i, m], V.mv[i, m], V.mw[i, m] = V.p[i, m], V.v[i, m], V.w[i, m]
                for c in range(3):
                    V.mR[i, m, c] = V.R[i, m, c]
        else:
            measure_vehicle(i, generator_at(gens, i), C, V)
        rw = S.reward
        Out.reward[i] = reward_row(
            _minus3(p, p_ref),
            _minus3(v, _ref3(R.refs, i, row + 1, 1)),
            V.f_cmd[i],
            S.f_max,
            terminated,
            R.action[i],
            (rw[0], rw[1], rw[2], rw[3], rw[4], rw[5]),
        )
    if S.next_step:
        R.resetting[i] = ended
    if S.observe:
        observe_vehicle(i, S, R, V, Out.obs)
    off = k - R.table_k0[i]
    return (1 if off < 0 or off > S.window - 1 else 0), (1 if ended else 0)


@jit(_nrt=False)
def _step_range(lo, hi, S, R, Out, K, gens, C, V, T, rec, fx, k_phys, dt):
    """:func:`step_vehicle` for the sub-envs ``lo .. hi-1``, in order; returns how many
    leave their window and how many ended. Compiled without numba's reference counts
    (``_nrt=False``: the step allocates nothing, and the caller holds every array): a loop
    whose body branches would otherwise take and drop a count of every array of its tuples
    at every vehicle (measured: 260 ns per vehicle for 24 arrays)."""
    stale, ended = 0, 0
    for i in range(lo, hi):
        s, e = step_vehicle(i, S, R, Out, K, gens, C, V, T, rec, fx, k_phys, dt)
        stale += s
        ended += e
    return stale, ended


def _claim_python(counter):
    c = int(counter[0])
    counter[0] += 1
    return c


def _compiled_claim():
    nb = _numba()
    if nb is None:
        return _claim_python
    from numba.core import cgutils, types
    from numba.extending import intrinsic, register_jitable

    @intrinsic
    def _fetch_add(typingctx, counter):
        """``counter[0]``, then ``counter[0] += 1``, atomically (an int64 array)."""

        def codegen(context, builder, sig, args):
            ary = context.make_array(sig.args[0])(context, builder, args[0])
            one = context.get_constant(types.int64, 1)
            return builder.atomic_rmw("add", cgutils.gep(builder, ary.data, 0), one, "monotonic")

        return types.int64(counter), codegen

    @register_jitable(inline="always")
    def claim(counter):
        return _fetch_add(counter)

    return claim


#: ``claim(counter)``: the next task's number from an int64 counter shared by the threads
#: (an atomic fetch-and-add in a compiled kernel)
claim = _compiled_claim()


@jit(parallel=True)
def _step_parallel(S, R, Out, K, gens, C, V, T, rec, fx, k_phys, dt, chunk, counter, workers):
    """The step over tasks of ``chunk`` vehicles that ``workers`` threads claim one after the
    other (``counter[0]``, 0 at the call): a thread that starts late, or runs on a core
    another process shares, takes fewer tasks instead of holding up the step with an equal
    share (numba's split of a ``prange`` is static)."""
    N = R.steps.shape[0]
    n_tasks = (N + chunk - 1) // chunk
    stale, ended = 0, 0
    for _ in prange(workers):
        s_w, e_w = 0, 0
        c = claim(counter)
        while c < n_tasks:
            lo = c * chunk
            s, e = _step_range(
                lo, min(lo + chunk, N), S, R, Out, K, gens, C, V, T, rec, fx, k_phys, dt
            )
            s_w += s
            e_w += e
            c = claim(counter)
        stale += s_w
        ended += e_w
    return stale, ended


@jit(_nrt=False)
def _observe_rows(rows, S, R, V, obs):
    for r in range(rows.shape[0]):
        observe_vehicle(rows[r], S, R, V, obs)


@jit(parallel=True)
def _observe_parallel(S, R, V, obs, chunk, counter, workers):
    N = obs.shape[0]
    n_tasks = (N + chunk - 1) // chunk
    for _ in prange(workers):
        c = claim(counter)
        while c < n_tasks:
            lo = c * chunk
            for i in range(lo, min(lo + chunk, N)):
                observe_vehicle(i, S, R, V, obs)
            c = claim(counter)


@jit(_nrt=False)
def spread_draws(gens, rows, u):
    """Row ``rows[k]``'s ``uniform(-1, 1, u.shape[1])`` from its generator into ``u[k]``: the
    draws of an episode start (``episode_start.SPREAD_DRAWS``), the same numbers as the
    generator's own ``uniform``."""
    for k in range(rows.shape[0]):
        g = generator_at(gens, rows[k])
        for j in range(u.shape[1]):
            u[k, j] = g.uniform(-1.0, 1.0)


@jit
def _copy_flat(a, out):
    """``out[k] = clip(a[k], -1, 1)``; the first ``k`` that is not finite or lies outside
    [-1, 1] by more than 1e-6, or -1. One pass without a branch (vector instructions), a
    second only when some number is bad."""
    bad = False
    for k in range(a.shape[0]):
        x = np.float64(a[k])
        bad |= not abs(x) <= 1.0 + 1e-6  # (NaN and infinities compare False)
        out[k] = min(max(x, -1.0), 1.0)
    if bad:
        for k in range(a.shape[0]):
            if not abs(np.float64(a[k])) <= 1.0 + 1e-6:
                return k
    return -1


def copy_actions(a: np.ndarray, out: np.ndarray) -> int:
    """The actions ``a`` (N, m) into ``out`` (N, m, C-contiguous), clipped to [-1, 1];
    returns -1, or the first row that is not finite or lies outside [-1, 1] by more than
    1e-6 (then ``validate_action`` names the problem)."""
    k = _copy_flat(np.ascontiguousarray(a).reshape(-1), out.reshape(-1))
    return -1 if k < 0 else k // a.shape[1]


def _counter() -> np.ndarray:
    """A fresh task counter of a parallel call (one per call: calls may overlap in threads)."""
    return np.zeros(1, dtype=np.int64)


def parallel(n_vehicles: int, threads: int) -> bool:
    """Whether a step of ``n_vehicles`` with ``threads`` numba threads runs under ``prange``."""
    return threads > 1 and n_vehicles >= PARALLEL_MIN_VEHICLES


def step(S, R, Out, K, loop, k_phys, dt, threads: int) -> tuple[int, int]:
    """Every sub-env's control step (:func:`step_vehicle`) in one call; ``loop`` the flight's
    ``(generators, constants, vehicles, tables, records, effects)``
    (:meth:`quadfault.model.flight.Flight.loop`). Returns the number of rows whose next step
    leaves its time-table window and the number of episodes that ended."""
    gens, C, V, T, rec, fx = loop
    N = R.steps.shape[0]
    if parallel(N, threads):
        stale, ended = _step_parallel(
            S, R, Out, K, gens, C, V, T, rec, fx, k_phys, dt, CHUNK, _counter(), threads
        )
    else:
        stale, ended = _step_range(0, N, S, R, Out, K, gens, C, V, T, rec, fx, k_phys, dt)
    return int(stale), int(ended)


def observe(S, R, V, obs, rows, threads: int) -> None:
    """The observations of ``rows`` (None: every sub-env) at their current step into ``obs``."""
    if rows is None:
        if parallel(len(obs), threads):
            _observe_parallel(S, R, V, obs, CHUNK, _counter(), threads)
            return
        rows = np.arange(len(obs))
    _observe_rows(np.asarray(rows, dtype=np.int64), S, R, V, obs)


__all__ = [
    "CHUNK",
    "ESTIMATE_KEPT",
    "ESTIMATE_TRUTH",
    "PARALLEL_MIN_VEHICLES",
    "StepConstants",
    "StepOut",
    "StepRows",
    "copy_actions",
    "observe",
    "parallel",
    "spread_draws",
    "step",
    "step_vehicle",
]
