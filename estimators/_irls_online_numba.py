"""Compiled (numba) online path of the IRLS estimator: one call per sample.

:func:`online_update` is :meth:`estimators.irls.SlidingWindowIRLS.update` in one compiled
call (sample checks, the new segment's terms into the ring, the window solve of
:mod:`estimators._irls_numba`), over a state kept in flat buffers (:func:`online_state`,
:func:`online_constants`); :func:`median_columns` / :func:`median_push_rows` are the compiled
causal output medians of the single and the batched estimator (``IRLSConfig.output_median``).
docs/irls.md, "Online update()".
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimators._irls_numba import _N_MAT, _N_VEC, _NO_EXC, _median, _solve_window_into
from estimators._residuals_numba import segment_terms_into
from estimators.base import STATUSES

#: why :func:`online_update` refused a sample (``bad_sample``)
WHY_NONFINITE, WHY_TIME = 1, 2
_WARM = STATUSES.index("warmup")
_BAD = STATUSES.index("bad_sample")


# the online estimator's state lives in two flat buffers (few kernel arguments: the call
# overhead of a compiled function grows with their number); these are their pieces, in order
_ONLINE_FLOAT_PIECES = ("last_t", "last_p", "last_v", "last_R", "last_w", "last_f", "c", "b",
                        "H", "thrust", "r0", "J", "x_out", "sd_out", "V", "M", "S", "weights")
_ONLINE_INT_PIECES = ("ints", "iters")
_CONST_PIECES = ("scalars", "Jmat", "Jinv", "A", "G")


def _online_shapes(m, n, rounds):
    """Shapes of the pieces of the float state, the int state and the constants (the order
    :func:`online_update` reads them in)."""
    fs = ((1,), (3,), (3,), (3, 3), (3,), (n,), (m,), (m, n), (m, n, n), (m,), (10,),
          (10, n), (n,), (n,), (_N_VEC, n), (_N_MAT, n, n), (3, m), (m,))
    return fs, ((4,), (rounds,)), ((5,), (3, 3), (3, 3), (4, n), (10,))


def _views(buf, shapes, names):
    out, o = {}, 0
    for name, shape in zip(names, shapes):
        size = int(np.prod(shape))
        out[name] = buf[o:o + size].reshape(shape)
        o += size
    return out


def online_state(m: int, n: int, rounds: int):
    """The state of one online estimator (:func:`online_update` updates it in place):
    ``(fstate, istate, views)``: a float and an int buffer, and named numpy views of their
    pieces -- ``ints = [head, count, has_last, m]`` (``head``: ring slot written next, the
    oldest segment of a full window), ``last_*`` the previous sample (command clipped),
    ``c``, ``b``, ``H``, ``thrust`` the ring of segment terms, ``x_out``, ``sd_out``,
    ``weights``, ``iters`` the last window's solution, and scratch."""
    fs, ints, _ = _online_shapes(m, n, rounds)
    fstate = np.zeros(sum(int(np.prod(s)) for s in fs))
    istate = np.zeros(sum(int(np.prod(s)) for s in ints), dtype=np.int64)
    views = _views(fstate, fs, _ONLINE_FLOAT_PIECES)
    views.update(_views(istate, ints, _ONLINE_INT_PIECES))
    views["ints"][3] = m
    return fstate, istate, views


def online_constants(vehicle, G, clip: bool, min_thrust: float) -> np.ndarray:
    """The constant arguments of :func:`online_update` in one buffer: ``[mass, gravity,
    rotor_max_thrust, clip, min_thrust]``, inertia, its inverse, allocation, ``G``."""
    parts = (np.array([vehicle.mass, vehicle.gravity, vehicle.rotor_max_thrust, float(clip),
                       min_thrust]), vehicle.inertia, vehicle.inertia_inverse,
             vehicle.allocation, G)
    return np.concatenate([np.asarray(a, dtype=np.float64).ravel() for a in parts])


@njit(cache=True)
def _all_finite(a):
    for x in a.flat:
        if not math.isfinite(x):
            return False
    return True


@njit(cache=True)
def _take(buf, o, size):
    return buf[o:o + size], o + size


@njit(cache=True)
def online_update(t, p, v, R, w, f, const, fp, ip, fstate, istate, x):
    """One online update of the sliding-window IRLS in one compiled call: checks the sample
    (finite, time increasing), clips its command to ``[0, rotor_max_thrust]``, adds the
    segment previous -> this sample to the ring (eqs. 17-26), and solves the window
    (Algorithm 2, :func:`_solve_window_into`) from the previous estimate ``x`` when it is full
    and excited. The caller keeps ``x``: the solution is left in the state's ``x_out`` /
    ``sd_out`` (:func:`online_state`; ``const`` from :func:`online_constants`).

    Returns ``(status code, why, rounds, cond)``; ``why`` is :data:`WHY_NONFINITE` or
    :data:`WHY_TIME` for a ``bad_sample`` (the window restarts), else 0."""
    n = f.size
    ints = istate[:4]
    m = ints[3]
    iters = istate[4:]
    o = 0
    last_t, o = _take(fstate, o, 1)
    last_p, o = _take(fstate, o, 3)
    last_v, o = _take(fstate, o, 3)
    a, o = _take(fstate, o, 9)
    last_R = a.reshape((3, 3))
    last_w, o = _take(fstate, o, 3)
    last_f, o = _take(fstate, o, n)
    c, o = _take(fstate, o, m)
    a, o = _take(fstate, o, m * n)
    b = a.reshape((m, n))
    a, o = _take(fstate, o, m * n * n)
    H = a.reshape((m, n, n))
    thrust, o = _take(fstate, o, m)
    r0, o = _take(fstate, o, 10)
    a, o = _take(fstate, o, 10 * n)
    J = a.reshape((10, n))
    x_out, o = _take(fstate, o, n)
    sd_out, o = _take(fstate, o, n)
    a, o = _take(fstate, o, _N_VEC * n)
    V = a.reshape((_N_VEC, n))
    a, o = _take(fstate, o, _N_MAT * n * n)
    M = a.reshape((_N_MAT, n, n))
    a, o = _take(fstate, o, 3 * m)
    S = a.reshape((3, m))
    wts, o = _take(fstate, o, m)
    mass, g, f_max, clip, min_thrust = const[0], const[1], const[2], const[3] != 0.0, const[4]
    Jmat = const[5:14].reshape((3, 3))
    Jinv = const[14:23].reshape((3, 3))
    A = const[23:23 + 4 * n].reshape((4, n))
    G = const[23 + 4 * n:33 + 4 * n]
    finite = (math.isfinite(t) and _all_finite(p) and _all_finite(v) and _all_finite(R)
              and _all_finite(w) and _all_finite(f))
    if not finite or (ints[2] == 1 and not t > last_t[0]):
        ints[1] = 0
        ints[2] = 0
        return _BAD, (WHY_NONFINITE if not finite else WHY_TIME), 0, np.nan
    if ints[2] == 1:
        slot = ints[0]
        ci, ti = segment_terms_into(t - last_t[0], last_p, p, last_v, v, last_R, R, last_w, w,
                                    last_f, mass, g, Jmat, Jinv, A, G, r0, J, b[slot], H[slot])
        c[slot] = ci
        thrust[slot] = ti
        ints[0] = (slot + 1) % m
        ints[1] = min(ints[1] + 1, m)
    last_t[0] = t
    for i in range(3):
        last_p[i], last_v[i], last_w[i] = p[i], v[i], w[i]
        for k in range(3):
            last_R[i, k] = R[i, k]
    for j in range(n):
        last_f[j] = min(max(f[j], 0.0), f_max) if clip else f[j]
    ints[2] = 1
    if ints[1] < m:
        return _WARM, 0, 0, np.nan
    mean = 0.0
    for s in range(m):
        mean += thrust[(ints[0] + s) % m]
    if mean / m < min_thrust:
        return _NO_EXC, 0, 0, np.nan
    code, rounds, cond = _solve_window_into(c, b, H, ints[0], x, fp, ip, V, M, S, iters, wts,
                                            np.zeros((0, 7)), x_out, sd_out)
    return code, 0, rounds, cond


@njit(cache=True)
def median_columns(buf, out):
    """Per column, the median of ``buf`` (L, n) into ``out`` (n,): the middle value, or the
    mean of the middle two (as ``np.median``)."""
    L, n = buf.shape
    tmp = np.empty(L)
    for j in range(n):
        out[j] = _median(buf[:, j], tmp)


@njit(cache=True)  # serial: a few ops per value; threads cost more than they save here
def median_push_rows(buf, srt, k, x, fresh, out):
    """One push of :class:`estimators.change_completion.BatchedCausalMedian`, compiled: per
    row i and motor j, ``x[i, j]`` replaces the value in slot ``k`` of the ring ``buf``
    (N, L, n) (a ``fresh`` row fills its whole ring with it), ``srt`` keeps each ring's
    values sorted (one removal and one insertion instead of a sort), and ``out`` (N, n)
    gets the median (the middle value, or the mean of the middle two, as ``np.median``)."""
    N, L, n = buf.shape
    h = L // 2
    for i in range(N):
        for j in range(n):
            new = x[i, j]
            if fresh[i]:
                for s in range(L):
                    buf[i, s, j] = new
                    srt[i, s, j] = new
            else:
                old = buf[i, k, j]
                buf[i, k, j] = new
                r = 0
                while r < L - 1 and srt[i, r, j] != old:  # the old value leaves the ring
                    r += 1
                while r > 0 and srt[i, r - 1, j] > new:  # the new one moves into place
                    srt[i, r, j] = srt[i, r - 1, j]
                    r -= 1
                while r < L - 1 and srt[i, r + 1, j] < new:
                    srt[i, r, j] = srt[i, r + 1, j]
                    r += 1
                srt[i, r, j] = new
            out[i, j] = srt[i, h, j] if L % 2 else (srt[i, h - 1, j] + srt[i, h, j]) / 2.0
