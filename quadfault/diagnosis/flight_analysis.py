"""Per-flight analyses of imported real logs (used by ``benchmarks/real_flights.py``).

* :func:`efficiency_fit` -- per-rotor efficiency of one flight: the diagnosis' own
  ``motor_efficiency`` effect (its library, replay and bounded robust least squares) fitted on
  the airborne blocks only, with a time-blocked held-out score. On a closed-loop flight this
  is the moment balance: the controller keeps the body level, so the mean moment of
  ``eta_i f_i`` must vanish (roll, pitch, yaw) and the sum must carry the weight.
* :func:`effect_fit` -- the same for any set of library effects fitted jointly (e.g. ``drag``
  and ``motor_lag`` on every flight, whether or not the diagnosis' selection accepts them),
  with held-out improvements per channel group.
* :func:`airborne` -- which times of a flight are airborne (the estimators' cross-check
  ``estimators.flight_efficiency.irls_efficiency`` takes its medians over them).
* :func:`rotational_check` -- why a nominal rotational model disagrees with a log: the gain
  of measured over modelled angular acceleration in a frequency band (from the commands and,
  when logged, from the measured rotor speeds), and how much of the slow moment the model
  cannot explain is a rotor-drag (blade-flapping) moment ``M = -c T (v_body x e_z)`` (body
  FRD), i.e. proportional to the thrust times the horizontal body-frame velocity.
* :func:`without_calibration` -- the recording without the importer's calibration segment,
  for held-out scores that never see the data a constant was fitted on.

Estimators and the diagnosis never read truth; these functions strip it first.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.signal import butter, csd, filtfilt, welch

from quadfault.diagnosis.fit import fit
from quadfault.diagnosis.library import build_library, predict
from quadfault.diagnosis.residuals import noise_scale, prepare
from quadfault.errors import ConfigError
from quadfault.io.recording import Recording
from quadfault.model.effects.motor_efficiency import MotorEfficiency
from quadfault.model.rotation import quat_to_rot

MIN_HEIGHT = 0.3  # [m] above the first sample: "airborne"


@dataclass(frozen=True)
class EfficiencyFit:
    """Per-rotor efficiency of one flight.

    Attributes:
        eta: fitted efficiency per rotor [-] (1 = the importer's nominal thrust curve).
        sd: one-sigma uncertainty from the Jacobian [-] (blocks treated as independent, so
            optimistic; the flight-to-flight spread is the honest error bar).
        improvement: held-out reduction of the normalised residual RMS over all channels
            (5 contiguous folds of the airborne blocks; scored outside the importer's
            calibration segment) [-].
        improvement_angular: the same over the angular channels only [-].
        blocks: airborne blocks used.
    """

    eta: tuple
    sd: tuple
    improvement: float
    improvement_angular: float
    blocks: int


def airborne(rec: Recording, t: np.ndarray, min_height: float | None = MIN_HEIGHT) -> np.ndarray:
    """Boolean mask of times ``t`` [s] at which the vehicle is more than ``min_height`` [m]
    above its first sample (None: any height) with the rotors carrying at least half the
    weight."""
    thrust = rec.thrust_cmd.sum(axis=1)
    ok = np.interp(t, rec.t, thrust) > 0.5 * rec.vehicle.mass * rec.vehicle.gravity
    if min_height is None:
        return ok
    height = -(rec.position[:, 2] - rec.position[0, 2])  # NED: up is -z
    return ok & (np.interp(t, rec.t, height) > min_height)


def without_calibration(rec: Recording) -> Recording:
    """A copy without the rows of the importer's calibration segment
    (``meta["calibration"]["segment"]``), so that a fit on the copy is scored on data the
    importer did not use; the cut becomes a gap, which the diagnosis never bridges."""
    seg = (rec.meta.get("calibration") or {}).get("segment")
    if not seg:
        return rec
    keep = (rec.t < seg[0]) | (rec.t > seg[1])

    def cut(a):
        return None if a is None else a[keep]

    meta = dict(rec.meta, scored_without_calibration_segment=list(seg))
    return replace(
        rec,
        t=rec.t[keep],
        omega=rec.omega[keep],
        thrust_cmd=rec.thrust_cmd[keep],
        position=cut(rec.position),
        velocity=cut(rec.velocity),
        quaternion=cut(rec.quaternion),
        accel=cut(rec.accel),
        vbat=cut(rec.vbat),
        rotor_speed=cut(rec.rotor_speed),
        eta_true=cut(rec.eta_true),
        commands_u=cut(rec.commands_u),
        extra={k: v[keep] for k, v in rec.extra.items()},
        meta=meta,
    )


def _rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


@dataclass(frozen=True)
class EffectFit:
    """Named library effects fitted jointly on the selected blocks of one flight.

    Attributes:
        names: the effects (diagnosis library names), in fit order.
        x: parameter vector per effect, in the library's units (``drag``: k [N s/m] per
            body axis; ``motor_lag``: tau [s]; ``motor_efficiency``: eta [-]).
        sd: one-sigma uncertainty per parameter from the Jacobian (blocks treated as
            independent, so optimistic; the flight-to-flight spread is the honest error bar).
        improvement: held-out reduction of the normalised residual RMS, 5 contiguous folds
            of the selected blocks, scored outside the importer's calibration segment, per
            channel group: ``all``, ``translational`` (acc/sf channels), ``angular`` [-].
        blocks: blocks used.
    """

    names: tuple
    x: tuple
    sd: tuple
    improvement: dict
    blocks: int


def effect_fit(
    rec: Recording, names, min_height: float | None = MIN_HEIGHT, folds: int = 5
) -> EffectFit:
    """Fit the diagnosis' library effects ``names`` jointly on the blocks of ``rec`` where
    the vehicle is airborne (:func:`airborne`; IMU-only logs: where it carries its weight)."""
    rec = rec.without_truth()
    if min_height is not None and not rec.has_pose:
        raise ConfigError("a minimum height needs a recording with position; pass None")
    rp = prepare(rec)
    library = {c.name: c for c in build_library(rp)}
    unknown = [n for n in names if n not in library]
    if unknown:
        raise ConfigError(f"unknown effect {unknown[0]!r}")
    cands = [library[n] for n in names]
    air = airborne(rec, rp.block_t, min_height)
    idx = np.flatnonzero(air)
    if idx.size < 5 * folds:
        raise ConfigError(f"only {idx.size} airborne blocks; need {5 * folds}")
    base = rp.measured - predict(rp, [])
    scale = noise_scale(rp, base)
    full = fit(rp, cands, scale, mask=air)
    after = np.empty_like(rp.measured)
    for part in np.array_split(idx, folds):  # time-blocked held-out score
        train = air.copy()
        train[part] = False
        f = fit(rp, cands, scale, mask=train, init=list(full.x))
        after[part] = rp.measured[part] - predict(rp, f.terms)[part]
    seg = (rec.meta.get("calibration") or {}).get("segment")
    scored = idx
    if seg:  # score outside the importer's calibration segment
        bt = rp.block_t[idx]
        scored = idx[(bt < seg[0]) | (bt > seg[1])]
        if scored.size < folds:
            scored = idx
    zb, za = base[scored] / scale, after[scored] / scale
    groups = {
        "all": list(range(len(rp.channels))),
        "translational": [i for i, c in enumerate(rp.channels) if not c.startswith("alpha")],
        "angular": [i for i, c in enumerate(rp.channels) if c.startswith("alpha")],
    }
    imp = {g: 1.0 - _rms(za[:, cols]) / _rms(zb[:, cols]) for g, cols in groups.items() if cols}
    return EffectFit(
        names=tuple(names),
        x=tuple(tuple(float(v) for v in x) for x in full.x),
        sd=tuple(tuple(float(v) for v in s) for s in full.sd),
        improvement=imp,
        blocks=int(idx.size),
    )


def efficiency_fit(
    rec: Recording, min_height: float | None = MIN_HEIGHT, folds: int = 5
) -> EfficiencyFit:
    """Fit the diagnosis' ``motor_efficiency`` effect on the airborne blocks of ``rec``."""
    ef = effect_fit(rec, (MotorEfficiency.name,), min_height, folds)
    return EfficiencyFit(
        eta=ef.x[0],
        sd=ef.sd[0],
        improvement=ef.improvement["all"],
        improvement_angular=ef.improvement["angular"],
        blocks=ef.blocks,
    )


@dataclass(frozen=True)
class RotationalCheck:
    """Nominal rotational model vs the log (body FRD).

    Attributes:
        band_hz: frequency band of the gains [Hz].
        gain_cmd: per axis, |H| of measured over modelled angular acceleration in the band
            (modelled from the commanded thrusts) [-]; 1 = the model is right.
        phase_cmd_deg: per axis, phase of that response in the band [deg] (0: in phase;
            a wrong torque sign or axis gives about 180, a lag a negative phase).
        gain_rotor, phase_rotor_deg: the same with thrusts k omega^2 from the measured rotor
            speeds (None when the log has none).
        slow_moment_rms: RMS of the unexplained roll/pitch moment below ``cutoff_hz`` [N m].
        drag_moment_fraction: fraction of that slow moment's variance explained by
            ``M = c T (v_by, -v_bx)`` plus a constant offset [-].
        drag_moment_c: fitted ``c`` for roll and pitch [m s / m] (the aerodynamic moment is
            ``-c T v_by`` about x and ``+c T v_bx`` about y: nose up when flying forward).
    """

    band_hz: tuple
    gain_cmd: tuple
    phase_cmd_deg: tuple
    gain_rotor: tuple | None
    phase_rotor_deg: tuple | None
    slow_moment_rms: tuple
    drag_moment_fraction: tuple
    drag_moment_c: tuple


def _band_response(x: np.ndarray, y: np.ndarray, fs: float, band) -> tuple:
    """``(gain, phase [deg])`` of y on x over ``band``: summed cross-spectrum over summed
    auto-spectrum of x (Welch)."""
    n = int(min(256, len(x) // 4))
    f, pxy = csd(x, y, fs=fs, nperseg=n)
    _, pxx = welch(x, fs=fs, nperseg=n)
    sel = (f >= band[0]) & (f <= band[1])
    h = np.sum(pxy[sel]) / np.sum(pxx[sel])
    return float(np.abs(h)), float(np.degrees(np.angle(h)))


def rotational_check(
    rec: Recording,
    thrust_coefficient: float | None = None,
    band=(2.0, 16.0),
    cutoff_hz: float = 1.0,
) -> RotationalCheck:
    """See :class:`RotationalCheck`; ``thrust_coefficient`` k [N/(rad/s)^2] turns the logged
    rotor speeds (``rec.rotor_speed``) into thrusts for the second gain."""
    rec = rec.without_truth()
    veh = rec.vehicle
    dt = float(np.median(np.diff(rec.t)))
    fs = 1.0 / dt
    J = np.diag(veh.inertia)
    alpha = np.gradient(rec.omega, rec.t, axis=0)

    def model_alpha(f):
        return (f @ veh.allocation.T)[:, 1:] / J

    cmd = [
        _band_response(model_alpha(rec.thrust_cmd)[:, i], alpha[:, i], fs, band) for i in range(3)
    ]
    rotor = None
    if rec.rotor_speed is not None and thrust_coefficient is not None:
        f_rotor = thrust_coefficient * rec.rotor_speed**2
        f_rotor = np.where(np.isfinite(f_rotor), f_rotor, np.nanmedian(f_rotor, axis=0))
        rotor = [
            _band_response(model_alpha(f_rotor)[:, i], alpha[:, i], fs, band) for i in range(3)
        ]
    # slow moment the model leaves: M_rotors - J alpha, below cutoff_hz
    f = rec.thrust_cmd
    moment = (f @ veh.allocation.T)[:, 1:3] - alpha[:, :2] * J[:2]
    b, a = butter(2, cutoff_hz, fs=fs)
    slow = filtfilt(b, a, moment, axis=0)
    R = quat_to_rot(rec.quaternion)
    v_body = np.einsum("nji,nj->ni", R, rec.velocity)
    T = f.sum(axis=1)
    fractions, coefs = [], []
    for axis, regressor in ((0, T * v_body[:, 1]), (1, -T * v_body[:, 0])):
        X = np.column_stack((np.ones_like(T), T, regressor))
        coef, *_ = np.linalg.lstsq(X, slow[:, axis], rcond=None)
        r0 = slow[:, axis] - X[:, :2] @ np.linalg.lstsq(X[:, :2], slow[:, axis], rcond=None)[0]
        r1 = slow[:, axis] - X @ coef
        fractions.append(float(1.0 - np.var(r1) / np.var(r0)))
        coefs.append(float(coef[2]))
    return RotationalCheck(
        band_hz=tuple(band),
        gain_cmd=tuple(g for g, _ in cmd),
        phase_cmd_deg=tuple(p for _, p in cmd),
        gain_rotor=None if rotor is None else tuple(g for g, _ in rotor),
        phase_rotor_deg=None if rotor is None else tuple(p for _, p in rotor),
        slow_moment_rms=tuple(float(x) for x in slow.std(axis=0)),
        drag_moment_fraction=tuple(fractions),
        drag_moment_c=tuple(coefs),
    )
