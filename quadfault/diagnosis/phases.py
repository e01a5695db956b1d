"""Flight-phase mask: find what is not free flight, so it is neither fitted nor scored.

A rigid body in free flight feels gravity, its rotors and the air; anything else -- the
ground, a landing pad, a hand, an impact -- is a force the model of the diagnosis has no term
for, and a few such blocks can hold most of a flight's squared residual. Each detector below
is a physical test on the block means of a first, unmasked replay (no fitted model is used);
a span is excluded with its reason:

``motors off``
    the commanded collective thrust stays below ``OFF_FRACTION`` (5 %) of the weight for at
    least ``OFF_SECONDS`` (0.5 s). Shorter cuts in flight (a deliberate thrust step, free
    fall) are data.
``supported``
    on the ground, on a pad or held: the specific force the vehicle measures along its thrust
    axis exceeds what the commanded thrust can give by more than ``SUPPORT_FRACTION`` (half)
    of the weight, beyond the flight's own level of that excess (its 20th percentile, which
    absorbs a thrust curve that is off by a constant factor), for at least
    ``SUPPORT_SECONDS`` (0.3 s); or by more than ``IDLE_FRACTION`` (15 %) while every rotor
    command stays exactly constant (a controller at idle, not flying) -- in both cases with
    the body nearly at rest, its specific force within ``HELD_G`` (0.25 g) of 1 g (strong
    ground effect in flight accelerates the vehicle and is not mistaken for support).
``impact``
    the measured specific force exceeds by ``IMPACT_G`` (2 g) the most the commanded thrust
    of the last ``IMPACT_MEMORY`` (0.3 s) could give -- a crash, a hard landing or a
    collision; the span continues ``AFTER_IMPACT`` (0.5 s) afterwards (tumbling).
``upside down or pushed``
    the specific force points down the thrust axis (along +z of the FRD body) by more than
    ``WRONG_WAY_G`` (0.5 g) for at least 0.1 s, which rotors cannot do.

Spans of the first three kinds grow by ``MARGIN`` (0.2 s) on each side and, for support and
motors off, outward while the excess support stays above ``TRANSITION_FRACTION`` (10 %) of
the weight, up to ``TRANSITION_SECONDS`` (1 s): take-off and landing contact. Pieces of free
flight shorter than ``MIN_FREE_SECONDS`` (1 s) between excluded spans or at the ends of the
log are excluded too (``ragged end``). The specific force is the accelerometer's when the log
has one, else ``R^T (a - g e3)`` from the pose, smoothed over 0.1 s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadfault.diagnosis.residuals import Replay

OFF_FRACTION, OFF_SECONDS = 0.05, 0.5
SUPPORT_FRACTION, SUPPORT_SECONDS, SUPPORT_QUANTILE, HELD_G = 0.5, 0.3, 20.0, 0.25
IDLE_FRACTION = 0.15
IMPACT_G, IMPACT_MEMORY, AFTER_IMPACT = 2.0, 0.3, 0.5
WRONG_WAY_G, WRONG_WAY_SECONDS = 0.5, 0.1
MARGIN = 0.2
TRANSITION_FRACTION, TRANSITION_SECONDS, REST_G = 0.1, 1.0, 0.05
MIN_FREE_SECONDS = 1.0


@dataclass(frozen=True)
class Span:
    """A stretch of the recording that is not free flight: ``[t0, t1]`` [s] and why."""

    t0: float
    t1: float
    reason: str

    def as_tuple(self) -> tuple:
        return (self.t0, self.t1, self.reason)


def _smooth(x: np.ndarray, n: int) -> np.ndarray:
    if n <= 1:
        return x
    k = np.ones(n) / n
    pad = np.pad(x, ((n // 2, n - 1 - n // 2), (0, 0)), mode="edge")
    return np.stack([np.convolve(pad[:, j], k, mode="valid") for j in range(x.shape[1])], axis=1)


def block_signals(rp: Replay) -> dict:
    """Block-mean signals of the detectors: ``thrust`` (commanded collective thrust / weight),
    ``sf`` (measured specific force, body FRD [m/s^2], (B, 3)), ``support`` (excess of the
    measured thrust-axis specific force over the commanded thrust, / weight), ``constant``
    (no rotor command changed within the block)."""
    veh = rp.vehicle
    g = veh.gravity
    n_smooth = max(1, int(round(0.1 / float(np.median(rp.block_dur)))))
    thrust = rp.block_mean(rp.f.sum(axis=1)[:, None])[:, 0] / veh.weight
    if rp.accel is not None:
        sf = rp.measured[:, rp.channel_index("sf")]
    else:
        acc = rp.measured[:, rp.channel_index("acc")]
        Rb = rp.block_mean(rp.R.reshape(len(rp.R), 9)).reshape(-1, 3, 3)
        sf = _smooth(np.einsum("bji,bj->bi", Rb, acc - g * np.array([0.0, 0.0, 1.0])), n_smooth)
    df = np.zeros(len(rp.dt))
    df[1:] = np.abs(np.diff(rp.f, axis=0)).sum(axis=1)
    constant = rp.block_mean(df[:, None])[:, 0] <= 1e-9 * veh.weight
    return {"thrust": thrust, "sf": sf, "support": -sf[:, 2] / g - thrust, "constant": constant}


def _runs(flag: np.ndarray, t0: np.ndarray, t1: np.ndarray, min_seconds: float) -> list:
    """Time spans of runs of flagged blocks lasting at least ``min_seconds`` (blocks closer
    than 50 ms count as adjacent)."""
    out = []
    idx = np.flatnonzero(flag)
    if idx.size == 0:
        return out
    start = prev = idx[0]
    for k in list(idx[1:]) + [None]:
        if k is not None and t0[k] - t1[prev] < 0.05:
            prev = k
            continue
        if t1[prev] - t0[start] >= min_seconds - 1e-9:
            out.append([float(t0[start]), float(t1[prev]), int(start), int(prev)])
        if k is not None:
            start = prev = k
    return out


def _extend(span, contact, t0, t1):
    """Grow a contact span outward over the blocks that look like partial contact (``contact``,
    its running maximum over +-0.15 s so brief dips do not end a take-off), at most
    ``TRANSITION_SECONDS``."""
    n = max(1, int(round(0.15 / float(np.median(t1 - t0)))))
    pad = np.pad(contact, n, mode="edge")
    near = np.lib.stride_tricks.sliding_window_view(pad, 2 * n + 1).max(axis=1)
    a, b = span[2], span[3]
    while a > 0 and near[a - 1] and span[0] - t0[a - 1] < TRANSITION_SECONDS:
        a -= 1
    while b < len(near) - 1 and near[b + 1] and t1[b + 1] - span[1] < TRANSITION_SECONDS:
        b += 1
    return [min(span[0], float(t0[a])), max(span[1], float(t1[b]))]


def _merge(spans: list) -> list:
    """Union of ``[t0, t1, reason]`` spans; overlapping reasons are joined."""
    spans = sorted(spans)
    out = []
    for a, b, why in spans:
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
            if why not in out[-1][2].split("; "):
                out[-1][2] += "; " + why
        else:
            out.append([a, b, why])
    return out


def flight_phases(rp: Replay) -> tuple:
    """Spans of ``rp`` (an unmasked replay) that are not free flight, as :class:`Span`."""
    s = block_signals(rp)
    t0 = rp.block_t - 0.5 * rp.block_dur
    t1 = rp.block_t + 0.5 * rp.block_dur
    g = rp.vehicle.gravity
    start, end = float(rp.t[0]), float(rp.t[-1])
    support = s["support"] - np.percentile(s["support"], SUPPORT_QUANTILE)
    found = []
    for a, b, *_ in _runs(s["thrust"] < OFF_FRACTION, t0, t1, OFF_SECONDS):
        found.append([a - MARGIN, b + MARGIN, "motors off"])
    # held: support while the body is (nearly) at rest, its specific force about 1 g
    rest = np.abs(np.linalg.norm(s["sf"], axis=1) / g - 1.0)
    held = ((support > SUPPORT_FRACTION) | ((support > IDLE_FRACTION) & s["constant"])) & (
        rest < HELD_G
    )
    partial = (support > TRANSITION_FRACTION) & (rest < REST_G)  # take-off, landing
    for span in _runs(held, t0, t1, SUPPORT_SECONDS):
        a, b = _extend(span, partial, t0, t1)
        found.append([a - MARGIN, b + MARGIN, "supported (ground, pad or hand)"])
    # impact: more specific force than the last IMPACT_MEMORY s of commands can give
    n_mem = max(1, int(round(IMPACT_MEMORY / float(np.median(rp.block_dur)))))
    avail = np.array([s["thrust"][max(0, k - n_mem) : k + 1].max() for k in range(len(t0))])
    impact = np.linalg.norm(s["sf"], axis=1) / g - avail > IMPACT_G
    for a, b, *_ in _runs(impact, t0, t1, 0.0):
        found.append([a - MARGIN, b + AFTER_IMPACT, "impact (crash, hard landing)"])
    for a, b, *_ in _runs(s["sf"][:, 2] > WRONG_WAY_G * g, t0, t1, WRONG_WAY_SECONDS):
        found.append([a - MARGIN, b + MARGIN, "upside down or pushed"])
    spans = _merge([[max(a, start), min(b, end), why] for a, b, why in found])
    # ragged ends: short pieces of free flight next to an excluded span or a log end
    if spans:
        edges = [start] + [x for a, b, _ in spans for x in (a, b)] + [end]
        for a, b in zip(edges[0::2], edges[1::2]):
            if 0 < b - a < MIN_FREE_SECONDS:
                spans.append(
                    [a, b, f"ragged end (free flight shorter than {MIN_FREE_SECONDS:g} s)"]
                )
        spans = _merge(spans)
    return tuple(Span(float(a), float(b), why) for a, b, why in spans if b > a)


def excluded_fraction(spans, start: float, end: float) -> float:
    """Fraction of ``[start, end]`` covered by the union of ``(t0, t1, ...)`` spans."""
    merged = _merge(
        [
            [max(float(s[0]), start), min(float(s[1]), end), ""]
            for s in spans
            if s[1] > start and s[0] < end
        ]
    )
    return float(sum(b - a for a, b, _ in merged) / max(end - start, 1e-12))
