"""Readable numpy forms of the core model, for the tests only: each compiled kernel of the
package is checked against the textbook statement here (batched numpy, written for clarity,
not speed). Nothing in the package imports this module."""

from __future__ import annotations

import numpy as np

E3 = np.array([0.0, 0.0, 1.0])


def hat(w):
    w = np.asarray(w, dtype=float)
    out = np.zeros(w.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -w[..., 2], w[..., 1]
    out[..., 1, 0], out[..., 1, 2] = w[..., 2], -w[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -w[..., 1], w[..., 0]
    return out


def vee(m):
    m = np.asarray(m, dtype=float)
    return 0.5 * np.stack(
        (m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]),
        axis=-1,
    )


def expm_so3(phi):
    """Rodrigues: ``I + sin(th)/th [phi]x + (1 - cos th)/th^2 [phi]x^2``."""
    phi = np.asarray(phi, dtype=float)
    th = np.linalg.norm(phi, axis=-1)[..., None, None]
    K = hat(phi)
    safe = np.where(th > 1e-12, th, 1.0)
    a = np.where(th > 1e-12, np.sin(safe) / safe, 1.0)
    b = np.where(th > 1e-12, (1 - np.cos(safe)) / safe**2, 0.5)
    return np.eye(3) + a * K + b * (K @ K)


def translational_acceleration(R, thrust, vehicle, F=None):
    """Eq. 2: ``g e3 - T/m R e3 + F/m``."""
    acc = vehicle.gravity * E3 - (np.asarray(thrust)[..., None] / vehicle.mass) * R[..., :, 2]
    return acc if F is None else acc + np.asarray(F) / vehicle.mass


def angular_acceleration(w, M, vehicle, M_ext=None):
    """Eq. 4: ``J^-1 (M - w x J w + M_ext)``."""
    m = M - np.cross(w, w @ vehicle.inertia.T)
    if M_ext is not None:
        m = m + M_ext
    return m @ np.linalg.inv(vehicle.inertia).T


def step_rk4(p, v, R, w, thrust, moment, vehicle, dt, external=None):
    """RKMK4 written out with the numpy helpers above."""

    def deriv(pp, vv, RR, ww):
        F = M = None
        if external is not None:
            F, M = external(pp, vv, RR, ww)
        return (
            vv,
            translational_acceleration(RR, thrust, vehicle, F),
            angular_acceleration(ww, moment, vehicle, M),
        )

    def dexpinv(th, ww):
        tw = np.cross(th, ww)
        return ww + 0.5 * tw + np.cross(th, tw) / 12.0

    h = dt / 2
    k1 = deriv(p, v, R, w)
    th1 = w
    s2 = (p + h * k1[0], v + h * k1[1], R @ expm_so3(h * th1), w + h * k1[2])
    k2 = deriv(*s2)
    th2 = dexpinv(h * th1, s2[3])
    s3 = (p + h * k2[0], v + h * k2[1], R @ expm_so3(h * th2), w + h * k2[2])
    k3 = deriv(*s3)
    th3 = dexpinv(h * th2, s3[3])
    s4 = (p + dt * k3[0], v + dt * k3[1], R @ expm_so3(dt * th3), w + dt * k3[2])
    k4 = deriv(*s4)
    th4 = dexpinv(dt * th3, s4[3])
    c = dt / 6
    return (
        p + c * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0]),
        v + c * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1]),
        R @ expm_so3(c * (th1 + 2 * th2 + 2 * th3 + th4)),
        w + c * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2]),
    )


def dcm_renormalize(R):
    x, y = R[0], R[1]
    err = x @ y
    xo, yo = x - 0.5 * err * y, y - 0.5 * err * x
    zo = np.cross(xo, yo)
    return np.stack([0.5 * (3 - r @ r) * r for r in (xo, yo, zo)])


class ReferenceEuler:
    """The authors' MATLAB step (``dynamics.m``): derivatives stored after each step."""

    def __init__(self, vehicle, dt):
        self.vehicle, self.dt = vehicle, dt
        self.a, self.w_dot = np.zeros(3), np.zeros(3)
        self.force_world, self.moment = np.zeros(3), np.zeros(3)

    def step(self, p, v, R, w):
        dt, veh = self.dt, self.vehicle
        w = w + self.w_dot * dt
        v = v + self.a * dt
        R = dcm_renormalize(R @ (np.eye(3) + hat(w * dt)))
        p = p + v * dt
        self.a = veh.gravity * E3 - self.force_world / veh.mass
        self.w_dot = np.linalg.inv(veh.inertia) @ (self.moment - np.cross(w, veh.inertia @ w))
        return p, v, R, w

    def apply(self, thrust, moment, R):
        self.force_world = thrust * R[:, 2]
        self.moment = np.asarray(moment, dtype=float).copy()


def motor_thrust(f_cmd, eta, f_max, saturate, sigma, z):
    """Eqs. 11, 13: ``eta clip(f) exp(sigma z)``."""
    f = np.clip(f_cmd, 0.0, f_max) if saturate else np.maximum(f_cmd, 0.0)
    return f * eta * np.exp(sigma * np.asarray(z))


def desired_attitude(f_n, b1d, normalize_b2d=True):
    b3d = f_n / np.linalg.norm(f_n, axis=-1, keepdims=True)
    b2d = np.cross(b3d, b1d)
    if normalize_b2d:
        b2d = b2d / np.linalg.norm(b2d, axis=-1, keepdims=True)
    return np.stack((np.cross(b2d, b3d), b2d, b3d), axis=-1)


def geometric_control(p, v, R, w, ref, w_d, w_dot_d, vehicle, config):
    """Eqs. 9, 10 (Lee, Leok, McClamroch) in NED/FRD: thrust [N], moment [N m], R_d."""
    g = config.gains
    m, J = vehicle.mass, vehicle.inertia
    f_n = (
        np.asarray(g.kx) * (p - ref.position)
        + np.asarray(g.kv) * (v - ref.velocity)
        + m * vehicle.gravity * E3
    )
    if config.acceleration_feedforward:
        f_n = f_n - m * ref.acceleration
    Rd = desired_attitude(f_n, ref.b1d, config.normalize_b2d)
    thrust = f_n @ R[:, 2]
    eR = 0.5 * vee(Rd.T @ R - R.T @ Rd)
    if config.angular_feedforward:
        wdb = R.T @ Rd @ w_d
        eW = w - wdb
        ff = np.cross(w, J @ w) - J @ (np.cross(w, wdb) - R.T @ Rd @ w_dot_d)
    else:
        eW, ff = w, np.cross(w, J @ w)
    M = -np.asarray(g.kR) * eR - np.asarray(g.kW) * eW + ff
    return thrust, M, Rd


def feedforward_rates(trajectory, t, vehicle, config):
    """Omega_d, Omega_d' by central differences of the feed-forward attitude."""
    h = config.ff_step
    m, g = vehicle.mass, vehicle.gravity

    def Rd(tt):
        ref = trajectory(tt)
        acc = ref.acceleration if config.acceleration_feedforward else 0.0 * ref.acceleration
        return desired_attitude(m * g * E3 - m * acc, ref.b1d, config.normalize_b2d)

    Rm, R0, Rp = Rd(t - h), Rd(t), Rd(t + h)
    return vee(R0.T @ (Rp - Rm)) / (2 * h), vee(R0.T @ (Rp - 2 * R0 + Rm)) / (h * h)


def measure(p, v, R, w, noise, rng):
    """The sensors: p, v, [attitude], w, each ``x + std z`` (all drawn when any std > 0)."""
    if not noise.any:
        return p, v, R, w
    p = p + noise.position * rng.standard_normal(3)
    v = v + noise.velocity * rng.standard_normal(3)
    if noise.attitude:
        R = R @ expm_so3(noise.attitude * rng.standard_normal(3))
    return p, v, R, w + noise.gyro * rng.standard_normal(3)


def mix(allocation_inverse, T, M, yaw_release, f_max=np.inf):
    """Rotor commands from ``(T, M)`` by the allocation inverse; with ``yaw_release`` the yaw
    moment scaled down (to none at most) so that it pushes no command below zero or above
    ``f_max``."""
    base = allocation_inverse[:, :3] @ np.array([T, M[0], M[1]])
    yaw = allocation_inverse[:, 3] * M[2]
    s = 1.0
    if yaw_release:
        low = (yaw < 0) & (base + yaw < 0)
        high = (yaw > 0) & (base + yaw > f_max)
        bounds = np.concatenate((-base[low] / yaw[low], (f_max - base[high]) / yaw[high]))
        if bounds.size:
            s = float(np.clip(bounds, 0.0, 1.0).min())
    return base + s * yaw


def closed_loop_flight(scenario, config, seed, vehicle, nominal, thrust_noise, initial):
    """The closed loop of ``quadfault.simulate`` written out step by step with the readable
    forms above: returns the recorded (measured p, v, R, w, f_cmd, accelerometer) rows."""
    rng = np.random.default_rng(seed)
    reference = config.integrator == "reference"
    n = int(round(scenario.duration / config.dt))
    dt = config.dt
    t0 = dt if reference else 0.0
    f_max = vehicle.rotor_max_thrust if config.saturate else np.inf
    p, v, R, w = (np.array(x, dtype=float) for x in initial)
    euler = ReferenceEuler(vehicle, dt) if reference else None
    f_cmd = np.zeros(vehicle.n_rotors)
    rows = {k: [] for k in ("p", "v", "R", "w", "f", "acc")}
    for k in range(n):
        t = t0 + dt * k
        if reference:
            p, v, R, w = euler.step(p, v, R, w)
        mp, mv, mR, mw = measure(p, v, R, w, config.sensor_noise, rng)
        if k % config.control_decimation == 0:
            ref = scenario.trajectory(t)
            wd = wdd = np.zeros(3)
            if config.controller.angular_feedforward:
                wd, wdd = feedforward_rates(scenario.trajectory, t, nominal, config.controller)
            T, M, _ = geometric_control(mp, mv, mR, mw, ref, wd, wdd, nominal, config.controller)
            f_cmd = mix(nominal.allocation_inverse, T, M, config.controller.yaw_release, f_max)
        eta = np.asarray(scenario.efficiency(t), dtype=float)
        z = rng.standard_normal(vehicle.n_rotors) if thrust_noise > 0 else 0.0
        f = motor_thrust(f_cmd, eta, f_max, config.saturate, thrust_noise, z)
        T, *M = vehicle.allocation @ f
        acc = translational_acceleration(R, T, vehicle)
        sf = R.T @ (acc - vehicle.gravity * E3)
        if reference:
            euler.apply(T, np.array(M), R)
        else:
            p, v, R, w = step_rk4(p, v, R, w, T, np.array(M), vehicle, dt)
        if config.record_accel and config.sensor_noise.accel:
            sf = sf + config.sensor_noise.accel * rng.standard_normal(3)
        for key, x in zip(rows, (mp, mv, mR, mw, f_cmd, sf)):
            rows[key].append(np.array(x, dtype=float))
    return {k: np.array(x) for k, x in rows.items()}
