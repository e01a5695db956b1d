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

The fix (:func:`complete_into`): when the estimate has moved by more than
``change_threshold`` on some motor over the last ``span`` windows (the window length less
one: a step takes several windows to pass through the robust weights), a change has
happened. From the estimate ``span`` windows before (the anchor ``x_a``), until
``change_hold`` windows after the last such move, the estimate is

    x = clip(x_a + P d + alpha* v),   d = x_raw - x_a,   P = I - v v^T,
    alpha* = argmin_alpha ||P d + alpha v||_1

i.e. the weak-direction component of the change is not taken from the smoothness prior but
completed by the sparsest change consistent with the observed components: faults hit one
motor at a time. ``alpha*`` is a weighted median (exact L1 minimiser in one dimension).

A change that is not a single-motor one is left alone (the completion stands down for that
window, :func:`single_motor`): when the completed change moves a second motor by more than
half the largest move. A collective change (all motors stepped at once) has no weak-direction
component to complete -- its observable part is the whole change -- and the L1 minimum is
then a tie whose median picks a two-motor drop of twice the size.
The completion applies only when the weak direction is really prior-dominated (smallest
eigenvalue of the window information ``J^T W G J`` below ``gamma``). The corrected estimate
is fed back as the next window's anchor ``eta_prev``, after which the data agree with it.

State of one estimator (per vehicle): the last ``span`` window estimates (a ring), the
anchor, the weak direction and the counters ``[k, left, has_v, events]`` (ring slot, windows
left to complete, whether the weak direction is prior-dominated, changes started).
:func:`complete_into` and :func:`observe_into` are plain Python compiled by
:func:`quadfault.jit.jit`, allocation-free; the IRLS's online update calls them after every
window (:mod:`estimators.irls`). :func:`l1_completion` and :func:`weak_direction` evaluate the
two pieces on their own.
"""

from __future__ import annotations

import numpy as np

from estimators.linalg import smallest_eigenpair_into
from estimators.state import fields
from quadfault.jit import jit

#: the counters of the completion state: ring slot, windows left to complete, whether the
#: weak direction is prior-dominated, changes started
COUNTERS = fields("CompletionCounters", "k", "left", "has_v", "events")
N_COUNTERS = COUNTERS.size


@jit
def l1_completion_into(delta, v, r, wts, out) -> None:
    """``out = P delta + alpha* v`` with ``P = I - v v^T`` and
    ``alpha* = argmin ||P delta + alpha v||_1``: since ``sum_i |p_i + alpha v_i| =
    sum_i |v_i| |alpha + p_i / v_i|``, the ``|v_i|``-weighted median of ``-p_i / v_i`` (the
    entries with ``|v_i| <= 1e-12`` do not count). ``r``, ``wts`` (n,) are scratch."""
    n = delta.shape[0]
    dv = 0.0
    for i in range(n):
        dv += delta[i] * v[i]
    for i in range(n):
        out[i] = delta[i] - dv * v[i]  # P delta
    k = 0
    for i in range(n):  # the ratios, insertion-sorted, with their weights
        if abs(v[i]) > 1e-12:
            ri, wi = -out[i] / v[i], abs(v[i])
            j = k - 1
            while j >= 0 and r[j] > ri:
                r[j + 1], wts[j + 1] = r[j], wts[j]
                j -= 1
            r[j + 1], wts[j + 1] = ri, wi
            k += 1
    if k == 0:
        return
    total = 0.0
    for j in range(k):
        total += wts[j]
    acc = 0.0
    alpha = r[k - 1]
    for j in range(k):  # the first ratio whose cumulative weight reaches half the total
        acc += wts[j]
        if acc >= 0.5 * total:
            alpha = r[j]
            break
    for i in range(n):
        out[i] += alpha * v[i]


#: the completed change counts as a single-motor change when no other motor moves by more than
#: this fraction of the largest move
SINGLE_MOTOR_RATIO = 0.5


@jit
def single_motor(change) -> bool:
    """True when ``change`` (n,) moves one motor: its second-largest ``|entry|`` is at most
    :data:`SINGLE_MOTOR_RATIO` times the largest."""
    first = 0.0
    second = 0.0
    for j in range(change.shape[0]):
        a = abs(change[j])
        if a > first:
            first, second = a, first
        elif a > second:
            second = a
    return second <= SINGLE_MOTOR_RATIO * first


@jit
def observe_into(x, history, counters) -> None:
    """Record the estimate ``x`` of a window (every window, solved or held)."""
    span = history.shape[0]
    k = counters[COUNTERS.k]
    for j in range(x.shape[0]):
        history[k, j] = x[j]
    counters[COUNTERS.k] = (k + 1) % span


@jit
def complete_into(
    x, info, history, anchor, v, counters, threshold, hold, gamma, lower, upper, D, E, scratch
) -> None:
    """The change completion of one window, in place: ``x`` is the solver's estimate on entry
    and the estimate to use (and feed back) on return; ``info`` (n, n) is the window's
    information ``J^T W G J``; ``D``, ``E`` (n, n) and ``scratch`` (3, n) are scratch.
    Records the result (:func:`observe_into`)."""
    n = x.shape[0]
    k = counters[COUNTERS.k]
    move = 0.0
    for j in range(n):  # the move against the estimate span windows ago
        move = max(move, abs(x[j] - history[k, j]))
    if move > threshold:
        if counters[COUNTERS.left] == 0:  # a new change: its weak direction and anchor
            lam = smallest_eigenpair_into(info, D, E, v)
            counters[COUNTERS.has_v] = 1 if lam < gamma else 0
            for j in range(n):
                anchor[j] = history[k, j]
            counters[COUNTERS.events] += 1
        counters[COUNTERS.left] = hold
    if counters[COUNTERS.left] > 0:
        counters[COUNTERS.left] -= 1
        if counters[COUNTERS.has_v] == 1:
            delta, out = scratch[0], scratch[1]
            for j in range(n):
                delta[j] = x[j] - anchor[j]
            l1_completion_into(delta, v, scratch[2], E[0], out)
            if single_motor(out):
                for j in range(n):
                    x[j] = min(max(anchor[j] + out[j], lower), upper)
    observe_into(x, history, counters)


def l1_completion(delta, v) -> np.ndarray:
    """:func:`l1_completion_into` of one change ``delta`` (n,) along the unit vector ``v``."""
    delta = np.ascontiguousarray(delta, dtype=float)
    v = np.ascontiguousarray(v, dtype=float)
    out = np.empty_like(delta)
    l1_completion_into(delta, v, np.empty_like(delta), np.empty_like(delta), out)
    return out


def weak_direction(info) -> tuple[np.ndarray, float]:
    """``(v, lambda_min)``: the unit eigenvector of the smallest eigenvalue of the symmetric
    part of ``info`` (n, n), largest entry positive
    (:func:`estimators.linalg.smallest_eigenpair_into`)."""
    info = np.ascontiguousarray(info, dtype=float)
    n = info.shape[0]
    v = np.empty(n)
    lam = smallest_eigenpair_into(info, np.empty((n, n)), np.empty((n, n)), v)
    return v, float(lam)


__all__ = [
    "COUNTERS",
    "N_COUNTERS",
    "complete_into",
    "l1_completion",
    "l1_completion_into",
    "observe_into",
    "single_motor",
    "weak_direction",
]
