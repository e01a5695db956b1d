"""Replay a recording through the nominal model and form per-channel residuals.

Channels (docs/formats.md), each present when the recording measures it:

* ``acc_x, acc_y, acc_z`` -- translational acceleration from the pose, world NED [m/s^2];
* ``sf_x, sf_y, sf_z`` -- accelerometer specific force, body FRD [m/s^2] (an IMU-only log has
  only these; a log with pose *and* accelerometer has both);
* ``alpha_x, alpha_y, alpha_z`` -- angular acceleration, body FRD [rad/s^2];
* ``rotor_1 .. rotor_n`` -- the thrust implied by the measured rotor speed, ``k omega_i^2``
  [N], against the command passed through the effects that act between the command and the
  rotor speed (:attr:`~quadfault.diagnosis.library.Candidate.rotor_side`: motor lag, delay).
  ``k`` is the sidecar's ``rotor_thrust_coefficient`` [N/(rad/s)^2], else the least-squares
  ratio of the commanded thrust to ``omega^2`` over the flight (then these channels carry the
  motor dynamics but not the curve's overall scale). Missing speed samples are interpolated.
  An interval's value is the speed sampled at its end: the model's thrust produced over an
  interval (the simulator's and the library's) is what the rotor reaches by its end, exact
  for a first-order motor at any sampling; the mean of the two end samples would lag it by
  half a sample (a fast motor's speed at a sample is already the command held before it).

Smoothing ("block means"): the recording is cut into contiguous blocks of about
``block_seconds`` (default 20 ms; at least one sample interval). Logs faster than
``internal_step`` (4 ms) are first merged to that step: the held commands and midpoint states
of consecutive intervals are averaged (weighted by duration), which keeps 1 kHz logs cheap and
changes the model only at time scales below 4 ms. The measured channel of a
block is the exact mean acceleration over it, ``(v_end - v_start) / (t_end - t_start)``
(likewise for the body rate), which handles non-uniform sampling without approximation; the
accelerometer and rotor channels are duration-weighted block means of the held samples. The
model channel is the duration-weighted mean over the same block of what each held command
produces (command of row k over ``[t_k, t_k+1]``, state at the interval's midpoint). Both
sides therefore see the same linear smoothing. Intervals longer than ``gap_factor`` times the
median spacing are gaps, and so are intervals inside ``exclude`` spans (what the flight-phase
mask, :mod:`quadfault.diagnosis.phases`, finds is not free flight): no block spans either.

Noise scales and channel weights are in :mod:`quadfault.diagnosis.scores`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix

from quadfault.errors import ConfigError, RecordingError
from quadfault.io.recording import Recording
from quadfault.model.dynamics import E3, angular_acceleration, translational_acceleration
from quadfault.model.motors import MotorModel
from quadfault.model.vehicle import Vehicle

ACC_CHANNELS = ("acc_x", "acc_y", "acc_z")
SF_CHANNELS = ("sf_x", "sf_y", "sf_z")
ALPHA_CHANNELS = ("alpha_x", "alpha_y", "alpha_z")
POSE_CHANNELS = ACC_CHANNELS + ALPHA_CHANNELS
IMU_CHANNELS = SF_CHANNELS + ALPHA_CHANNELS
CHANNEL_UNITS = {"acc": "m/s^2", "sf": "m/s^2", "alpha": "rad/s^2", "rotor": "N"}
#: what each channel group measures (groups share one total weight, see ``scores``)
CHANNEL_GROUPS = {
    "acc": "translation",
    "sf": "translation",
    "alpha": "rotation",
    "rotor": "rotor speed",
}


def channel_unit(name: str) -> str:
    return CHANNEL_UNITS[name.split("_")[0]]


def channel_group(name: str) -> str:
    return CHANNEL_GROUPS[name.split("_")[0]]


@dataclass(frozen=True, eq=False)
class Replay:
    """A recording prepared for the diagnosis (interval arrays have ``M = N - 1`` rows).

    Attributes:
        vehicle: nominal vehicle.
        t: sample times [s] (N,); dt: interval lengths [s] (M,).
        f: saturated rotor commands held over each interval [N] (M, n).
        p, v, R, w: interval-midpoint position [m], velocity [m/s], rotation (mean of the
            end-point matrices; only its third column enters the thrust direction) and body
            rate [rad/s]; ``p, v, R`` are None for an IMU-only log.
        block: block index of each interval, -1 outside any block (gaps, leftovers) (M,).
        block_t: block centre times [s] (B,); block_dur: block durations [s] (B,).
        measured: measured block-mean channels (B, C).
        channels: channel names (module docstring).
        knots: recording row of each interval boundary (N_k,): fast logs are merged to an
            internal step of about ``internal_step`` [s] (duration-weighted means of the held
            commands and midpoint states), so ``t = recording.t[knots]``.
        scored: blocks that held-out scores use (B,) bool: blocks overlapping the recording's
            calibration segment (``meta.calibration.segment`` [s], written by the importers
            for rows used to fit missing constants) are fitted on but never scored.
        excluded: the calibration segments ``((t0, t1), ...)`` [s] (fitted on, not scored).
        scoring_note: why the segment was not excluded (it left too few blocks), or "".
        starts: the unmerged inputs at the first recording row of every interval:
            ``{"f", "p", "v", "R", "w"}`` (``p, v, R`` None for an IMU-only log) -- what the
            controller knew when it chose the interval's first command (instruments of the
            feedback-bias check, ``feedback.frozen_replay``).
        raw: for merged (fast) logs, the unmerged commands ``{"t", "dt", "f", "merge",
            "seg"}`` (recording times (N,), interval lengths and saturated commands (M_raw,
            ...), the duration-weighted merge matrix and the merged interval of each raw one):
            timing effects (delay, lag) act on the raw commands before merging, so merging
            does not bias their time constants; None when nothing was merged.
        masked: spans ``((t0, t1, reason), ...)`` [s] left out of fitting and scoring (not
            free flight, :mod:`quadfault.diagnosis.phases`).
        accel: accelerometer specific force held over each interval, body FRD [m/s^2]
            (M, 3), or None.
        rotor_k: thrust per squared measured rotor speed [N/(rad/s)^2] of the ``rotor_*``
            channels, or None without rotor speeds; rotor_k_source: ``"sidecar"`` or
            ``"fitted"``.
        thrust_curve: the nominal ``(a, b, c)`` command-to-thrust curve of a ``u``-command
            recording (``f = a + b u + c u^2``), None for thrust commands.
        vbat: battery voltage [V] at each interval's midpoint (M,) (gaps in the stream
            interpolated), or None when not logged or not usable.
        vbat_unusable: why a logged voltage is not used ("" when it is): the importer found
            it implausible for the pack.
    """

    vehicle: Vehicle
    t: np.ndarray
    dt: np.ndarray
    f: np.ndarray
    p: np.ndarray | None
    v: np.ndarray | None
    R: np.ndarray | None
    w: np.ndarray
    block: np.ndarray
    block_t: np.ndarray
    block_dur: np.ndarray
    block_run: np.ndarray
    measured: np.ndarray
    channels: tuple
    knots: np.ndarray
    scored: np.ndarray | None = None
    excluded: tuple = ()
    scoring_note: str = ""
    starts: dict | None = None
    raw: dict | None = None
    masked: tuple = ()
    accel: np.ndarray | None = None
    rotor_k: float | None = None
    rotor_k_source: str = ""
    thrust_curve: tuple | None = None
    vbat: np.ndarray | None = None
    vbat_unusable: str = ""

    @property
    def has_pose(self) -> bool:
        return self.p is not None

    @property
    def has_rotor(self) -> bool:
        return self.rotor_k is not None

    @property
    def n_blocks(self) -> int:
        return len(self.block_t)

    @property
    def arm(self) -> float:
        """Largest rotor distance from the centre [m] (from the allocation's moment rows)."""
        A = self.vehicle.allocation
        return float(np.max(np.hypot(A[1], A[2])))

    def channel_index(self, *groups: str) -> np.ndarray:
        """Indices of the channels whose name starts with one of ``groups`` (``"alpha"``)."""
        return np.array(
            [j for j, c in enumerate(self.channels) if c.split("_")[0] in groups], dtype=int
        )

    def block_mean(self, x: np.ndarray) -> np.ndarray:
        """Duration-weighted block means of interval values ``x`` (M, k) -> (B, k)."""
        S = self.__dict__.get("_averager")
        if S is None:
            ok = np.flatnonzero(self.block >= 0)
            blk = self.block[ok]
            S = csr_matrix(
                (self.dt[ok] / self.block_dur[blk], (blk, ok)), shape=(self.n_blocks, len(self.dt))
            )
            object.__setattr__(self, "_averager", S)
        return np.asarray(S @ x)

    def floors(self) -> np.ndarray:
        """Least noise scale per channel (what a noise-free recording is compared to):
        1e-3 g (accelerations), 1e-3 g / arm (angular), 1e-3 of the hover thrust per rotor
        (rotor channels)."""
        g = self.vehicle.gravity
        per = {
            "acc": 1e-3 * g,
            "sf": 1e-3 * g,
            "alpha": 1e-3 * g / max(self.arm, 1e-3),
            "rotor": 1e-3 * self.vehicle.weight / self.vehicle.n_rotors,
        }
        return np.array([per[c.split("_")[0]] for c in self.channels])


def _knots(valid: np.ndarray, r: int) -> np.ndarray:
    """Rows bounding merged intervals: every ``r``-th row inside runs of valid intervals,
    plus both ends of every invalid interval (gap)."""
    knots = [0]
    pos = 0
    M = len(valid)
    for k in range(M):
        if valid[k]:
            pos += 1
            if pos == r or k == M - 1 or not valid[k + 1]:
                knots.append(k + 1)
                pos = 0
        else:
            knots.append(k + 1)
            pos = 0
    return np.asarray(knots, dtype=int)


def _blocks(dt: np.ndarray, valid: np.ndarray, q: int):
    """Assign intervals to blocks of ``q`` consecutive valid intervals."""
    M = len(dt)
    block = np.full(M, -1, dtype=int)
    runs = []
    k, b = 0, 0
    run_id = []
    while k < M:
        if not valid[k]:
            k += 1
            continue
        start = k
        while k < M and valid[k]:
            k += 1
        n_full = (k - start) // q
        if n_full:
            block[start : start + n_full * q] = b + np.arange(n_full * q) // q
            run_id += [len(runs)] * n_full
            runs.append((start, start + n_full * q))
            b += n_full
    return block, b, np.asarray(run_id, dtype=int)


def _check(recording: Recording, veh: Vehicle, where: str) -> np.ndarray:
    t = np.asarray(recording.t, dtype=float)
    if len(t) < 20:
        raise RecordingError(where, f"too short for a diagnosis ({len(t)} rows, need >= 20)")
    if recording.thrust_cmd.shape[1] != veh.n_rotors:
        raise RecordingError(
            where,
            f"{recording.thrust_cmd.shape[1]} rotor commands but the "
            f"vehicle has {veh.n_rotors} rotors",
            key="vehicle",
        )
    if not np.all(np.diff(t) > 0):
        raise RecordingError(where, "time must be strictly increasing", column="t")
    for name in ("omega", "thrust_cmd", "position", "velocity", "quaternion", "accel"):
        arr = getattr(recording, name)
        if arr is not None and not np.all(np.isfinite(arr)):
            bad = int(np.flatnonzero(~np.all(np.isfinite(arr.reshape(len(t), -1)), axis=1))[0])
            raise RecordingError(where, f"non-finite value in {name}", row=bad + 1)
    return t


def rotor_speeds(recording: Recording) -> np.ndarray | None:
    """Measured rotor speeds [rad/s] with missing (NaN) samples interpolated in time, or
    None when the recording has none (or a rotor has no valid sample)."""
    W = recording.rotor_speed
    if W is None or W.shape[1] != recording.thrust_cmd.shape[1]:
        return None
    W = np.array(W, dtype=float)
    for i in range(W.shape[1]):
        ok = np.isfinite(W[:, i])
        if ok.sum() < 2:
            return None
        if not ok.all():
            W[:, i] = np.interp(recording.t, recording.t[ok], W[ok, i])
    return W


def prepare(
    recording: Recording,
    vehicle: Vehicle | None = None,
    *,
    block_seconds: float = 0.02,
    gap_factor: float = 2.5,
    saturate: bool = True,
    internal_step: float = 0.004,
    exclude=(),
) -> Replay:
    """Replay ``recording`` (truth is never read) into block-mean measured channels.

    ``exclude``: spans ``(t0, t1[, reason])`` [s] treated like gaps (never in a block)."""
    if not isinstance(recording, Recording):
        raise ConfigError(f"diagnosis needs a Recording, got {type(recording).__name__}")
    veh = vehicle or recording.vehicle
    where = recording.path or "recording"
    t = _check(recording, veh, where)
    dt = np.diff(t)
    f = MotorModel(0.0, saturate).apply(recording.thrust_cmd[:-1], 1.0, veh.rotor_max_thrust, None)
    med = float(np.median(dt))
    valid = dt <= gap_factor * med
    for span in exclude:  # intervals overlapping an excluded span
        valid &= ~((t[1:] > span[0]) & (t[:-1] < span[1]))
    # internal step: merge consecutive intervals of fast logs (duration-weighted means)
    r = max(1, int(internal_step / med + 1e-9))
    q = max(1, int(round(block_seconds / (r * med))))
    knots = _knots(valid, r)
    tk = t[knots]
    dtk = np.diff(tk)
    bad = np.r_[0, np.cumsum(~valid)]
    validk = bad[knots[1:]] == bad[knots[:-1]]
    M = len(dt)
    seg = np.searchsorted(knots, np.arange(M), side="right") - 1
    merge = csr_matrix((dt / dtk[seg], (seg, np.arange(M))), shape=(len(dtk), M))

    def mean(x):
        return np.asarray(merge @ x.reshape(M, -1)).reshape((len(dtk),) + x.shape[1:])

    block, n_blocks, run = _blocks(dtk, validk, q)
    if n_blocks < 10:
        hint = " after excluding what is not free flight (--no-mask keeps it)" if exclude else ""
        raise RecordingError(
            where,
            f"only {n_blocks} usable blocks of {q * r} samples (too short or too many gaps{hint})",
        )
    ok = block >= 0
    dur = np.bincount(block[ok], weights=dtk[ok], minlength=n_blocks)
    tc = (
        np.bincount(block[ok], weights=(tk[:-1] + 0.5 * dtk)[ok] * dtk[ok], minlength=n_blocks)
        / dur
    )
    ok_idx = np.flatnonzero(ok)
    first_k = ok_idx[np.unique(block[ok], return_index=True)[1]]
    first, last = knots[first_k], knots[first_k + q]  # sample indices at the block ends
    k0 = knots[:-1]
    raw = {"t": t, "dt": dt, "f": f, "merge": merge, "seg": seg} if r > 1 else None
    starts = {"f": f[k0], "w": recording.omega[k0], "p": None, "v": None, "R": None}
    f = mean(f)
    w_mid = mean(0.5 * (recording.omega[:-1] + recording.omega[1:]))
    rate = (recording.omega[last] - recording.omega[first]) / dur[:, None]
    parts, channels = [], ()
    R_mid = p_mid = v_mid = None
    if recording.has_pose:
        vel = recording.velocity
        parts.append((vel[last] - vel[first]) / dur[:, None])
        channels += ACC_CHANNELS
        Rm = recording.rotation
        R_mid = mean(0.5 * (Rm[:-1] + Rm[1:]))
        p_mid = mean(0.5 * (recording.position[:-1] + recording.position[1:]))
        v_mid = mean(0.5 * (vel[:-1] + vel[1:]))
        starts.update(p=recording.position[k0], v=vel[k0], R=Rm[k0])
    accel = None if recording.accel is None else mean(recording.accel[:-1])
    if accel is not None:
        parts.append(None)  # block means once the replay exists
        channels += SF_CHANNELS
    parts.append(rate)
    channels += ALPHA_CHANNELS
    W = rotor_speeds(recording)
    rotor_k, k_source = None, ""
    if W is not None:
        f2 = mean(W[1:] ** 2)  # squared speed at each interval's end (module docstring)
        rotor_k = (recording.meta or {}).get("rotor_thrust_coefficient")
        k_source = "sidecar"
        if rotor_k is None:
            use = validk[:, None] & (f2 > 0)
            rotor_k = float(np.sum((f * f2)[use]) / max(np.sum((f2 * f2)[use]), 1e-300))
            k_source = "fitted"
        else:
            try:
                rotor_k = float(rotor_k)
            except (TypeError, ValueError):
                rotor_k = float("nan")
            if not (math.isfinite(rotor_k) and rotor_k > 0):
                raise RecordingError(
                    where,
                    f"must be a positive number, got "
                    f"{recording.meta['rotor_thrust_coefficient']!r}",
                    key="rotor_thrust_coefficient",
                )
        channels += tuple(f"rotor_{i + 1}" for i in range(W.shape[1]))
        parts.append(None)
    excluded = calibration_segments(recording, where)
    scored = np.ones(n_blocks, dtype=bool)
    for a, b in excluded:
        scored &= ~((tc + 0.5 * dur > a) & (tc - 0.5 * dur < b))
    note = ""
    if excluded and scored.sum() < max(10, n_blocks // 10):
        note = (
            f"calibration segment {list(excluded[0])} s leaves only {int(scored.sum())} of "
            f"{n_blocks} blocks: scored on all blocks (including calibration data)"
        )
        scored[:] = True
        excluded = ()
    masked = tuple(
        (float(s[0]), float(s[1]), str(s[2]) if len(s) > 2 else "excluded") for s in exclude
    )
    curve = recording.thrust_curve if recording.commands_u is not None else None
    vbat = _interval_voltage(recording, mean)
    rp = Replay(
        veh,
        tk,
        dtk,
        f,
        p_mid,
        v_mid,
        R_mid,
        w_mid,
        block,
        tc,
        dur,
        run,
        np.zeros((n_blocks, len(channels))),
        channels,
        knots,
        scored,
        excluded,
        note,
        starts,
        raw,
        masked,
        accel,
        rotor_k,
        k_source,
        curve,
        vbat,
        _voltage_unusable(recording),
    )
    later = iter(
        [rp.block_mean(x) for x in (accel, None if W is None else rotor_k * f2) if x is not None]
    )
    parts = [next(later) if x is None else x for x in parts]
    object.__setattr__(rp, "measured", np.hstack(parts))
    return rp


def _voltage_unusable(recording: Recording) -> str:
    """Why the logged battery voltage cannot be used ("" when it can): the importer's check
    found it implausible for the pack (``meta.import.battery.plausible``, docs/formats.md)."""
    battery = ((recording.meta or {}).get("import") or {}).get("battery") or {}
    if battery.get("plausible", True):
        return ""
    return "battery voltage implausible for the pack: " + str(battery.get("why", "see the sidecar"))


def _interval_voltage(recording: Recording, mean) -> np.ndarray | None:
    """Battery voltage at the (merged) interval midpoints, dropouts (NaN, <= 0) interpolated;
    None without a usable ``vbat`` column (or one the importer found implausible)."""
    if recording.vbat is None or _voltage_unusable(recording):
        return None
    t, v = recording.t, np.asarray(recording.vbat, dtype=float)
    ok = np.isfinite(v) & (v > 0)
    if ok.sum() < 2:
        return None
    v = np.interp(t, t[ok], v[ok])
    return mean(0.5 * (v[:-1] + v[1:]))


def calibration_segments(recording: Recording, where: str = "recording") -> tuple:
    """``((t0, t1),)`` [s] from ``meta.calibration.segment`` (the importers' calibration rows,
    see docs/importers.md), or ``()``; a malformed entry is a one-line RecordingError."""
    cal = (recording.meta or {}).get("calibration")
    if cal is None:
        return ()
    seg = cal.get("segment") if isinstance(cal, dict) else None
    if seg is None:
        return ()
    try:
        t0, t1 = (float(x) for x in seg)
    except (TypeError, ValueError):
        raise RecordingError(
            where,
            f"meta calibration.segment must be [t0, t1] in seconds, got {seg!r}",
            key="calibration",
        ) from None
    if not (np.isfinite(t0) and np.isfinite(t1) and t0 < t1):
        raise RecordingError(
            where, f"meta calibration.segment needs finite t0 < t1, got {seg!r}", key="calibration"
        )
    return ((t0, t1),)


def model_parts(
    rp: Replay,
    f: np.ndarray,
    force=None,
    moment_ext=None,
    thrust=None,
    moment=None,
    vehicle: Vehicle | None = None,
) -> list:
    """Interval channels (M, C) the model predicts for produced rotor thrusts ``f`` [N] and
    external force (world; body for an IMU-only log) [N] / moment (body) [N m] (paper eqs. 2
    and 4), for the rigid body ``vehicle`` (default: the nominal one; another mass or inertia
    for body-stage effects). The ``rotor_*`` channels are not formed here (they need the
    command before the effects that act after the rotor speed; ``library.predict_intervals``
    appends them). :func:`model_channels` stacks the parts, (M, 3) each."""
    veh = rp.vehicle if vehicle is None else vehicle
    if thrust is None or moment is None:
        wrench = veh.wrench(f)
        thrust, moment = wrench[:, 0], wrench[:, 1:]
    parts = []
    if rp.has_pose:
        parts.append(translational_acceleration(rp.R, thrust, veh, force))
    if rp.accel is not None:  # specific force in the body frame: -T/m e3 + R^T F / m
        sf = -(thrust / veh.mass)[:, None] * E3
        if force is not None:
            sf = sf + (np.einsum("mji,mj->mi", rp.R, force) if rp.has_pose else force) / veh.mass
        parts.append(sf)
    parts.append(angular_acceleration(rp.w, moment, veh, moment_ext))
    return parts


def model_channels(
    rp: Replay,
    f: np.ndarray,
    force=None,
    moment_ext=None,
    thrust=None,
    moment=None,
    vehicle: Vehicle | None = None,
) -> np.ndarray:
    """Interval channels (M, C) of :func:`model_parts`, stacked."""
    return np.hstack(model_parts(rp, f, force, moment_ext, thrust, moment, vehicle))


def noise_scale(rp: Replay, residual: np.ndarray) -> np.ndarray:
    """Robust per-channel noise scale of block residuals (B, C): MAD of differences at lag 2
    within each run, divided by sqrt(2), floored (``Replay.floors``)."""
    same = rp.block_run[2:] == rp.block_run[:-2]
    d = (residual[2:] - residual[:-2])[same]
    if len(d) < 5:
        d = residual - np.median(residual, axis=0)
    mad = 1.4826 * np.median(np.abs(d - np.median(d, axis=0)), axis=0) / math.sqrt(2.0)
    return np.maximum(mad, rp.floors())
