"""Importers on the real data sets in ../shared/data/real (skipped when absent).

Physical sanity: the accelerometer reads (0, 0, -g) in FRD at rest, the thrust curve fitted on
the calibration segment predicts m g on the held-out rest, quaternions are unit, gyro rates
are plausible, and the allocation's roll / pitch / yaw signs agree with the measured angular
acceleration (moment from lagged commands vs d omega / dt).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.signal import lfilter

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"
ESCHMANN = REAL / "eschmann-cf21-sysid"
NANODRONE = REAL / "nanodrone-cf21bl"
CRAZYPAD = REAL / "crazypad-cf21-faults"
G = 9.81


def _need(folder: Path):
    if not folder.is_dir():
        pytest.skip(f"real data not available ({folder} is absent)")


def _moment_alpha_correlation(rec, tau: float, smooth_n: int) -> np.ndarray:
    """Correlation per axis between the moment of first-order-lagged commanded thrusts
    (allocation rows Mx, My, Mz) and the body angular acceleration."""
    dt = np.median(np.diff(rec.t))
    a = dt / (tau + dt)
    f = lfilter([a], [1.0, a - 1.0], rec.thrust_cmd, axis=0) if tau > 0 else rec.thrust_cmd
    moment = f @ rec.vehicle.allocation.T
    k = np.ones(smooth_n) / smooth_n
    w = np.stack([np.convolve(c, k, "same") for c in rec.omega.T], axis=1)
    alpha = np.gradient(w, rec.t, axis=0)
    return np.array([np.corrcoef(moment[:, i + 1], alpha[:, i])[0, 1] for i in range(3)])


def _held_out_thrust_ratio(rec, measured_thrust):
    seg = rec.meta["calibration"]["segment"]
    rest = (rec.t < seg[0]) | (rec.t > seg[1])
    return float(np.mean(measured_thrust[rest]) / np.mean(rec.thrust_cmd[rest].sum(1)))


# ----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def eschmann():
    _need(ESCHMANN)
    from quadfault.io.importers.eschmann import import_eschmann

    return {n: import_eschmann(ESCHMANN / f"{n}.csv.gz") for n in ("log10", "log15", "log16")}


@pytest.mark.slow
def test_eschmann_at_rest_reads_minus_g_in_frd():
    _need(ESCHMANN)
    from quadfault.io.importers.eschmann import import_eschmann

    rec = import_eschmann(ESCHMANN / "log10.csv.gz", keep_all=True)
    rest = rec.t < rec.meta["import"]["motors_running"][0] - 1.0
    assert rest.sum() > 1000
    np.testing.assert_allclose(rec.accel[rest].mean(0), [0, 0, -G], atol=0.3)
    assert np.abs(rec.omega[rest]).max() < 0.05  # [rad/s], a still gyro


@pytest.mark.slow
def test_eschmann_thrust_curve_and_rates(eschmann):
    scales = []
    for name, rec in eschmann.items():
        assert rec.meta["import"]["dropped_duplicate_times"] == 0
        assert np.all(np.diff(rec.t) > 0)
        t0, t1 = rec.meta["import"]["motors_running"]
        assert rec.t[0] == pytest.approx(t0) and rec.t[-1] == pytest.approx(t1)
        assert np.abs(rec.omega).max() < 35.0  # within the 2000 deg/s gyro range
        flying = rec.commands_u.max(1) > 0.3
        ratio = float(
            np.mean(-rec.vehicle.mass * rec.accel[flying, 2])
            / np.mean(rec.thrust_cmd[flying].sum(1))
        )
        assert ratio == pytest.approx(1.0, abs=0.1), name
        scales.append(rec.meta["calibration"]["fitted"]["thrust_scale"])
    # one airframe: the fitted scale of Foerster's curve agrees between flights
    assert 0.7 < min(scales) and max(scales) < 1.0 and np.ptp(scales) < 0.05


def test_eschmann_allocation_signs_agree_with_the_gyro(eschmann):
    # log15: roll/pitch inertia manoeuvres; commands lagged by the ~0.07 s motor delay
    c15 = _moment_alpha_correlation(eschmann["log15"], 0.07, 20)
    assert c15[0] > 0.7 and c15[1] > 0.7
    # log16: yaw manoeuvres
    c16 = _moment_alpha_correlation(eschmann["log16"], 0.07, 20)
    assert c16[2] > 0.4


def _first_order(t, u, tau):
    """Exact zero-order-hold discretisation of tau dx/dt = u - x on the log's own time grid."""
    x = np.empty_like(u)
    x[0] = u[0]
    a = 1.0 - np.exp(-np.diff(t) / tau)
    for k in range(1, len(u)):
        x[k] = x[k - 1] + a[k - 1] * (u[k - 1] - x[k - 1])
    return x


def test_eschmann_log10_shows_the_readme_motor_lag(eschmann):
    # README: on the thrust segment (35-65 s) the fit of m a_z to the summed thrust improves
    # by ~63 % when the commands pass through a ~0.08 s first-order lag
    from quadfault.model.effects import curve_thrust

    rec = eschmann["log10"]
    seg = (rec.t >= 35.0) & (rec.t <= 65.0)
    measured = -rec.vehicle.mass * rec.accel[seg, 2]

    def rmse(tau):
        u = rec.commands_u if tau == 0 else _first_order(rec.t, rec.commands_u, tau)
        return np.sqrt(np.mean((measured - curve_thrust(rec.thrust_curve, u[seg]).sum(1)) ** 2))

    taus = [0.03, 0.05, 0.08, 0.11, 0.15]
    errors = [rmse(tau) for tau in taus]
    assert 0.05 <= taus[int(np.argmin(errors))] <= 0.11
    assert min(errors) < 0.5 * rmse(0.0)


# ----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def nanodrone():
    _need(NANODRONE)
    from quadfault.io.importers.nanodrone import import_nanodrone

    return {p.name.split(".")[0]: import_nanodrone(p) for p in sorted(NANODRONE.glob("*.csv.gz"))}


@pytest.mark.slow
def test_nanodrone_physical_sanity(nanodrone):
    assert len(nanodrone) == 9
    for name, rec in nanodrone.items():
        np.testing.assert_allclose(np.linalg.norm(rec.quaternion, axis=1), 1.0, atol=1e-9)
        assert -10.8 < rec.accel[:, 2].mean() < -9.6, name  # body FRD specific force
        assert np.abs(rec.accel[:, :2].mean(0)).max() < 0.5, name
        assert np.abs(rec.omega).max() < 20.0, name  # README: up to ~9 rad/s (peaks 16)
        assert np.nanmax(rec.rotor_speed) < 3e5 * 2 * np.pi / 360  # spikes removed
        ratio = _held_out_thrust_ratio(rec, -rec.vehicle.mass * rec.accel[:, 2])
        assert ratio == pytest.approx(1.0, abs=0.03), name
        assert rec.meta["calibration"]["thrust_ratio_on_rest"] == pytest.approx(ratio)


def test_nanodrone_allocation_signs_agree_with_the_gyro(nanodrone):
    for name, rec in nanodrone.items():
        c = _moment_alpha_correlation(rec, 0.03, 3)
        assert c[2] > 0.25, name  # yaw: the data README's tau_z formula has the other sign
    for name in ("square_20251017_run3", "square_20251017_run4"):  # aggressive corners
        c = _moment_alpha_correlation(nanodrone[name], 0.03, 3)
        assert c[0] > 0.4 and c[1] > 0.4, name


# ----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def crazypad():
    _need(CRAZYPAD)
    from quadfault.io.importers.crazypad import import_crazypad

    folders = ("normal_flight", "cut_propeller_M3_3mm")
    return {
        f"{kind}/{p.parent.name}/{p.name}": import_crazypad(p)
        for kind in ("motor_data", "controller_data")
        for c in folders
        for p in sorted((CRAZYPAD / kind / c).glob("*.csv.gz"))
    }


def _m3_share(rec):
    air = -rec.position[:, 2] > 0.3
    u = rec.commands_u[air]
    return float(np.mean(u[:, 2]) / np.mean(u))


@pytest.mark.slow
def test_crazypad_motor_logs(crazypad):
    motor = {k: r for k, r in crazypad.items() if k.startswith("motor_data")}
    assert len(motor) == 18
    for name, rec in motor.items():
        assert rec.has_pose and rec.vbat is not None
        assert 3.0 < rec.vbat.min() and rec.vbat.max() < 4.3, name
        # reconstructed attitude predicts the logged roll
        assert rec.meta["import"]["roll_check_rms_deg"] < 3.0, name
        f_world = np.linalg.norm(
            np.gradient(rec.velocity, rec.t, axis=0) - np.array([0, 0, G]), axis=1
        )
        air = -rec.position[:, 2] > 0.3
        assert np.mean(rec.thrust_cmd[air].sum(1)) == pytest.approx(
            rec.vehicle.mass * np.mean(f_world[air]), rel=0.1
        ), name
    # README: the M3 command share is already > 1 in nominal flights (1.128) and grows with
    # a cut M3 propeller (1.218 at 3 mm)
    normal = [_m3_share(r) for k, r in motor.items() if "normal_flight" in k]
    cut = [_m3_share(r) for k, r in motor.items() if "cut_propeller" in k]
    assert 1.05 < np.mean(normal) < 1.2
    assert np.mean(cut) > np.mean(normal)


def test_crazypad_controller_logs(crazypad):
    from quadfault.model.rotation import quat_to_rot

    ctrl = {k: r for k, r in crazypad.items() if k.startswith("controller_data")}
    motor_normal = [_m3_share(r) for k, r in crazypad.items() if k.startswith("motor_data/normal")]
    ctrl_normal = [_m3_share(r) for k, r in ctrl.items() if "normal_flight" in k]
    # the reconstructed mixer gives the same command split as the logged motor commands
    assert abs(np.mean(ctrl_normal) - np.mean(motor_normal)) < 0.1
    for name, rec in ctrl.items():
        # gyro-integrated attitude: the thrust axis tilts the way the vehicle accelerates
        # (this fails if the firmware's pitch-rate sign is not undone)
        thrust_dir = -quat_to_rot(rec.quaternion)[:, :, 2]
        k = np.ones(25) / 25
        p = np.stack([np.convolve(c, k, "same") for c in rec.position.T], axis=1)
        acc = np.gradient(np.gradient(p, rec.t, axis=0), rec.t, axis=0)
        air = -rec.position[:, 2] > 0.3
        c = [np.corrcoef(thrust_dir[air, i], acc[air, i])[0, 1] for i in range(2)]
        assert min(c) > 0.0 and max(c) > 0.2, name


# ----------------------------------------------------------------------------------------
# autopilot logs: every log of each format in the real-data folder imports with physical sense
def _autopilot_logs(patterns):
    if not REAL.is_dir():
        return []
    return sorted(p for pat in patterns for p in REAL.glob(pat))


@pytest.mark.parametrize("path", _autopilot_logs(["*/*.ulg"]), ids=lambda p: p.name)
def test_px4_logs_import_with_physical_sense(path):
    pytest.importorskip("pyulog")
    from quadfault.io.importers import detect_format, get_importer

    assert detect_format(path) == "px4"
    rec = get_importer("px4")(path)
    u = rec.commands_u
    assert np.all((u >= 0) & (u <= 1)) and np.median(u) > 0.1  # flying, not idle
    sf = np.median(rec.accel[:, 2])
    assert -1.3 * G < sf < -0.7 * G  # FRD: the specific force in flight points up (-z)
    if rec.rotor_speed is not None:  # measured rotor speed rises with the command
        w, c = rec.rotor_speed.ravel(), u.ravel()
        ok = np.isfinite(w)
        assert np.corrcoef(w[ok], c[ok])[0, 1] > 0.5
    assert set(rec.meta["assumed"]) >= {"mass", "inertia"}  # ULogs carry neither


@pytest.mark.parametrize(
    "path", _autopilot_logs(["*/*.bin", "*/*.BIN", "ardupilot*/*.log"]), ids=lambda p: p.name
)
def test_ardupilot_logs_import_or_say_what_is_missing(path):
    pytest.importorskip("pymavlink")
    from quadfault.errors import QuadfaultError
    from quadfault.io.importers import detect_format, get_importer

    assert detect_format(path) == "ardupilot"
    try:
        rec = get_importer("ardupilot")(path)
    except QuadfaultError as exc:  # old logs lack channels: the error names what is missing
        assert "\n" not in str(exc) and path.name in str(exc)
        return
    assert np.median(rec.commands_u) > 0.1
    assert -1.3 * G < np.median(rec.accel[:, 2]) < -0.7 * G


@pytest.mark.slow
@pytest.mark.parametrize(
    "path", _autopilot_logs(["*/*.bbl", "*/*.BBL", "*/*.bfl", "*/*.BFL"]), ids=lambda p: p.name
)
def test_blackbox_logs_decode_cleanly_and_import(path):
    from quadfault.io.importers import detect_format, get_importer
    from quadfault.io.importers.blackbox_format import decode_log, split_logs

    assert detect_format(path) == "blackbox"
    data = path.read_bytes()
    for a, b in split_logs(data):
        log = decode_log(data, a, b)
        t = log.field("time")
        assert log.corrupt <= 0.001 * len(log.main) and np.all(np.diff(t) > 0)
    rec = get_importer("blackbox")(path)
    assert -1.3 * G < np.median(rec.accel[:, 2]) < -0.7 * G  # FRD: specific force points up
    assert np.median(rec.commands_u) > 0.1
    if rec.rotor_speed is not None:  # the rotors spin faster when commanded more
        level = rec.commands_u.mean(axis=1)
        w = np.nanmean(rec.rotor_speed, axis=1)
        high = level > np.median(level)
        assert np.nanmean(w[high]) > np.nanmean(w[~high])
    if rec.has_pose:  # the attitude agrees with the gyro (body rates from dq/dt, FRD)
        from quadfault.model.rotation import quat_multiply

        q = rec.quaternion
        dq = np.gradient(q, rec.t, axis=0)
        w_q = 2 * quat_multiply(q * np.array([1, -1, -1, -1]), dq)[:, 1:]
        k = np.ones(25) / 25  # gyro noise: compare 50 ms means, on the axes that move

        def smooth(x):
            return np.convolve(x, k, mode="same")

        moving = [i for i in range(3) if np.std(rec.omega[:, i]) > 0.1]
        assert moving
        for i in moving:
            a, b = smooth(w_q[:, i]), smooth(rec.omega[:, i])
            assert np.corrcoef(a, b)[0, 1] > 0.8
            assert 0.8 < np.sum(a * b) / np.sum(b * b) < 1.25  # units, not just sign
        # position and velocity in the same units: d(position)/dt against velocity
        dp = np.gradient(rec.position, rec.t, axis=0)
        for i in range(3):
            a, b = smooth(dp[:, i]), smooth(rec.velocity[:, i])
            if np.std(b) > 0.05:  # (gaps and held samples blur this one: a factor of 2)
                assert 0.5 < np.sum(a * b) / np.sum(b * b) < 2.0
