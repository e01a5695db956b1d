"""What the autopilot importers (PX4, ArduPilot, Betaflight) share: from a log's streams to a
recording.

Each autopilot importer reads its format into a :class:`FieldLog` -- the streams it found
(time stamps, values, how to resample them), the log's own landed flags and validity flags,
its rotor geometry and thrust model -- and :func:`build_recording` does the rest the same way
for all of them:

1. every stream is resampled onto one time base (:mod:`quadfault.io.importers.resample`);
2. the **flight span**: rows where a motor runs (a normalised command above ``RUNNING``,
   1 %: a command of 7e-10 is not running) and the vehicle is airborne -- by the log's land
   detector where it has one, else by a collective command above idle (``IDLE_MARGIN`` of
   the way from idle to the flight's typical command; a log whose lowest running command
   is above ``NO_IDLE_RATIO`` of the typical one has no idle, and all of it flies); with a
   land detector and a position, each airborne run starts where the vehicle leaves the
   height it rested at while the detector said landed and ends where it is back at rest
   (``LIFT_M``, :func:`lift_off`), so ground spool-up that the detector already calls
   flight stays out; spans shorter than ``MIN_FLIGHT_S`` are dropped and ``TRANSITION_S`` is cut from each end (take-off and landing). Armed idle,
   ground contact and the time between flights become gaps (``keep_all`` keeps them);
3. **invalid position or velocity** (the log's validity flags) is never written: those rows
   are dropped (gaps) when they are few, else the pose is left out and the recording is
   IMU-only (``POSE_VALID_FRACTION``);
4. the **vehicle**: the user's (``--vehicle`` or flags) over the log's geometry over
   assumptions, each constant's source in ``meta.constants`` and the assumed ones listed in
   ``meta.assumed``; what the user should know is in ``meta.import.warnings`` (``quadfault
   import`` prints it as one line on stderr);
5. the **thrust curve**: the log's thrust model (normalised command -> relative thrust)
   times a scale fitted on a calibration segment of free flight (default the first
   ``CALIBRATION_FRACTION`` of the longest flight span) so that the summed rotor thrust
   matches m times the measured specific force along the thrust axis.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from quadfault.errors import ConfigError, RecordingError
from quadfault.io.importers import gap_stats
from quadfault.io.importers.crazyflie import calibration_mask, scale_curve_on_segment
from quadfault.io.importers.resample import merge_topics
from quadfault.io.recording import Recording
from quadfault.model.effects import curve_thrust
from quadfault.model.vehicle import Vehicle, allocation_from_rotors

RUNNING = 0.01  # normalised command above which a motor runs
IDLE_MARGIN = 0.4  # airborne without landed flags: this far from idle to typical flight
NO_IDLE_RATIO = 0.6  # a lowest running command above this share of the typical is no idle
MIN_FLIGHT_S = 2.0  # shorter airborne spans are not flights [s]
TRANSITION_S = 1.0  # cut after take-off and before landing [s]
LIFT_M = 0.15  # height change from the resting height that marks lift-off / touch-down [m]
REST_S = 0.3  # the resting height: median over this long before / after a run [s]
POSE_VALID_FRACTION = 0.8
CALIBRATION_FRACTION = 0.3
ASSUMED_MASS = 1.0  # [kg]
#: Inertia rule of thumb for small quadrotors (Crazyflie 0.67, a 3-inch racer 0.57):
#: Jxx = Jyy = 0.6 m d^2 with d the mean per-axis rotor offset, Jzz = 1.4 Jxx.
INERTIA_RULE = (0.6, 1.4)
ASSUMED_TORQUE_COEFFICIENT = 0.016  # yaw torque per newton [m], typical of 5-10 inch props
#: Generic quad X (FRD, per-axis offset 1): front-right, rear-left, front-left, rear-right,
#: rotors 1 and 2 counter-clockwise (PX4's and ArduPilot's quad X order).
QUAD_X_XY = ((1.0, 1.0), (-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0))
QUAD_X_YAW = (1.0, 1.0, -1.0, -1.0)


@dataclass(frozen=True)
class Geometry:
    """Rotor layout from a log (FRD body).

    Attributes:
        xy: ``(4, 2)`` rotor positions [m] (or in units of the arm when ``placeholder``).
        yaw: ``(4,)`` sign of each rotor's reaction torque about +z (FRD) [-].
        torque_coefficient: yaw torque per newton [m], or None when the log has none.
        source: where it came from (parameter names).
        placeholder: the positions are generic (unit offsets, zeros), not this vehicle's.
    """

    xy: tuple
    yaw: tuple
    torque_coefficient: float | None
    source: str
    placeholder: bool = False


def quad_x(source: str) -> Geometry:
    """The generic quad X layout, marked as a placeholder."""
    return Geometry(QUAD_X_XY, QUAD_X_YAW, None, source, placeholder=True)


@dataclass
class FieldLog:
    """One log's streams, as an autopilot importer read them.

    Attributes:
        path: the log file.
        importer: registry name ("px4", "ardupilot", "blackbox").
        streams: ``{name: (t [s], values, kind)}`` with kind "linear", "quaternion" or "hold";
            names: ``q`` (w, x, y, z; FRD -> NED), ``w`` (body rate FRD [rad/s]), ``acc``
            (specific force FRD [m/s^2]), ``pos``, ``vel`` (NED [m], [m/s]), ``u`` (normalised
            motor commands 0..1, in the geometry's rotor order), ``rotor`` (measured rotor
            speed [rad/s]), ``vbat`` [V], ``current`` [A].
        time_base: stamps [s] to resample onto.
        thrust_model: ``(a, b, c)``: relative thrust a + b u + c u^2 of a command u.
        thrust_note: where the thrust model came from (and its parameters).
        geometry: the rotor layout, or None (generic quad X assumed).
        landed: ``(t, flag)`` from the log's land detector (True: on the ground), or None.
        landed_source: what ``landed`` is.
        invalid: ``{"pos"|"vel": (t, flag)}`` the log's own invalid flags (True: invalid).
        commands: how ``u`` was formed.
        missing: what the log lacks (for the summary).
        params: log parameters recorded in the sidecar (``meta.log_parameters``).
        source: free text for the sidecar.
        warnings: what the user should know (one phrase each).
        armed: whether the log says the vehicle was ever armed (None: it does not say);
            ``armed_source`` names the message.
        cells: ``(count, source)``: the battery's cell count from the log's parameters, or
            None (inferred from the voltage at arming, :func:`battery_check`).
        skipped: what the reader skipped of a truncated or corrupt log (``{"bytes": int,
            "truncated": bool, "corrupt": int, "after_t": float | None, "what": str}``), or
            None for an intact log.
    """

    path: Path
    importer: str
    streams: dict
    time_base: np.ndarray
    thrust_model: tuple = (0.0, 0.0, 1.0)
    thrust_note: str = "thrust proportional to the command squared (assumed)"
    geometry: Geometry | None = None
    landed: tuple | None = None
    landed_source: str = ""
    invalid: dict = field(default_factory=dict)
    commands: str = ""
    missing: list = field(default_factory=list)
    params: dict = field(default_factory=dict)
    source: str = ""
    warnings: list = field(default_factory=list)
    armed: bool | None = None
    armed_source: str = ""
    cells: tuple | None = None
    skipped: dict | None = None


# ----------------------------------------------------------------------------------------
# flight span
def _runs(flag: np.ndarray) -> list:
    """``[(i0, i1), ...]`` index runs (i1 exclusive) where ``flag`` is True."""
    d = np.diff(np.r_[0, flag.astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def lift_off(z: np.ndarray, ground_before: float, ground_after: float) -> tuple:
    """``(i0, i1)``: the first and one past the last row of an airborne run ``z`` (height [m],
    either sign convention) where the vehicle is off the ground, from its own motion: more
    than ``LIFT_M`` from the resting height before the run (``ground_before``) and after it
    (``ground_after``). A NaN resting height (nothing logged at rest: the log starts or ends
    in the air) keeps that end of the run, and so does a vehicle already off the ground
    there; a NaN height counts as unknown."""
    n = len(z)
    i0, i1 = 0, n
    ok = np.isfinite(z)
    if np.isfinite(ground_before):
        off = ok & (np.abs(z - ground_before) > LIFT_M)
        i0 = int(np.argmax(off)) if off.any() else 0
    if np.isfinite(ground_after):
        off = ok & (np.abs(z - ground_after) > LIFT_M)
        i1 = n - int(np.argmax(off[::-1])) if off.any() else n
    return (i0, i1) if i1 > i0 else (0, n)


def _resting_height(t: np.ndarray, z: np.ndarray, sel: np.ndarray) -> float:
    """Median height over the rows ``sel``, or NaN when there is no finite one or the height
    moves there by more than half of ``LIFT_M`` (not at rest: thrown, falling, a gap)."""
    zs = z[sel & np.isfinite(z)]
    if zs.size == 0 or np.ptp(zs) > 0.5 * LIFT_M:
        return float("nan")
    return float(np.median(zs))


def flight_spans(
    t: np.ndarray, u: np.ndarray, landed: np.ndarray | None = None, z: np.ndarray | None = None
) -> tuple:
    """Free-flight spans of a log: ``([(t0, t1), ...], how)``.

    Airborne means a motor runs and the land detector says not landed (``landed``, per row),
    or without one, the mean command is above idle by ``IDLE_MARGIN`` of the way to the
    flight's typical (75th-percentile) command. With a land detector and the vehicle's height
    ``z`` [m], each airborne run starts where the vehicle leaves the height it rested at
    while the detector said landed, and ends where it is back at rest (:func:`lift_off`): a
    detector that fires while the vehicle still spools up on the ground does not put ground
    time into the flight. Spans shorter than
    ``MIN_FLIGHT_S`` are dropped; ``TRANSITION_S`` is cut from each end of the rest.
    """
    running = np.any(u > RUNNING, axis=1)
    if not running.any():
        return [], "the motors never run"
    if landed is not None:
        air = running & ~landed
        how = "land detector"
    else:
        level = np.mean(u, axis=1)
        idle = float(np.percentile(level[running], 2))
        typical = float(np.percentile(level[running], 75))
        if idle > NO_IDLE_RATIO * typical:  # no idle plateau: the motors ran only in flight
            air = running
            how = (
                f"motors running (no idle in the log: 2nd percentile {idle:.3f}, typical "
                f"{typical:.3f})"
            )
        else:
            air = running & (level > idle + IDLE_MARGIN * (typical - idle))
            how = (
                f"mean command above {idle + IDLE_MARGIN * (typical - idle):.3f} (idle "
                f"{idle:.3f}, typical {typical:.3f})"
            )
    spans = []
    trimmed = 0.0
    logged = np.all(np.isfinite(u), axis=1)
    for i0, i1 in _runs(air):
        if z is not None and landed is not None:  # at rest: the detector says landed
            rest = logged & landed
            before = rest & (t < t[i0]) & (t >= t[i0] - REST_S)
            after = rest & (t > t[i1 - 1]) & (t <= t[i1 - 1] + REST_S)
            j0, j1 = lift_off(z[i0:i1], _resting_height(t, z, before), _resting_height(t, z, after))
            trimmed += float(t[i0 + j0] - t[i0]) + float(t[i1 - 1] - t[i0 + j1 - 1])
            i0, i1 = i0 + j0, i0 + j1
        a, b = float(t[i0]) + TRANSITION_S, float(t[i1 - 1]) - TRANSITION_S
        if b - a >= MIN_FLIGHT_S - 2 * TRANSITION_S and b > a:
            spans.append((a, b))
    if trimmed > 0.0:
        how += f", lift-off and touch-down from the height ({trimmed:.1f} s on the ground left out)"
    return spans, how


def _span_mask(t: np.ndarray, spans) -> np.ndarray:
    keep = np.zeros(len(t), dtype=bool)
    for a, b in spans:
        keep |= (t >= a) & (t <= b)
    return keep


# ----------------------------------------------------------------------------------------
# vehicle
def field_vehicle(
    log: FieldLog, *, mass=None, inertia=None, arm=None, torque_coefficient=None
) -> tuple:
    """``(Vehicle, constants, assumed, warnings)`` from the user's values, the log's
    geometry and, for the rest, stated assumptions."""
    geo = log.geometry or quad_x("no geometry in the log: generic quad X")
    constants, assumed, warns = {}, [], []
    xy = np.asarray(geo.xy, dtype=float)
    if arm is not None:
        if not arm > 0:
            raise ConfigError("--arm must be a positive number of metres")
        xy = np.sign(xy) * float(arm)
        constants["geometry"] = (
            f"per-axis offset {arm:g} m from --arm; order and spin directions from {geo.source}"
        )
    elif geo.placeholder:
        scale = 0.1 if np.allclose(np.abs(xy), 1.0) or not np.any(xy) else 1.0
        xy = np.sign(xy) * scale if scale != 1.0 else xy
        constants["geometry"] = f"{geo.source}; per-axis offset assumed {scale:g} m"
        assumed.append("geometry")
        warns.append(
            f"rotor positions are a generic placeholder ({geo.source}): assumed a "
            f"quad X with {scale:g} m per axis (give --arm)"
        )
    else:
        constants["geometry"] = f"from {geo.source}"
    if torque_coefficient is not None:
        c = float(torque_coefficient)
        constants["torque_coefficient"] = "from --torque-coefficient"
    elif geo.torque_coefficient is not None:
        c = float(geo.torque_coefficient)
        constants["torque_coefficient"] = f"from {geo.source}"
    else:
        c = ASSUMED_TORQUE_COEFFICIENT
        constants["torque_coefficient"] = f"assumed {c:g} m (typical propellers)"
        assumed.append("torque_coefficient")
    if mass is not None:
        m = float(mass)
        constants["mass"] = "from --mass"
    else:
        m = ASSUMED_MASS
        constants["mass"] = (
            f"assumed {m:g} kg (not in the log): thrust is calibrated as mass "
            "times the measured acceleration, so forces are per unit mass"
        )
        assumed.append("mass")
    if inertia is not None:
        J = np.asarray(inertia, dtype=float)
        constants["inertia"] = "from --inertia"
    else:
        d2 = float(np.mean(np.abs(xy))) ** 2
        kxy, kz = INERTIA_RULE
        J = np.array([kxy * m * d2, kxy * m * d2, kz * kxy * m * d2])
        constants["inertia"] = (
            f"assumed {kxy:g} m d^2 (roll, pitch), {kz:g} times that (yaw), "
            "a rule of thumb for small quadrotors: results that depend on "
            "inertia are not measurements"
        )
        assumed.append("inertia")
    if "mass" in assumed or "inertia" in assumed:
        warns.append(
            "assumed "
            + ", ".join(a for a in ("mass", "inertia") if a in assumed)
            + " (not in the log; give --mass, --inertia or --vehicle)"
        )
    alloc = allocation_from_rotors(xy, np.asarray(geo.yaw, dtype=float), c)
    vehicle = Vehicle(mass=m, inertia=J, allocation=alloc, name=f"{log.importer} log vehicle")
    return vehicle, constants, assumed, warns


# ----------------------------------------------------------------------------------------
def _pose_validity(log: FieldLog, t: np.ndarray) -> np.ndarray:
    """Per row: position and velocity valid by the log's flags (a row is invalid when the
    flag before or after it is)."""
    ok = np.ones(len(t), dtype=bool)
    for ts, flag in log.invalid.values():
        ts = np.asarray(ts, dtype=float)
        bad = np.asarray(flag, dtype=float)
        order = np.argsort(ts, kind="stable")
        ts, bad = ts[order], bad[order]
        i = np.clip(np.searchsorted(ts, t, side="right") - 1, 0, len(ts) - 1)
        j = np.clip(i + 1, 0, len(ts) - 1)
        ok &= (bad[i] < 0.5) & ((bad[j] < 0.5) | (ts[j] < t))
    return ok


def _measured_thrust(res: dict, vehicle: Vehicle) -> np.ndarray | None:
    """m times the specific force along the thrust axis [N] (accelerometer, else pose)."""
    if "acc" in res:
        return -vehicle.mass * res["acc"][:, 2]
    return None


#: plausible LiPo voltage per cell in flight [V] (below: empty or a wrong reading; above:
#: more than a charged cell holds)
CELL_MIN_V, CELL_MAX_V = 3.0, 4.35


def battery_check(t, vbat, flying, cells=None) -> dict | None:
    """Is the logged battery voltage plausible for the pack? ``(count, source)`` ``cells``
    from the log's parameters, else inferred from the voltage at the first flying row (the
    fewest cells that keep it at or below ``CELL_MAX_V`` per cell). Returns the sidecar's
    ``meta.import.battery`` entry (``plausible`` False when the 2nd or 98th percentile of
    the in-flight voltage per cell is below ``CELL_MIN_V`` or above ``CELL_MAX_V``), or None
    without a voltage in flight."""
    v = np.asarray(vbat, dtype=float)[flying]
    v = v[np.isfinite(v)]
    if v.size < 5:
        return None
    if cells is not None:
        n, how = int(cells[0]), str(cells[1])
    else:
        v0 = float(v[: max(1, min(50, v.size // 20))].mean())
        n = max(1, int(np.ceil(v0 / CELL_MAX_V - 1e-9)))
        how = f"inferred from {v0:.2f} V at the start of the flight"
    lo, hi = (float(x) / n for x in np.percentile(v, [2, 98]))
    entry = {
        "cells": n,
        "cells_from": how,
        "volts_per_cell": [round(lo, 3), round(hi, 3)],
        "plausible": bool(CELL_MIN_V <= lo and hi <= CELL_MAX_V),
    }
    if not entry["plausible"]:
        entry["why"] = (
            f"{lo:.2f}-{hi:.2f} V per cell in flight on {n} cell{'s' if n > 1 else ''} "
            f"({how}): outside {CELL_MIN_V:g}-{CELL_MAX_V:g} V, so the voltage is not "
            "the pack's; battery_thrust is not fitted on it"
        )
    return entry


def skipped_phrase(skipped: dict) -> str:
    """The warning phrase of a reader's ``skipped`` entry (:class:`FieldLog`)."""
    parts = [f"{skipped['what']}: {skipped['bytes']} bytes skipped"]
    if skipped.get("after_t") is not None:
        parts.append(f"the log ends at t = {skipped['after_t']:.2f} s")
    if skipped.get("spans"):
        spans = ", ".join(f"{a:.2f}-{b:.2f} s" for a, b in skipped["spans"][:3])
        more = len(skipped["spans"]) - 3
        parts.append("gaps at " + spans + (f" and {more} more" if more > 0 else ""))
    return "; ".join(parts) + "; imported what is valid"


def build_recording(
    log: FieldLog,
    *,
    vehicle: Vehicle | None = None,
    thrust_curve=None,
    mass=None,
    inertia=None,
    arm=None,
    torque_coefficient=None,
    keep_all: bool = False,
    calibration=None,
    vehicle_source: str = "the user's vehicle file",
) -> Recording:
    """The recording of ``log`` (module docstring); ``vehicle_source`` says where a given
    ``vehicle`` comes from."""
    path = log.path
    streams = dict(log.streams)
    if "u" not in streams:
        raise RecordingError(path, "no motor outputs found")
    never = (
        f"the vehicle was never armed ({log.armed_source}): a bench or ground log has no "
        "flight to import"
    )
    t = np.unique(np.asarray(log.time_base, dtype=float))
    dropped = len(log.time_base) - len(t)
    res = merge_topics(t, streams)
    need = [k for k in ("q", "w", "acc", "pos", "vel", "u") if k in res]
    ok = np.all(
        np.stack([np.all(np.isfinite(res[k].reshape(len(t), -1)), axis=1) for k in need]), axis=0
    )
    if ok.sum() < 2:
        raise RecordingError(path, "the streams (" + ", ".join(need) + ") do not overlap in time")
    first, last = np.flatnonzero(ok)[[0, -1]]
    t, res = t[first : last + 1], {k: v[first : last + 1] for k, v in res.items()}
    landed = None
    if log.landed is not None:
        landed = merge_topics(t, {"l": (log.landed[0], np.asarray(log.landed[1], float), "hold")})[
            "l"
        ]
        landed = np.nan_to_num(landed, nan=1.0) > 0.5  # before its first message: landed
    height = res["pos"][:, 2] if "pos" in res else None
    spans, how = flight_spans(t, res["u"], landed, height)
    if landed is not None and not spans and np.any(res["u"] > RUNNING):
        spans, how = flight_spans(t, res["u"], None, height)
        how += f" (the land detector, {log.landed_source}, never reports a flight)"
    if not np.any(res["u"] > RUNNING):
        if log.armed is False:
            raise RecordingError(path, never)
        raise RecordingError(path, "the motors never run (no output above 1 % of its range)")
    if not spans:
        raise RecordingError(path, f"no free flight of {MIN_FLIGHT_S:g} s or more ({how})")
    notes, missing = list(log.warnings), list(log.missing)
    if log.skipped:
        notes.insert(0, skipped_phrase(log.skipped))
    keep = np.ones(len(t), dtype=bool) if keep_all else _span_mask(t, spans)
    if "pos" in res:
        valid = _pose_validity(log, t)
        in_flight = _span_mask(t, spans)
        frac = float(valid[in_flight].mean())
        if frac < 1.0 and (frac >= POSE_VALID_FRACTION or "acc" not in res):
            keep &= valid
            notes.append(
                f"position/velocity flagged invalid on {100 * (1 - frac):.0f} % of the "
                "flight: those rows dropped"
            )
        elif frac < POSE_VALID_FRACTION:
            res.pop("pos"), res.pop("vel")
            missing.append(
                f"position and velocity (flagged invalid on {100 * (1 - frac):.0f} % "
                "of the flight; left out: IMU-only recording)"
            )
            notes.append(
                f"position/velocity flagged invalid on {100 * (1 - frac):.0f} % of the "
                "flight: left out (IMU-only recording)"
            )
    need = [k for k in ("q", "w", "acc", "pos", "vel", "u") if k in res]
    keep &= np.all(
        np.stack([np.all(np.isfinite(res[k].reshape(len(t), -1)), axis=1) for k in need]), axis=0
    )
    if keep.sum() < 20:
        raise RecordingError(path, f"fewer than 20 usable rows in flight ({how})")
    t, res = t[keep], {k: v[keep] for k, v in res.items()}
    if "pos" not in res and "acc" not in res:
        raise RecordingError(path, "no accelerometer and no valid position: nothing to diagnose")

    constants, assumed = {}, []
    if vehicle is None:
        vehicle, constants, assumed, warns = field_vehicle(
            log, mass=mass, inertia=inertia, arm=arm, torque_coefficient=torque_coefficient
        )
        notes += warns
    else:
        if vehicle.n_rotors != 4:
            raise ConfigError(
                f"quadfault imports quadrotors; the vehicle has {vehicle.n_rotors} rotors"
            )
        if mass is not None:
            vehicle = vehicle.replace(mass=float(mass))
        constants["vehicle"] = f"from {vehicle_source}"
    u = np.clip(res["u"], 0.0, 1.0)
    meta_cal = None
    if thrust_curve is None:
        base = tuple(float(c) for c in log.thrust_model)
        longest = max(spans, key=lambda s: s[1] - s[0])
        if calibration is None:
            span = longest[1] - longest[0]
            calibration = (longest[0], longest[0] + CALIBRATION_FRACTION * span)
        measured = _measured_thrust(res, vehicle)
        mask = calibration_mask(t, calibration)
        if measured is None:  # no accelerometer: hover on average over the segment
            measured = np.full(len(t), vehicle.mass * vehicle.gravity)
            cal_method = (
                "mean(sum f_i) = m g over the segment (no accelerometer: level flight "
                "on average assumed)"
            )
        else:
            cal_method = "mean(sum f_i) = mean(-m a_z) over the segment (accelerometer)"
        thrust_curve, scale = scale_curve_on_segment(base, u, measured, mask)
        meta_cal = {
            "segment": [float(x) for x in calibration],
            "fitted": {"thrust_scale": scale, "thrust_curve": list(thrust_curve)},
            "thrust_model": log.thrust_note,
            "method": cal_method,
            "score_on": "the rest of the recording; exclude this segment when scoring",
        }
    thrust_curve = tuple(float(c) for c in thrust_curve)
    top = float(curve_thrust(thrust_curve, np.ones((1, 1)))[0, 0])
    if top > 0 and "vehicle" not in constants:
        vehicle = vehicle.replace(max_thrust=top)
        constants["max_thrust"] = "the thrust curve at full command"
    rates = {}
    for name, (ts, _, _) in log.streams.items():
        ts = np.unique(np.asarray(ts, dtype=float))
        if len(ts) > 1:
            rates[name] = float(1.0 / np.median(np.diff(ts)))
    battery = None
    if "vbat" in res:
        battery = battery_check(t, res["vbat"], _span_mask(t, spans), log.cells)
        if battery is not None and not battery["plausible"]:
            notes.append("implausible battery voltage: " + battery["why"])
    meta = {
        "dataset": f"{log.importer}-log",
        "file": path.name,
        "import": {
            "importer": log.importer,
            "segment": [float(t[0]), float(t[-1])],
            "flight_spans": [[float(a), float(b)] for a, b in spans],
            "flight_span_from": how,
            "trimmed": not keep_all,
            "dropped_duplicate_times": dropped,
            **gap_stats(t),
            "missing": missing,
            "commands": log.commands,
            "stream_rates_hz": rates,
            "warnings": notes,
        },
        "constants": constants,
        "assumed": assumed,
        "log_parameters": log.params,
    }
    if battery is not None:
        meta["import"]["battery"] = battery
    if log.skipped:
        meta["import"]["skipped"] = dict(log.skipped)
    if meta_cal:
        meta["calibration"] = meta_cal
    rotor = res.get("rotor")
    if rotor is not None and not np.any(np.isfinite(rotor)):
        rotor = None
    return Recording(
        t=t,
        omega=res["w"],
        accel=res.get("acc"),
        position=res.get("pos"),
        velocity=res.get("vel"),
        quaternion=res["q"] if "pos" in res else None,
        vbat=res.get("vbat"),
        rotor_speed=rotor,
        thrust_cmd=curve_thrust(thrust_curve, u),
        commands_u=u,
        thrust_curve=thrust_curve,
        vehicle=vehicle,
        frame="NED",
        source=log.source or f"{log.importer} log {path.name}, imported by quadfault",
        meta=meta,
        extra={} if "current" not in res else {"current": res["current"]},
    )
