"""Crazyflie uSD-deck event logs (``crazyflie-usd``): the binary log the Crazyflie firmware
writes to the micro-SD card deck.

The bytes -- header, event definitions, timestamped records, the CRC32 appended when logging
is stopped -- are read by :mod:`quadfault.io.importers.usd_format`, written from Bitcraze's
public description of the format. A log without the CRC (logging not stopped, or the file
cut) gets a warning; corrupt records are stepped over and reported.

The variables read (Crazyflie log names; world z up, body FLU, converted to NED/FRD):
``stateEstimate.x/y/z`` [m], ``vx/vy/vz`` [m/s], ``qx/qy/qz/qw`` (body -> world); without
them the motion-capture pose sent to the vehicle (``locSrv.x/y/z``, ``locSrv.qx..qw``; the
velocity is then its time derivative); ``gyro.x/y/z`` [deg/s]; ``acc.x/y/z`` [g]; the motor
commands ``motor.m1..m4`` (0-65535, the controller's request before the firmware's
battery compensation), else the applied ``pwm.m1_pwm..m4_pwm``; ``rpm.m1..m4`` (RPM deck)
[rpm]; ``pm.vbat`` [V]. Each comes from whichever event type logs it, at that event's
rate; the recording is resampled onto the gyro's stamps (the fastest stream where the
gyro is logged at the stabilizer rate) by
:func:`quadfault.io.importers.field_log.build_recording`, which does the flight span, the
thrust calibration and the rest as for the autopilot logs.

The vehicle: the user's ``--vehicle`` file, or a named preset (:data:`PRESETS`, the
constants of :mod:`quadfault.io.importers.crazyflie`), by default the Crazyflie 2.1
(brushed), said so in ``meta.assumed``.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quadfault.errors import ConfigError, RecordingError
from quadfault.io.importers.crazyflie import (
    CF21_BRUSHED,
    CF21_BRUSHLESS,
    FOERSTER_THRUST_CURVE,
    G_CRAZYFLIE,
)
from quadfault.io.importers.field_log import FieldLog, build_recording
from quadfault.io.importers.usd_format import parse_header, read_records
from quadfault.io.recording import Recording
from quadfault.model.frames import enu_flu_to_ned_frd

RPM_TO_RAD_S = 2.0 * np.pi / 60.0
PWM_FULL = 65536.0


@dataclass(frozen=True)
class Preset:
    """A named Crazyflie: its spec (mass, inertia, geometry, sources) and thrust map.

    Attributes:
        spec: :class:`quadfault.io.importers.crazyflie.CrazyflieSpec`.
        thrust_model: ``(a, b, c)``: per-rotor thrust a + b u + c u^2 [N or relative] of the
            command u = PWM / 65536, scaled on the calibration segment.
        thrust_note: where the map comes from, and what it assumes about the battery.
    """

    spec: object
    thrust_model: tuple
    thrust_note: str


#: name -> preset (``quadfault import LOG --preset NAME``)
PRESETS = {
    "crazyflie21": Preset(
        CF21_BRUSHED,
        FOERSTER_THRUST_CURVE,
        "Foerster 2015 per-rotor PWM map f = a + b u + c u^2 [N] (Crazyflie 2.0 motors on a "
        "bench supply; it has no battery term: with the firmware's battery compensation the "
        "command keeps its thrust as the battery drains, without it the fitted scale "
        "absorbs the mean voltage)",
    ),
    "crazyflie21-brushless": Preset(
        CF21_BRUSHLESS,
        (0.0, 1.0, 0.0),
        "linear in the command: Bitcraze's battery compensation for the Crazyflie 2.1 "
        "Brushless makes commanded thrust approximately linear and independent of the "
        "battery (firmware documentation, battery compensation); the scale is fitted",
    ),
}
DEFAULT_PRESET = "crazyflie21"


# ----------------------------------------------------------------------------------------
def _find(records: dict, events: dict, names) -> tuple | None:
    """``(t, (n, k) values, event name)`` of the event type that logs all ``names`` (the
    one with the most records), or None."""
    best = None
    for eid, (t, cols) in records.items():
        if all(n in cols for n in names) and (best is None or len(t) > len(best[0])):
            best = (t, np.stack([cols[n] for n in names], axis=1), events[eid].name)
    return best


def read_usd(path, preset: str = DEFAULT_PRESET) -> FieldLog:
    """The streams of a uSD event log (module docstring)."""
    path = Path(path)
    if not path.exists():
        raise RecordingError(path, "file not found")
    if preset not in PRESETS:
        raise ConfigError(f"unknown Crazyflie preset {preset!r}; choose from {', '.join(PRESETS)}")
    data = path.read_bytes()
    try:
        version, events, start = parse_header(data)
    except ValueError:
        raise RecordingError(
            path, "not a Crazyflie uSD event log (no readable 0xBC header)"
        ) from None
    except (IndexError, struct.error):
        raise RecordingError(path, "the uSD log is cut inside its header: nothing valid") from None
    end, notes = len(data), []
    has_crc = end - start >= 4 and zlib.crc32(data[: end - 4]) == int.from_bytes(
        data[end - 4 :], "little"
    )
    if has_crc:
        end -= 4
    records, skipped = read_records(data, start, end, events, version)
    logged = sorted(
        f"{events[e].name}: {', '.join(events[e].variables)}" for e in events if e in records
    )
    streams, missing = {}, []
    gyro = _find(records, events, ("gyro.x", "gyro.y", "gyro.z"))
    acc = _find(records, events, ("acc.x", "acc.y", "acc.z"))
    cmd = _find(records, events, tuple(f"motor.m{i}" for i in range(1, 5)))
    how = "motor.m1..m4 / 65536 (the controller's command)"
    if cmd is None:
        cmd = _find(records, events, tuple(f"pwm.m{i}_pwm" for i in range(1, 5)))
        how = "pwm.m1_pwm..m4_pwm / 65536 (the applied PWM, after battery compensation)"
    lacking = [
        what
        for what, got in (
            ("body rates (gyro.x, gyro.y, gyro.z)", gyro),
            ("motor commands (motor.m1..m4 or pwm.m1_pwm..m4_pwm)", cmd),
        )
        if got is None
    ]
    if lacking:
        has = "; ".join(logged) if logged else "no records"
        raise RecordingError(
            path, f"cannot import: no {' and no '.join(lacking)} (the log has {has})"
        )
    _, _, _, om, _ = enu_flu_to_ned_frd(None, None, None, np.radians(gyro[1]), None)
    streams["w"] = (gyro[0], om, "linear")
    if acc is not None:
        _, _, _, _, a = enu_flu_to_ned_frd(None, None, None, None, acc[1] * G_CRAZYFLIE)
        streams["acc"] = (acc[0], a, "linear")
    else:
        missing.append("accelerometer (acc.x, acc.y, acc.z)")
    streams["u"] = (cmd[0], np.clip(cmd[1] / PWM_FULL, 0.0, 1.0), "hold")
    pose_note = _pose(records, events, streams, missing)
    if pose_note:
        notes.append(pose_note)
    rpm = _find(records, events, tuple(f"rpm.m{i}" for i in range(1, 5)))
    if rpm is not None:
        streams["rotor"] = (rpm[0], np.abs(rpm[1]) * RPM_TO_RAD_S, "linear")
    else:
        missing.append("rotor speed (rpm.m1..m4, the RPM deck)")
    vbat = _find(records, events, ("pm.vbat",))
    if vbat is not None:
        v = vbat[1][:, 0]
        streams["vbat"] = (vbat[0], np.where(v > 0, v, np.nan), "linear")
    else:
        missing.append("battery voltage (pm.vbat)")
    if not has_crc:
        notes.append("no CRC32 at the end (logging was not stopped, or the file was cut)")
    damage = None
    if skipped["bytes"]:
        damage = {
            "what": ("corrupt records" if skipped["gaps"] else "")
            + (" and " if skipped["gaps"] and skipped["tail"] else "")
            + ("the log ends mid-record (cut)" if skipped["tail"] else ""),
            "bytes": skipped["bytes"],
            "truncated": bool(skipped["tail"]),
            "corrupt": len(skipped["gaps"]),
            "after_t": float(gyro[0][-1]) if skipped["tail"] else None,
            "spans": skipped["gaps"],
        }
    chosen = PRESETS[preset]
    rates = {
        events[e].name: round(float(1.0 / np.median(np.diff(t))), 1)
        for e, (t, _) in records.items()
        if len(t) > 2 and np.median(np.diff(t)) > 0
    }
    return FieldLog(
        path=path,
        importer="crazyflie-usd",
        streams=streams,
        time_base=gyro[0],
        thrust_model=chosen.thrust_model,
        thrust_note=chosen.thrust_note,
        commands=how,
        missing=missing,
        params={
            "usd_version": version,
            "event_types": sorted(ev.name for ev in events.values()),
            "event_rates_hz": rates,
        },
        source=f"Crazyflie uSD event log {path.name}, imported by quadfault",
        warnings=notes,
        cells=(1, "a Crazyflie flies on one LiPo cell"),
        skipped=damage,
    )


def _pose(records: dict, events: dict, streams: dict, missing: list) -> str | None:
    """Position, velocity and attitude from ``stateEstimate`` (else the motion-capture pose
    ``locSrv``) into ``streams``; a note when the pose is the motion capture's."""
    pos = _find(records, events, ("stateEstimate.x", "stateEstimate.y", "stateEstimate.z"))
    vel = _find(records, events, ("stateEstimate.vx", "stateEstimate.vy", "stateEstimate.vz"))
    quat = _find(
        records,
        events,
        ("stateEstimate.qw", "stateEstimate.qx", "stateEstimate.qy", "stateEstimate.qz"),
    )
    note = None
    if pos is None or quat is None:
        mpos = _find(records, events, ("locSrv.x", "locSrv.y", "locSrv.z"))
        mquat = _find(records, events, ("locSrv.qw", "locSrv.qx", "locSrv.qy", "locSrv.qz"))
        if mpos is not None and mquat is not None:
            pos, quat, vel = mpos, mquat, None
            note = "pose from the motion capture sent to the vehicle (locSrv), no stateEstimate"
    if pos is None or quat is None:
        missing.append(
            "position, velocity and attitude (stateEstimate.x/y/z, vx/vy/vz, qx/qy/qz/qw, "
            "or the motion-capture pose locSrv)"
        )
        return None
    if vel is None:
        order = np.argsort(pos[0], kind="stable")
        t, p = pos[0][order], pos[1][order]
        keep = np.r_[True, np.diff(t) > 0]
        t, p = t[keep], p[keep]
        vel = (t, np.gradient(p, t, axis=0), "")
        note = (note + "; " if note else "") + "velocity from the position's time derivative"
    p, v, q, _, _ = enu_flu_to_ned_frd(pos[1], None, quat[1], None, None)
    _, v, _, _, _ = enu_flu_to_ned_frd(None, vel[1], None, None, None)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    streams["pos"] = (pos[0], p, "linear")
    streams["vel"] = (vel[0], v, "linear")
    streams["q"] = (quat[0], q, "quaternion")
    return note


def import_crazyflie_usd(
    path,
    *,
    vehicle=None,
    thrust_curve=None,
    keep_all: bool = False,
    calibration=None,
    mass=None,
    preset: str | None = None,
    **_ignored,
) -> Recording:
    """Import a Crazyflie uSD-deck event log.

    Args:
        path: the log file (``log00`` ...).
        vehicle: nominal :class:`quadfault.model.vehicle.Vehicle` (FRD, Crazyflie motor order
            M1..M4), e.g. from ``--vehicle``; default: the ``preset``'s.
        thrust_curve: ``(a, b, c)`` [N]; default the preset's map scaled on the calibration
            segment.
        keep_all: keep rows outside the flight span.
        calibration: ``(t0, t1)`` [s, the log's clock] for the thrust-scale fit.
        mass: take-off mass [kg] (default the preset's).
        preset: a name of :data:`PRESETS` (default the Crazyflie 2.1, said so in
            ``meta.assumed``).
    """
    name = preset or DEFAULT_PRESET
    log = read_usd(path, name)
    spec = PRESETS[name].spec
    constants, assumed = {}, []
    if vehicle is None:
        vehicle = spec.vehicle(mass=mass)
        constants = {k: f"{spec.name} preset: {v}" for k, v in spec.sources.items()}
        constants["thrust_curve"] = PRESETS[name].thrust_note
        if mass is not None:
            constants["mass"] = "from --mass"
        if preset is None:
            assumed.append(f"vehicle: the {spec.name} preset (give --preset or --vehicle)")
            log.warnings.append(
                f"assumed the {spec.name} preset (the log names no vehicle; give --preset "
                f"{' or --preset '.join(PRESETS)}, or --vehicle)"
            )
        source = f"the {spec.name} preset"
    else:
        source = "the user's vehicle file"
    rec = build_recording(
        log,
        vehicle=vehicle,
        vehicle_source=source,
        thrust_curve=thrust_curve,
        mass=mass if source == "the user's vehicle file" else None,
        keep_all=keep_all,
        calibration=calibration,
    )
    rec.meta["constants"].update(constants)
    rec.meta["assumed"] = list(rec.meta.get("assumed", [])) + assumed
    return rec
