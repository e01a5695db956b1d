"""What a recording can identify, decided before any fit.

A candidate effect is fitted only when the recording carries the evidence it needs; the
others are listed under ``not_identifiable`` with the reason, and no effect is ever accepted
on evidence the log lacks. Each effect declares its needs in its own module
(:class:`quadfault.model.effects.base.Identifiability`, read through
:func:`quadfault.model.effects.registry.identifiability`); this module holds the one gate that reads
them:

``channels`` / ``any_of``
    the channel groups must be logged (and valid: spans the recording flags invalid are left
    out of the diagnosis, :func:`invalid_spans`; when they cover more than
    ``MAX_INVALID_FRACTION`` of the flight the pose is not used at all -- an accelerometer
    log is then diagnosed from its IMU -- and the effects that need position, velocity or
    attitude are not identifiable).
``min_command_rate``
    the rotor commands must be logged at least this fast -- or, when the effect is shown
    ``direct``-ly by measured rotor speeds the log has, the rotor speeds. The rate is that of
    the changes (an importer that resamples a 10 Hz output onto a 250 Hz time base holds each
    command for 25 rows: the rate stays 10 Hz), or the rate of the stream as logged where the
    importer records it (``meta.import.stream_rates_hz``: ``u``, ``rotor``), whichever is
    slower: interpolated streams change at every row.
``direct``
    with measured rotor speeds, a time constant they show directly (``motor_lag``,
    ``delay``) comes from command to speed (:func:`pin_to_rotor_speeds`).
``timescale``
    a time constant is seen only through commands logged at ``TIMING_SAMPLES`` (2) or more
    samples per time constant: a fitted value below two command periods is rejected, and
    the effect is not identifiable when two periods exceed half of the candidate's range.

Invalid spans are read from the sidecar's ``invalid`` object (``{"velocity": [[t0, t1],
...], "position": [...]}`` [s]) or from 0/1 columns ``velocity_valid`` / ``position_valid``.

The nominal vehicle's mass, inertia, geometry and yaw coefficient may be assumed (the
sidecar's ``assumed`` list, e.g. ``["mass", "inertia"]``, written by the importers): :func:`assumptions` says which results scale with them
(:data:`DEPENDS_ON`) and which do not (ratios between rotors, time constants).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from quadfault.diagnosis.fit import fit
from quadfault.diagnosis.library import build_library
from quadfault.diagnosis.phases import excluded_fraction
from quadfault.diagnosis.residuals import rotor_speeds
from quadfault.errors import ConfigError, RecordingError
from quadfault.io.recording import Recording
from quadfault.model.effects.base import ASSUMABLE
from quadfault.model.effects.registry import identifiability
from quadfault.model.effects.registry import names as effect_names

TIMING_SAMPLES = 2.0
MAX_INVALID_FRACTION = 0.5

#: assumed constants each effect's fitted value scales with (each effect's declaration,
#: ``Identifiability.scales_with``; effects not listed: none -- time constants, and
#: motor_efficiency's eta relative to the median rotor)
DEPENDS_ON = {
    n: identifiability(n).scales_with for n in effect_names() if identifiability(n).scales_with
}


@dataclass(frozen=True)
class Evidence:
    """What a recording carries.

    Attributes:
        command_period: median time between changes of the rotor commands [s] (inf when they
            never change).
        sample_period: median row spacing [s].
        rotor_speed_period: the same for measured rotor speeds [s], or None.
        pose, accel, vbat: position/velocity/attitude, accelerometer, battery voltage logged.
        invalid: ``{"velocity": ((t0, t1), ...), ...}`` spans flagged invalid [s].
        invalid_fraction: fraction of the recording where the velocity is invalid.
        assumed: nominal constants the recording says are assumed (``"mass"``, ``"inertia"``).
    """

    command_period: float
    sample_period: float
    rotor_speed_period: float | None
    pose: bool
    accel: bool
    vbat: bool
    invalid: dict
    invalid_fraction: float
    assumed: tuple = ()

    @property
    def shortest_time_constant(self) -> float:
        """The shortest time constant the logged commands resolve [s]."""
        return TIMING_SAMPLES * self.command_period

    def to_dict(self) -> dict:
        """The rates and channels as reported in the diagnosis JSON (``evidence``)."""

        def hz(period):
            return None if period is None or not np.isfinite(period) else 1.0 / period

        return {
            "command_rate_hz": hz(self.command_period),
            "sample_rate_hz": hz(self.sample_period),
            "rotor_speed_rate_hz": hz(self.rotor_speed_period),
            "shortest_time_constant_s": (
                self.shortest_time_constant if np.isfinite(self.command_period) else None
            ),
            "pose": self.pose,
            "pose_valid": self.pose_valid,
            "velocity_invalid_fraction": self.invalid_fraction,
            "accelerometer": self.accel,
            "battery": self.vbat,
            "assumed": list(self.assumed),
        }

    @property
    def pose_valid(self) -> bool:
        return self.pose and self.invalid_fraction <= MAX_INVALID_FRACTION


def change_period(t: np.ndarray, x: np.ndarray | None) -> float | None:
    """Median time between rows where any column of ``x`` changes [s] (inf when fewer than
    two changes); None without ``x``."""
    if x is None:
        return None
    x = np.asarray(x, dtype=float).reshape(len(t), -1)
    d = np.diff(x, axis=0)
    changed = np.flatnonzero(np.any((d != 0) & np.isfinite(d), axis=1)) + 1
    if changed.size < 3:
        return float("inf")
    return float(np.median(np.diff(t[changed])))


def _spans_from_column(t, flag) -> tuple:
    bad = ~(np.asarray(flag, dtype=float) > 0.5)
    if not bad.any():
        return ()
    edges = np.flatnonzero(np.diff(np.r_[0, bad.astype(int), 0]))
    return tuple(
        (float(t[a]), float(t[min(b, len(t) - 1)])) for a, b in zip(edges[::2], edges[1::2])
    )


def invalid_spans(rec: Recording) -> dict:
    """``{"velocity": ((t0, t1), ...), "position": (...)}``: spans [s] the recording flags
    invalid (sidecar ``invalid`` object, or 0/1 columns ``velocity_valid``/``position_valid``)."""
    out = {}
    declared = (rec.meta or {}).get("invalid") or {}
    if not isinstance(declared, dict):
        raise RecordingError(
            rec.path or "recording",
            'must be an object {"velocity": [[t0, t1], ...]}',
            key="invalid",
        )
    for key in ("velocity", "position"):
        spans = []
        for s in declared.get(key) or ():
            try:
                a, b = (float(v) for v in s)
            except (TypeError, ValueError):
                raise RecordingError(
                    rec.path or "recording",
                    f"invalid.{key} must list [t0, t1] spans in seconds, got {s!r}",
                    key="invalid",
                ) from None
            spans.append((a, b))
        col = rec.extra.get(f"{key}_valid")
        if col is not None:
            spans += list(_spans_from_column(rec.t, col))
        if spans:
            out[key] = tuple(sorted(spans))
    return out


def evidence(rec: Recording) -> Evidence:
    """What ``rec`` carries (:class:`Evidence`)."""
    if not isinstance(rec, Recording):
        raise ConfigError(f"diagnosis needs a Recording, got {type(rec).__name__}")
    t = np.asarray(rec.t, dtype=float)
    cmd = rec.commands_u if rec.commands_u is not None else rec.thrust_cmd
    W = rotor_speeds(rec)
    invalid = invalid_spans(rec) if rec.has_pose else {}
    spans = [s for k in ("velocity", "position") for s in invalid.get(k, ())]
    frac = excluded_fraction(spans, float(t[0]), float(t[-1])) if spans else 0.0
    assumed = (rec.meta or {}).get("assumed") or ()
    if isinstance(assumed, str):
        assumed = (assumed,)
    command_period = change_period(t, cmd)
    rotor_period = None if W is None else change_period(t, W)
    source = _source_rates(rec)  # the importer's rates of the streams before resampling
    if "u" in source:
        command_period = max(command_period, 1.0 / source["u"])
    if rotor_period is not None and "rotor" in source:
        rotor_period = max(rotor_period, 1.0 / source["rotor"])
    return Evidence(
        command_period=command_period,
        sample_period=float(np.median(np.diff(t))),
        rotor_speed_period=rotor_period,
        pose=rec.has_pose,
        accel=rec.accel is not None,
        vbat=rec.vbat is not None,
        invalid=invalid,
        invalid_fraction=frac,
        assumed=tuple(str(a) for a in assumed if a in ASSUMABLE),
    )


def _source_rates(rec: Recording) -> dict:
    """``{"u": Hz, "rotor": Hz}``: the rates of the command and rotor-speed streams as logged,
    before an importer resampled them (``meta.import.stream_rates_hz``), where it says."""
    rates = ((rec.meta or {}).get("import") or {}).get("stream_rates_hz") or {}
    out = {}
    for key in ("u", "rotor"):
        try:
            v = float(rates[key])
        except (KeyError, TypeError, ValueError):
            continue
        if np.isfinite(v) and v > 0:
            out[key] = v
    return out


def without_pose(rec: Recording) -> Recording:
    """``rec`` as an IMU-only log (its pose is not valid)."""
    return dataclasses.replace(rec, position=None, velocity=None, quaternion=None)


def _present(group: str, ev: Evidence) -> str:
    """Why channel group ``group`` is not usable, or ""."""
    if group in ("position", "velocity", "attitude"):
        if not ev.pose:
            return f"no {group} in the log"
        if not ev.pose_valid:
            return (
                f"no valid {group}: the log flags the velocity or position invalid over "
                f"{100 * ev.invalid_fraction:.0f}% of the flight"
            )
        return ""
    have = {
        "accelerometer": ev.accel,
        "battery": ev.vbat,
        "body_rate": True,
        "rotor_speed": ev.rotor_speed_period is not None,
    }
    names = {
        "accelerometer": "accelerometer",
        "battery": "battery voltage",
        "rotor_speed": "measured rotor speed",
        "body_rate": "body rates",
    }
    return "" if have.get(group, False) else f"no {names.get(group, group)} in the log"


def _why_not(cand, ev: Evidence) -> str:
    need = identifiability(cand.name)
    for group in need.channels:
        why = _present(group, ev)
        if why:
            return why
    if need.any_of and all(_present(g, ev) for g in need.any_of):
        return "none of " + ", ".join(need.any_of) + " in the log"
    direct = "rotor_speed" in need.direct and ev.rotor_speed_period is not None
    if need.min_command_rate is not None:
        period = ev.command_period
        if not np.isfinite(period):
            return "the rotor commands never change"
        if direct:  # rotor speeds show it directly: the faster of the two streams counts
            period = min(period, ev.rotor_speed_period)
        if 1.0 / period < need.min_command_rate:
            return (
                f"rotor commands logged at {1.0 / ev.command_period:.3g} Hz (needs "
                f"{need.min_command_rate:g} Hz"
                + (")" if not direct else " from the commands or rotor speeds)")
            )
    if need.timescale is not None:
        upper = float(cand.upper[0])
        if ev.shortest_time_constant > 0.5 * upper:
            return (
                f"rotor commands logged at {1.0 / ev.command_period:.3g} Hz resolve no "
                f"time constant below {ev.shortest_time_constant:.3g} s ("
                f"{TIMING_SAMPLES:g} samples per time constant); the candidate's range "
                f"ends at {upper:g} s"
            )
    return ""


def gate(library, ev: Evidence) -> tuple[list, list]:
    """``(candidates to fit, [{"name", "reason"}, ...])``: the timing candidates that stay
    carry the shortest time constant the commands resolve (``resolvable``)."""
    keep, out = [], []
    for c in library:
        why = _why_not(c, ev)
        if why:
            out.append({"name": c.name, "reason": why})
            continue
        if identifiability(c.name).timescale and ev.shortest_time_constant > 0:
            c = dataclasses.replace(c, resolvable=float(ev.shortest_time_constant))
        keep.append(c)
    return keep, out


def too_short(cand, x) -> str:
    """Why the fitted time constant ``x`` of ``cand`` is below what its commands resolve, or
    ""."""
    floor = getattr(cand, "resolvable", 0.0)
    if floor > 0 and float(np.ravel(x)[0]) < floor:
        return (
            f"{cand.name} {float(np.ravel(x)[0]):.3g} s is shorter than {TIMING_SAMPLES:g} "
            f"command periods ({floor:.3g} s): the log cannot show it"
        )
    return ""


def assumptions(ev: Evidence, names) -> dict:
    """``{"assumed": [...], "depends": {name: [...]}, "independent": [...], "note"}`` for the
    effects ``names`` (empty when nothing is assumed)."""
    if not ev.assumed:
        return {}
    dep = {n: [a for a in DEPENDS_ON.get(n, ()) if a in ev.assumed] for n in names}
    depends = {n: a for n, a in dep.items() if a}
    independent = [n for n, a in dep.items() if not a]
    many = len(ev.assumed) > 1
    note = (
        f"the vehicle's {', '.join(ev.assumed).replace('_', ' ')} "
        f"{'are' if many else 'is'} assumed: forces, thrust factors and inertia-scaled "
        f"moments scale with {'them' if many else 'it'}; ratios between rotors "
        "(motor_efficiency's relative eta) and time constants (motor_lag, delay) do not"
    )
    return {
        "assumed": list(ev.assumed),
        "depends": depends,
        "independent": independent,
        "note": note,
    }


#: a parameter pinned by direct evidence may move this fraction inside its bounds
PIN_WIDTH = 1e-3


def pin_to_rotor_speeds(rp, library, sc) -> list:
    """With measured rotor speeds, the time constants that the rotor speeds show directly
    (the declaration's ``direct``: ``motor_lag``, ``delay``) come from command to speed: each
    is fitted on the ``rotor_*`` channels alone (with the command curve, ``thrust_curve``, of
    a ``u``-command log), and the candidate the selection sees is held
    at that value (``Candidate.pinned``); the selection still decides from every channel
    whether the effect is there."""
    if not rp.has_rotor:
        return list(library)
    rotor = np.array([c.startswith("rotor_") for c in rp.channels])
    scale = np.where(rotor, sc.divisor, 1e30)  # the other channels do not count
    # the static map from command to speed is fitted with it (a curve left out would
    # bend the time constant)
    static = [c for c in build_library(rp, ("thrust_curve",)) if c.testable(rp)]
    out = []
    for c in library:
        need = identifiability(c.name)
        if need.timescale is None or "rotor_speed" not in need.direct or not c.rotor_side:
            out.append(c)
            continue
        f = fit(rp, [c] + static, scale)
        x, sd = np.asarray(f.x[0], dtype=float), np.asarray(f.sd[0], dtype=float)
        lo = np.maximum(x * (1.0 - PIN_WIDTH), np.asarray(c.lower, dtype=float))
        hi = np.minimum(np.maximum(x * (1.0 + PIN_WIDTH), lo + 1e-9), np.asarray(c.upper, float))
        out.append(
            dataclasses.replace(
                c,
                lower=tuple(lo),
                upper=tuple(hi),
                starts=(tuple(x),),
                pinned=(tuple(x), tuple(sd)),
            )
        )
    return out
