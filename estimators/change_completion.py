"""Beyond the paper: keep an abrupt fault of one motor from leaking into the others.

Why (docs/irls.md, "Spikes"): the window's information about the efficiencies is far from
isotropic. Its weakest direction is the yaw-differential mode ``v ~ (-1, +1, -1, +1)/2``
(information ~2e-4 per window against ``gamma = 5e-3``), so along ``v`` the estimate is held
by the smoothness term ``gamma/2 ||eta - eta_prev||^2`` and moves by only a few per cent per
window. When motor ``j`` steps by ``delta``, the data fixes the three observable components of
the step at once, but its component ``delta (e_j . v) v`` along the weak direction arrives
only over tens of windows. Until then every motor carries an error of ``|delta| / 4`` with
the pattern of ``v`` -- the cross-coupling spike of the paper's metric (about 0.09 for a
0.355 step; the whole-window fit is not the cause: restarting the window at the true change
gives the same error).

The fix (:class:`ChangeCompletion`): when the estimate has moved by more than
``change_threshold`` on some motor over the last ``span`` windows (the window length less
one: a step takes several windows to pass through the robust weights), a change has
happened. From the estimate ``span`` windows before (the anchor ``x_a``), until
``change_hold`` windows after the last such move, the estimate is

    x = clip(x_a + P d + alpha* v),   d = x_raw - x_a,   P = I - v v^T,
    alpha* = argmin_alpha ||P d + alpha v||_1

i.e. the weak-direction component of the change is not taken from the smoothness prior but
completed by the sparsest change consistent with the observed components: faults hit one
motor at a time. ``alpha*`` is a weighted median (exact L1 minimiser in one dimension).
The completion applies only when the weak direction is really prior-dominated (smallest
eigenvalue of the window information ``J^T W G J`` below ``gamma``). The corrected estimate
is fed back as the next window's anchor ``eta_prev``, after which the data agree with it.

Also here: the causal running median of the output (:func:`causal_median`,
:class:`CausalMedian`), the other option of :class:`estimators.irls.IRLSConfig` beyond the
paper, and the batched twins of both (:class:`BatchedChangeCompletion`,
:class:`BatchedCausalMedian`) used by :class:`estimators.batched.BatchedIRLS`.
"""

from __future__ import annotations

import numpy as np


def weak_direction(info: np.ndarray) -> tuple[np.ndarray, float]:
    """``(v, lambda_min)``: unit eigenvector of the smallest eigenvalue of ``info`` (n, n)."""
    vals, vecs = np.linalg.eigh(0.5 * (info + info.T))
    return vecs[:, 0], float(vals[0])


def l1_completion(delta: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``P delta + alpha* v`` with ``alpha* = argmin ||P delta + alpha v||_1``, ``P = I - v v^T``.

    ``sum_i |p_i + alpha v_i| = sum_i |v_i| |alpha + p_i / v_i|`` is minimised by the
    ``|v_i|``-weighted median of ``-p_i / v_i``.
    """
    delta = np.asarray(delta, dtype=float)
    p = delta - (delta @ v) * v
    nz = np.abs(v) > 1e-12
    if not nz.any():
        return p
    r, wts = -p[nz] / v[nz], np.abs(v[nz])
    order = np.argsort(r)
    r, cw = r[order], np.cumsum(wts[order])
    alpha = float(r[np.searchsorted(cw, 0.5 * cw[-1])])
    return p + alpha * v


class ChangeCompletion:
    """State of the change completion over a stream of window estimates (module doc).

    Args:
        threshold: an estimate that differs by more than this on some motor from the one
            ``span`` windows before starts (or extends) a change [1].
        hold: windows during which the completion applies after the last such move.
        gamma: the estimator's smoothness weight (the weak direction must be below it).
        lower, upper: the box of the estimate.
        span: windows over which a move is measured.
    """

    def __init__(self, threshold: float, hold: int, gamma: float, lower: float, upper: float,
                 span: int = 9):
        self.threshold, self.hold, self.gamma = threshold, hold, gamma
        self.lower, self.upper, self.span = lower, upper, span
        self.reset(None)

    def reset(self, x0) -> None:
        """Forget any change; the past ``span`` estimates are taken as ``x0``."""
        self.left = 0
        self.anchor = None
        self.v = None
        self.events = 0
        self.history = None if x0 is None else np.repeat(
            np.asarray(x0, dtype=float)[None], self.span, axis=0)
        self._k = 0

    @property
    def reference(self) -> np.ndarray:
        """The estimate ``span`` windows ago."""
        return self.history[self._k]

    def observe(self, x: np.ndarray) -> None:
        """Record the estimate of a window (every window, solved or held)."""
        self.history[self._k] = x
        self._k = (self._k + 1) % self.span

    def recent(self) -> np.ndarray:
        """The last ``span`` estimates, oldest first."""
        return np.roll(self.history, -self._k, axis=0)

    @property
    def active(self) -> bool:
        """True while a change is being completed."""
        return self.left > 0

    def triggers(self, x_raw: np.ndarray) -> bool:
        """Would the estimate ``x_raw`` start or extend a change?"""
        # max_i |x_i - ref_i| on Python floats: the same numbers, without numpy's
        # per-call overhead on a 4-vector (the online update calls this every window)
        ref = self.history[self._k].tolist()
        return max(abs(a - b) for a, b in zip(np.asarray(x_raw, dtype=float).tolist(),
                                              ref)) > self.threshold

    def step(self, x_raw: np.ndarray, info) -> np.ndarray:
        """The estimate to use (and feed back) for a window whose solver returned ``x_raw``;
        ``info()`` gives the window's information matrix. Records the result."""
        x = x_raw
        if self.triggers(x_raw):
            if self.left == 0:
                v, lam = weak_direction(info())
                self.v = v if lam < self.gamma else None
                self.anchor = self.reference.copy()
                self.events += 1
            self.left = self.hold
        if self.left > 0:
            self.left -= 1
            if self.v is not None:
                x = np.clip(self.anchor + l1_completion(x_raw - self.anchor, self.v),
                            self.lower, self.upper)
        self.observe(x)
        return x


def causal_median(x: np.ndarray, length: int) -> np.ndarray:
    """Running median of the last ``length`` rows of ``x`` (N, n), per column; the first rows
    see the first row repeated before them (as :class:`CausalMedian` starts)."""
    x = np.asarray(x, dtype=float)
    if length <= 1 or len(x) == 0:
        return x.copy()
    pad = np.concatenate((np.repeat(x[:1], length - 1, axis=0), x))
    windows = np.lib.stride_tricks.sliding_window_view(pad, length, axis=0)
    return np.median(windows, axis=-1)


class CausalMedian:
    """Online twin of :func:`causal_median` (one row at a time); ``median`` computes the
    middle of the buffer, ``(buffer (L, n), out (n,)) -> None`` (default: numpy sort)."""

    def __init__(self, length: int, median=None):
        self.length = length
        self._median = median
        self.reset()

    def reset(self) -> None:
        self._buf = None
        self._k = 0

    def push(self, row: np.ndarray) -> np.ndarray:
        row = np.asarray(row, dtype=float)
        if self.length <= 1:
            return row.copy()
        if self._buf is None:
            self._buf = np.repeat(row[None], self.length, axis=0)
        self._buf[self._k] = row
        self._k = (self._k + 1) % self.length
        if self._median is not None:
            out = np.empty(row.shape)
            self._median(self._buf, out)
            return out
        # np.median's value (middle element, or the mean of the middle two), from one sort:
        # a few times faster on these small buffers
        ordered = np.sort(self._buf, axis=0)
        k = self.length // 2
        if self.length % 2:
            return ordered[k]
        return (ordered[k - 1] + ordered[k]) / 2.0


class BatchedChangeCompletion:
    """:class:`ChangeCompletion` for N independent rows (the batched estimator's), as arrays.

    Row i follows exactly the single object's rules; only the rows of a window that
    triggers a new change (rare) and the rows being completed run per row in Python.
    Arguments as :class:`ChangeCompletion`, plus ``num`` rows of ``n`` motors.
    """

    def __init__(self, num: int, n: int, threshold: float, hold: int, gamma: float,
                 lower: float, upper: float, span: int = 9):
        self.threshold, self.hold, self.gamma = threshold, hold, gamma
        self.lower, self.upper, self.span = lower, upper, span
        self.history = np.zeros((num, span, n))
        self._k = np.zeros(num, dtype=np.int64)
        self.left = np.zeros(num, dtype=np.int64)
        self.anchor = np.zeros((num, n))
        self.v = np.zeros((num, n))
        self.has_v = np.zeros(num, dtype=bool)
        self.events = np.zeros(num, dtype=np.int64)

    def reset(self, mask: np.ndarray, x0: np.ndarray) -> None:
        """Forget the rows in ``mask``; their past ``span`` estimates are taken as ``x0``
        (num, n)."""
        self.history[mask] = x0[mask][:, None, :]
        self._k[mask] = 0
        self.left[mask] = 0
        self.has_v[mask] = False
        self.events[mask] = 0

    def observe(self, rows: np.ndarray, x: np.ndarray) -> None:
        """Record the window estimates ``x`` (K, n) of ``rows`` (K,), distinct."""
        k = self._k[rows]
        self.history[rows, k] = x
        self._k[rows] = (k + 1) % self.span

    def step(self, rows: np.ndarray, x_raw: np.ndarray, infos) -> np.ndarray:
        """:meth:`ChangeCompletion.step` of ``rows`` (K,), distinct, whose solver returned
        ``x_raw`` (K, n); ``infos(J)`` gives the information matrices (len(J), n, n) of the
        windows of ``rows[J]``. Returns the estimates to use (K, n) and records them.
        Vectorised over rows, so a fault that hits every row at once stays cheap."""
        ref = self.history[rows, self._k[rows]]
        trig = np.max(np.abs(x_raw - ref), axis=1) > self.threshold
        new = np.flatnonzero(trig & (self.left[rows] == 0))  # rows starting a change
        if new.size:
            info = infos(new)
            vals, vecs = np.linalg.eigh(0.5 * (info + np.swapaxes(info, 1, 2)))
            i = rows[new]
            self.v[i], self.has_v[i] = vecs[:, :, 0], vals[:, 0] < self.gamma
            self.anchor[i] = ref[new]
            self.events[i] += 1
        self.left[rows[trig]] = self.hold
        active = self.left[rows] > 0
        self.left[rows[active]] -= 1
        x = x_raw.copy()
        J = np.flatnonzero(active & self.has_v[rows])
        if J.size:
            i = rows[J]
            x[J] = np.clip(self.anchor[i] + l1_completion_rows(x_raw[J] - self.anchor[i],
                                                               self.v[i]),
                           self.lower, self.upper)
        self.observe(rows, x)
        return x


def l1_completion_rows(delta: np.ndarray, v: np.ndarray) -> np.ndarray:
    """:func:`l1_completion` of each row of ``delta`` (K, n) with its own ``v`` (K, n)."""
    delta = np.asarray(delta, dtype=float)
    p = delta - np.einsum("ki,ki->k", delta, v)[:, None] * v
    nz = np.abs(v) > 1e-12
    r = np.where(nz, -p / np.where(nz, v, 1.0), np.inf)  # excluded entries: last, weight 0
    wts = np.where(nz, np.abs(v), 0.0)
    order = np.argsort(r, axis=1)
    r = np.take_along_axis(r, order, axis=1)
    cw = np.cumsum(np.take_along_axis(wts, order, axis=1), axis=1)
    pick = np.argmax(cw >= 0.5 * cw[:, -1:], axis=1)  # the weighted median (searchsorted)
    alpha = np.where(nz.any(axis=1), r[np.arange(len(r)), pick], 0.0)
    return p + alpha[:, None] * v


class BatchedCausalMedian:
    """:class:`CausalMedian` for N rows pushed together (every row at every push).

    The rows share the buffer slot they write; a reset row refills its whole buffer with
    its next value, so it holds the same values as a fresh :class:`CausalMedian` (the
    median does not depend on their order). ``push_kernel`` is the compiled push
    (``estimators._irls_online_numba.median_push_rows``, which keeps each buffer sorted
    incrementally); without it each push sorts the buffers with numpy. Same values.
    """

    def __init__(self, num: int, n: int, length: int, push_kernel=None):
        self.length = length
        self._kernel = push_kernel
        self._buf = np.zeros((num, length, n)) if length > 1 else None
        self._sorted = np.zeros((num, length, n)) if length > 1 and push_kernel else None
        self._fresh = np.ones(num, dtype=bool)
        self._k = 0

    def reset(self, mask: np.ndarray) -> None:
        self._fresh[mask] = True

    def push(self, x: np.ndarray) -> np.ndarray:
        """Add one value per row (N, n); returns each row's running median (N, n)."""
        if self.length <= 1:
            return np.array(x, dtype=float)
        k = self._k
        self._k = (k + 1) % self.length
        if self._kernel is not None:
            out = np.empty(x.shape)
            self._kernel(self._buf, self._sorted, k, np.ascontiguousarray(x, dtype=float),
                         self._fresh, out)
            self._fresh[:] = False
            return out
        fresh = np.flatnonzero(self._fresh)
        if fresh.size:
            self._buf[fresh] = x[fresh][:, None, :]
            self._fresh[:] = False
        self._buf[:, k] = x
        ordered = np.sort(self._buf, axis=1)
        h = self.length // 2
        if self.length % 2:
            return ordered[:, h]
        return (ordered[:, h - 1] + ordered[:, h]) / 2.0


def run_completed(c, b, H, excited, x0, completion: ChangeCompletion, run_chunk, solve_one,
                  window_info, chunk: int = 4096):
    """All windows of a recording with the change completion, fast between changes.

    Between changes the windows run in chunks through ``run_chunk(c, b, H, excited, x0) ->
    (eta, sd, status)`` (the compiled whole-recording kernel); from the first window that
    triggers a change until the completion ends they run one at a time through
    ``solve_one(c, b, H, x_prev) -> (eta, sd, diagnostics)``. The result is the same as one
    window at a time throughout.

    Args:
        c, b, H: per-segment quadratic terms of the recording.
        excited: per window, whether it has enough thrust to be solved.
        window_info: ``(H_window, weights) -> information matrix``.

    Returns:
        ``(eta, sd, status)`` per window.
    """
    from estimators.base import STATUS_NO_EXCITATION

    m = c.shape[0] - excited.shape[0] + 1
    n_win, n = excited.shape[0], len(x0)
    completion.reset(x0)
    span = completion.span
    eta = np.empty((n_win, n))
    sd = np.full((n_win, n), np.nan)
    status = np.empty(n_win, dtype=object)
    x = np.array(x0, dtype=float)
    s = np.full(n, np.nan)
    k = 0
    while k < n_win:
        if not completion.active:
            hi = min(k + chunk, n_win)
            e_w, s_w, st_w = run_chunk(c[k:hi + m - 1], b[k:hi + m - 1], H[k:hi + m - 1],
                                       excited[k:hi], x)
            ref = np.vstack((completion.recent(), e_w))[:len(e_w)]  # span windows back
            jumps = np.flatnonzero(np.max(np.abs(e_w - ref), axis=1) > completion.threshold)
            take = int(jumps[0]) if jumps.size else hi - k
            for row in e_w[max(take - span, 0):take]:
                completion.observe(row)
            if take:
                eta[k:k + take], sd[k:k + take], status[k:k + take] = (
                    e_w[:take], s_w[:take], st_w[:take])
                x = e_w[take - 1].copy()
                ok = np.flatnonzero(np.all(np.isfinite(s_w[:take]), axis=1))
                first = ok[0] if ok.size else take  # rows before it carry the previous sd
                sd[k:k + first] = s
                if ok.size:
                    s = s_w[ok[-1]].copy()
                k += take
            if not jumps.size:
                continue
        # one window at a time: the triggering window and the hold after it
        sl = slice(k, k + m)
        solved = False
        if excited[k]:
            x_raw, s_raw, diag = solve_one(c[sl], b[sl], H[sl], x)
            if s_raw is not None:
                x = completion.step(x_raw, lambda: window_info(H[sl], diag.weights))
                s, solved = s_raw, True
            status[k] = diag.status
        else:
            status[k] = STATUS_NO_EXCITATION
        if not solved:
            completion.observe(x)
        eta[k], sd[k] = x, s
        k += 1
    return eta, sd, status
