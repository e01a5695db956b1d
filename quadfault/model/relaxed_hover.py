"""Relaxed hover: how a quadrotor that lost one rotor still holds its position.

Without one rotor a quadrotor cannot hold its heading: the three remaining rotors' drag
torques do not cancel, and the body spins. It can still hover in the relaxed sense of
Mueller & D'Andrea (ICRA 2014, "Stability and control of a quadrocopter despite the complete
loss of one, two, or three propellers"): the body rate ``w`` and the rotor thrusts are
constant in the body frame, ``w`` is parallel to gravity (the body turns about the vertical
through its centre of mass), the component of the thrust along that axis carries the weight,
and the thrust's small horizontal part turns with the body, so the centre of mass runs on
a circle of radius ``T sin(tilt) / (m |w|^2)`` (millimetres) about the hover point.

This module computes that solution from the model the simulator flies (one
implementation): the allocation (:meth:`~quadfault.model.vehicle.Vehicle.wrench`, the
rotors' drag torque in its yaw row), the body's rate damping
(:func:`~quadfault.model.effects.rate_damping.rate_damping_moment`), the rotors'
gyroscopic moment (:func:`~quadfault.model.effects.rotor_inertia.gyroscopic_moment` with
:func:`~quadfault.model.effects.rotor_inertia.rotor_momentum`) and the rotor thrust limit.
:func:`relaxed_hover` solves Euler's equation at constant body rate together with the
vertical force balance; :func:`closed_form_hover` evaluates the closed-form conditions of
the same solution (written here from first principles, after the construction of Mueller &
D'Andrea: yaw rate from the yaw-torque balance, the spin axis' tilt from the roll/pitch
balance of the opposite rotor's moment against the spinning body's and rotors' angular
momentum, thrust from the vertical balance) under the paper's simplifications (roll and
pitch undamped, a linear yaw damping, ``J_x = J_y``, a symmetric X layout). The two agree
exactly when those hold.

The solutions form a one-parameter family: with the lost rotor's two neighbours at equal
thrust ``f``, the opposite rotor gives ``rho f``. ``rho = 0`` flies the two neighbours
alone (a spin about body z, no tilt); a larger ``rho`` lowers the neighbours' thrust but
tilts the spin axis. :func:`linearised` gives the reduced-attitude dynamics about a
solution, constant in the body frame (what the relaxed-hover controller,
:mod:`quadfault.model.relaxed_hover_control`, is designed on).

Frames: world NED, body FRD; the "up" axis ``n`` is the world's ``-z`` in body coordinates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadfault.errors import ConfigError
from quadfault.model.effects.rate_damping import RateDamping, rate_damping_moment
from quadfault.model.effects.rotor_inertia import RotorInertia, gyroscopic_moment, rotor_momentum
from quadfault.model.effects.spec import parse_effect
from quadfault.model.vehicle import Vehicle

#: the complete-loss vehicle's thrust-to-weight ratio (the paper's F450 otherwise)
ROTOR_LOSS_THRUST_TO_WEIGHT = 2.75
#: its body rate damping, ``rate_damping`` D1 per axis [N m s/rad]
ROTOR_LOSS_RATE_DAMPING = (1e-3, 1e-3, 5e-3)
#: its rotors' inertia: ``rotor_inertia`` kappa [m s] and momentum J_r / sqrt(k_f)
#: [N m s / sqrt(N)] (a 10-inch propeller and motor bell, J_r about 3e-5 kg m^2, hovering near
#: 650 rad/s: kappa = momentum / (2 sqrt(f_hover)))
ROTOR_LOSS_MOMENTUM = 0.0125
ROTOR_LOSS_KAPPA = 0.004
#: the ``effects`` specs of the complete-loss vehicle (``quadfault simulate --effect``)
ROTOR_LOSS_EFFECTS = (
    "rate_damping={},{},{}".format(*ROTOR_LOSS_RATE_DAMPING),
    f"rotor_inertia={ROTOR_LOSS_KAPPA},{ROTOR_LOSS_MOMENTUM}",
)
#: the opposite rotor's thrust over the neighbours' of the solution the controller flies
DEFAULT_RHO = 0.3


def rotor_loss_vehicle() -> Vehicle:
    """The complete-loss vehicle: the paper's F450 (1 kg, arm 0.225 m) with thrust-to-weight
    2.75 (6.74 N per rotor); fly it with :data:`ROTOR_LOSS_EFFECTS` (body rate damping and
    the rotors' inertia and gyroscopic moment), the physics a relaxed hover rests on."""
    return Vehicle(thrust_to_weight=ROTOR_LOSS_THRUST_TO_WEIGHT, name="F450 rotor-loss")


def rotor_loss_effects() -> tuple:
    """:data:`ROTOR_LOSS_EFFECTS` as effect objects."""
    return (
        RateDamping(linear=ROTOR_LOSS_RATE_DAMPING),
        RotorInertia(kappa=ROTOR_LOSS_KAPPA, momentum=ROTOR_LOSS_MOMENTUM),
    )


@dataclass(frozen=True)
class SpinPhysics:
    """What a relaxed hover depends on besides the vehicle: the body's rate damping
    ``M = -(D1 + D2 |w|) w`` (``linear`` D1, ``quadratic`` D2 per axis) and the rotors'
    angular momentum per square root of thrust ``momentum`` [N m s / sqrt(N)]."""

    linear: tuple = ROTOR_LOSS_RATE_DAMPING
    quadratic: tuple = (0.0, 0.0, 0.0)
    momentum: float = ROTOR_LOSS_MOMENTUM

    @classmethod
    def of(cls, effects) -> SpinPhysics:
        """The physics of ``effects`` (effect objects or specs): their ``rate_damping`` and
        ``rotor_inertia`` (zero when absent)."""
        linear, quadratic, momentum = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0
        for e in effects or ():
            e = parse_effect(e) if isinstance(e, str) else e
            if isinstance(e, RateDamping):
                linear, quadratic = e.linear, e.quadratic
            elif isinstance(e, RotorInertia):
                momentum = e.momentum
        return cls(tuple(linear), tuple(quadratic), float(momentum))

    def body_moment(self, vehicle: Vehicle, f: np.ndarray, w: np.ndarray) -> np.ndarray:
        """The body moment [N m] on a body turning at ``w`` [rad/s] with rotor thrusts ``f``
        [N] held: the rotors' moments and drag torques, the rate damping and the rotors'
        gyroscopic moment (the terms of the simulator's model)."""
        signs = np.sign(vehicle.allocation[3])
        h = rotor_momentum(np.maximum(f, 0.0), signs, self.momentum)
        return (
            vehicle.wrench(f)[1:]
            + rate_damping_moment(w, self.linear, self.quadratic)
            + gyroscopic_moment(w, h)
        )

    def angular_acceleration(self, vehicle: Vehicle, f, w) -> np.ndarray:
        """``dw/dt`` [rad/s^2] = J^-1 (M - w x J w) at constant rotor thrusts."""
        J = vehicle.inertia
        return vehicle.inertia_inverse @ (self.body_moment(vehicle, f, w) - np.cross(w, J @ w))


@dataclass(frozen=True)
class RelaxedHover:
    """A relaxed-hover solution (constant in the body frame).

    Attributes:
        lost: index of the lost rotor (0-based).
        rho: the opposite rotor's thrust over the neighbours' [-].
        f: rotor thrusts [N] (the lost rotor's 0).
        w: body rate [rad/s] (body FRD).
        n: the up axis in body coordinates (``w`` / ``|w|`` turned to point up).
        f_max: the rotor thrust limit [N].
        residual: norm of the equations' residual at the solution.
    """

    lost: int
    rho: float
    f: np.ndarray
    w: np.ndarray
    n: np.ndarray
    f_max: float
    residual: float

    @property
    def spin_rate(self) -> float:
        """|w| [rad/s]."""
        return float(np.linalg.norm(self.w))

    @property
    def yaw_rate(self) -> float:
        """Body z rate [rad/s]."""
        return float(self.w[2])

    @property
    def tilt(self) -> float:
        """Angle between the thrust axis (body -z) and the vertical [rad]."""
        return float(math.acos(min(1.0, -self.n[2])))

    @property
    def load(self) -> float:
        """The busiest rotor's thrust over the limit [-] (feasible when <= 1)."""
        return float(np.max(self.f) / self.f_max)

    @property
    def feasible(self) -> bool:
        return self.load <= 1.0 and float(np.min(self.f)) >= 0.0

    def circle_radius(self, vehicle: Vehicle) -> float:
        """Radius [m] of the circle the centre of mass runs on."""
        T = float(np.sum(self.f))
        return T * math.sin(self.tilt) / (vehicle.mass * self.spin_rate**2)


def rotor_roles(vehicle: Vehicle, lost: int) -> tuple[int, int, int]:
    """``(neighbour, neighbour, opposite)`` rotor indices of ``lost`` on a quadrotor: the
    opposite rotor is the farthest one (it spins the same way)."""
    if vehicle.n_rotors != 4:
        raise ConfigError(f"relaxed hover needs a quadrotor, the vehicle has {vehicle.n_rotors}")
    if not (isinstance(lost, (int, np.integer)) and 0 <= lost < 4):
        raise ConfigError(f"lost rotor must be 0..3, got {lost!r}")
    xy = np.stack((vehicle.allocation[2], -vehicle.allocation[1]), axis=1)  # (x, y) per rotor
    others = [i for i in range(4) if i != lost]
    opp = max(others, key=lambda i: float(np.linalg.norm(xy[i] - xy[lost])))
    a, b = (i for i in others if i != opp)
    return a, b, opp


def _thrusts(vehicle, lost, f_nb, rho) -> np.ndarray:
    a, b, o = rotor_roles(vehicle, lost)
    f = np.zeros(4)
    f[a] = f[b] = f_nb
    f[o] = rho * f_nb
    return f


def up_axis(w: np.ndarray) -> np.ndarray:
    """``w / |w|`` turned so that it points up (negative body z component)."""
    n = np.asarray(w, float) / np.linalg.norm(w)
    return n if n[2] < 0 else -n


def closed_form_hover(
    vehicle: Vehicle, physics: SpinPhysics, lost: int = 0, rho: float = DEFAULT_RHO
) -> RelaxedHover:
    """The closed-form conditions of the relaxed hover under the paper's simplifications
    (undamped roll and pitch, linear yaw damping ``gamma`` = D1z, ``J_x = J_y``; see the
    module docstring), solved for the neighbours' thrust ``f``:

    * yaw: ``gamma r = c sum_i s_i f_i = c s_nb (2 - rho) f``;
    * roll/pitch: the opposite rotor's moment ``rho f (-y_o, x_o)`` equals
      ``k (q, -p)`` with ``k = (J_z - J_x) r + h``, ``h`` the rotors' angular momentum;
    * vertical: ``(2 + rho) f |r| / |w| = m g``.
    """
    J = vehicle.inertia
    c = float(np.max(np.abs(vehicle.allocation[3])))
    a, b, o = rotor_roles(vehicle, lost)
    s_nb = float(np.sign(vehicle.allocation[3, a]))
    x_o, y_o = float(vehicle.allocation[2, o]), float(-vehicle.allocation[1, o])
    gamma = float(physics.linear[2])
    if gamma <= 0:
        raise ConfigError("a relaxed hover needs yaw damping (rate_damping D1z > 0)")
    signs = np.sign(vehicle.allocation[3])

    def rates(f):
        r = c * s_nb * (2.0 - rho) * f / gamma
        h = rotor_momentum(_thrusts(vehicle, lost, f, rho), signs, physics.momentum)
        k = (J[2, 2] - J[0, 0]) * r + h
        Mx, My = -y_o * rho * f, x_o * rho * f
        return np.array([-My / k, Mx / k, r])

    def vertical(f):
        w = rates(f)
        return (2.0 + rho) * f * abs(w[2]) / np.linalg.norm(w) - vehicle.weight

    lo, hi = vehicle.weight / (2.0 + rho), 4.0 * vehicle.weight
    if vertical(lo) > 0 or vertical(hi) < 0:
        raise ConfigError(f"no relaxed hover with rho = {rho:g} for this vehicle")
    for _ in range(200):  # bisection: vertical() rises with f on this bracket
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if vertical(mid) < 0 else (lo, mid)
    f_nb = 0.5 * (lo + hi)
    w = rates(f_nb)
    return RelaxedHover(
        lost,
        float(rho),
        _thrusts(vehicle, lost, f_nb, rho),
        w,
        up_axis(w),
        vehicle.rotor_max_thrust,
        abs(vertical(f_nb)),
    )


def hover_residual(vehicle: Vehicle, physics: SpinPhysics, f: np.ndarray, w: np.ndarray):
    """The equations of a relaxed hover at thrusts ``f`` and body rate ``w``: ``dw/dt``
    (3) [rad/s^2] and the vertical force balance [m/s^2] (the thrust along the up axis
    ``w/|w|`` over the mass, minus g)."""
    n = up_axis(w)
    vertical = float(np.sum(f)) * (-n[2]) / vehicle.mass - vehicle.gravity
    return np.append(physics.angular_acceleration(vehicle, f, w), vertical)


def relaxed_hover(
    vehicle: Vehicle, physics: SpinPhysics, lost: int = 0, rho: float = DEFAULT_RHO
) -> RelaxedHover:
    """The relaxed hover of ``vehicle`` with rotor ``lost`` (0-based) gone, the neighbours
    at equal thrust and the opposite rotor at ``rho`` times theirs: Newton's method on
    :func:`hover_residual` (unknowns: the neighbours' thrust and the body rate), started
    from :func:`closed_form_hover`. Raises :class:`~quadfault.errors.ConfigError` when there
    is none (e.g. no yaw damping: nothing stops the spin)."""
    if not (math.isfinite(rho) and 0.0 <= rho < 2.0):
        raise ConfigError(f"rho must be in [0, 2), got {rho!r}")
    guess = closed_form_hover(vehicle, physics, lost, rho)
    x = np.append(guess.f[rotor_roles(vehicle, lost)[0]], guess.w)

    def F(x):
        return hover_residual(vehicle, physics, _thrusts(vehicle, lost, x[0], rho), x[1:])

    for _ in range(50):
        r = F(x)
        if np.linalg.norm(r) < 1e-12:
            break
        Jac = np.empty((4, 4))
        for j in range(4):
            dx = np.zeros(4)
            dx[j] = 1e-7 * max(1.0, abs(x[j]))
            Jac[:, j] = (F(x + dx) - F(x - dx)) / (2 * dx[j])
        x = x - np.linalg.solve(Jac, r)
    res = float(np.linalg.norm(F(x)))
    if not (np.all(np.isfinite(x)) and res < 1e-8):
        raise ConfigError(f"no relaxed hover found (residual {res:.2g})")
    f = _thrusts(vehicle, lost, x[0], rho)
    return RelaxedHover(
        lost, float(rho), f, x[1:].copy(), up_axis(x[1:]), vehicle.rotor_max_thrust, res
    )


def linearised(vehicle: Vehicle, physics: SpinPhysics, hover: RelaxedHover):
    """``(A, B)`` of the reduced attitude about ``hover``, constant in the body frame.

    State ``x = (n_x - nbar_x, n_y - nbar_y, w - wbar)`` (5): the desired up axis in body
    coordinates (it turns as ``dn/dt = -w x n`` for a fixed direction in the world; its z
    component follows from the unit norm) and the body rate; input ``u = f - fbar`` (4, the
    lost rotor's column zero). Central differences of :func:`SpinPhysics.angular_acceleration`.
    """
    nbar, wbar, fbar = hover.n, hover.w, hover.f

    def xdot(x, u):
        nx, ny = nbar[0] + x[0], nbar[1] + x[1]
        n = np.array([nx, ny, -math.sqrt(max(0.0, 1.0 - nx * nx - ny * ny))])
        w = wbar + x[2:]
        dn = -np.cross(w, n)
        return np.concatenate((dn[:2], physics.angular_acceleration(vehicle, fbar + u, w)))

    A, B = np.empty((5, 5)), np.zeros((5, 4))
    for j in range(5):
        dx = np.zeros(5)
        dx[j] = 1e-6
        A[:, j] = (xdot(dx, np.zeros(4)) - xdot(-dx, np.zeros(4))) / 2e-6
    for j in range(4):
        if j == hover.lost:
            continue
        du = np.zeros(4)
        du[j] = 1e-6
        B[:, j] = (xdot(np.zeros(5), du) - xdot(np.zeros(5), -du)) / 2e-6
    return A, B


def attitude_of(n: np.ndarray) -> np.ndarray:
    """The body-to-world rotation (NED/FRD) that turns the body axis ``n`` onto the world's
    up (-z) by the smallest rotation."""
    n = np.asarray(n, float) / np.linalg.norm(n)
    up = np.array([0.0, 0.0, -1.0])
    axis = np.cross(n, up)
    s, c = float(np.linalg.norm(axis)), float(n @ up)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = axis / s
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * K + (1 - c) * K @ K


def hover_state(vehicle: Vehicle, hover: RelaxedHover, centre=(0.0, 0.0, -1.0)):
    """``(p, v, R, w)`` on the solution's circle about ``centre`` [m] (NED): attitude
    :func:`attitude_of` the up axis, body rate ``hover.w``, and the position and velocity of
    the circle the turning horizontal thrust drives (``x = -a_h / |w|^2`` from the centre,
    ``v = W x x`` with ``W`` the world rate), so that the centre of mass stays on it."""
    R = attitude_of(hover.n)
    a = R @ np.array([0.0, 0.0, -float(np.sum(hover.f))]) / vehicle.mass
    a_h = np.array([a[0], a[1], 0.0])
    W = R @ hover.w
    x = -a_h / float(W @ W)
    return np.asarray(centre, float) + x, np.cross(W, x), R, hover.w.copy()
