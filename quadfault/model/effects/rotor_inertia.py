"""``rotor_inertia``: the rotors' reaction when they change speed, a yaw moment
``M_z = kappa sum_i s_i df_i'/dt`` (``s_i`` the sign of rotor i's yaw torque), and,
optionally, their gyroscopic moment ``-w x h`` with the spinning rotors' angular momentum
``h = -sum_i s_i momentum sqrt(f_i) e_z`` (body frame)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadfault.errors import ConfigError
from quadfault.jit import jit
from quadfault.layout import ROTORS, fields
from quadfault.model.effects.base import Compiled, Identifiability, number, param, vector
from quadfault.model.effects.candidate import Candidate
from quadfault.model.effects.physics import batch_of, rows_of
from quadfault.model.rotation import store3


# kernels ---------------------------------------------------------------------------------
@jit
def thrust_rate1(f_end, f_prev, dt):
    """Mean rate of change [N/s] of a thrust that went from ``f_prev`` to ``f_end`` over
    ``dt`` [s]."""
    return (f_end - f_prev) / dt


@jit
def rotor_momentum1(f, signs, momentum):
    """The rotors' angular momentum along body ``+z`` [N m s]: rotor i spins against its
    reaction torque's sign ``s_i`` with ``J_r Omega_i = momentum sqrt(f_i)`` (``f = k_f
    Omega^2``, ``momentum = J_r / sqrt(k_f)`` [N m s / sqrt(N)]); a rotor producing no
    thrust does not spin."""
    h = 0.0
    for r in range(f.shape[0]):
        if f[r] > 0.0:
            h -= signs[r] * momentum * f[r] ** 0.5
    return h


@jit
def gyroscopic_moment3(w, h):
    """Body moment [N m] ``-w x (0, 0, h)`` of rotors with angular momentum ``h`` [N m s]
    along body ``+z`` on a body turning at ``w`` [rad/s]."""
    return -h * w[1], h * w[0], 0.0


@jit
def rotor_inertia_moment1(yaw_rate_sum, kappa):
    """Yaw moment [N m] ``kappa sum_i s_i df_i/dt`` from the signed sum of rotor thrust rates
    ``sum_i s_i df_i/dt`` [N/s]."""
    return kappa * yaw_rate_sum


#: the chain entry's parameters and memory: a step opened by the thrust stage (``fresh``),
#: whether a previous step was seen, the step length, the step's yaw-signed sum of thrust
#: rates, and each rotor's thrust of the last step
PARAMETERS = fields("RotorInertiaParameters", "kappa", "momentum", ("yaw_signs", ROTORS))
MEMORY = fields("RotorInertiaMemory", "fresh", "seen", "dt", "rate", ("thrust", ROTORS))


@jit(inline="always")
def thrust_step(x, q, f, t, dt, p, gen, streams, i):
    """Marks the step: the next wrench call opens it."""
    q[MEMORY.fresh], q[MEMORY.dt] = 1.0, dt
    return f


@jit
def _rotor_rate(x, q, f):
    """The yaw-signed sum of the rotors' thrust rates over the current step [N/s] (computed
    at the step's first wrench call, from the thrusts the chain produced)."""
    if q[MEMORY.fresh] != 0.0:
        s = 0.0
        for r in range(f.shape[0]):
            rate = 0.0
            if q[MEMORY.seen] != 0.0:
                rate = thrust_rate1(f[r], q[MEMORY.thrust + r], q[MEMORY.dt])
            s += rate * x[PARAMETERS.yaw_signs + r]
            q[MEMORY.thrust + r] = f[r]
        q[MEMORY.rate], q[MEMORY.fresh], q[MEMORY.seen] = s, 0.0, 1.0
    return q[MEMORY.rate]


@jit(inline="always")
def wrench_term(x, q, f):
    """The step's numbers: the yaw moment of the step's thrust rates and the rotors' angular
    momentum (:func:`rotor_momentum1`)."""
    Mz = rotor_inertia_moment1(_rotor_rate(x, q, f), x[PARAMETERS.kappa])
    h = rotor_momentum1(f, x[PARAMETERS.yaw_signs :], x[PARAMETERS.momentum])
    return 0.0, 0.0, Mz, h, 0.0, 0.0


@jit(inline="always")
def wrench_stage(s, v, R, w):
    """The step's yaw moment plus the gyroscopic moment at the stage's body rate."""
    g = gyroscopic_moment3(w, s[4])
    return (0.0, 0.0, 0.0), (s[1] + g[0], s[2] + g[1], s[3])


# over arrays -----------------------------------------------------------------------------
@jit
def _rate_rows(f_end, dt, out):
    for k in range(1, f_end.shape[0]):
        for m in range(f_end.shape[1]):
            out[k, m] = thrust_rate1(f_end[k, m], f_end[k - 1, m], dt[k])


def thrust_rate(f_end: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Mean rate of change [N/s] of a thrust held over each interval: the step from the
    previous interval's final thrust to this one's, ``(f_end_k - f_end_{k-1}) / dt_k`` (0 for
    the first), so block means of the rate telescope exactly."""
    f = np.ascontiguousarray(f_end, dtype=float)
    out = np.zeros_like(f)
    if len(f) > 1:
        d = np.ascontiguousarray(np.broadcast_to(np.asarray(dt, dtype=float), (len(f),)))
        _rate_rows(f.reshape(len(f), -1), d, out.reshape(len(f), -1))
    return out


@jit
def _moment_rows(rate, signs, kappa, out):
    for i in range(rate.shape[0]):
        s = 0.0
        for m in range(rate.shape[1]):
            s += rate[i, m] * signs[i, m]
        store3(out[i], (0.0, 0.0, rotor_inertia_moment1(s, kappa)))


def rotor_inertia_moment(rate: np.ndarray, yaw_signs: np.ndarray, kappa: float) -> np.ndarray:
    """Body moment [N m] of the rotors' reaction when they spin up or down:
    ``M_z = kappa sum_i s_i df_i/dt`` (``rate`` = df/dt [N/s], ``s_i`` = the sign of rotor
    i's drag torque on the body, ``kappa`` [m s] = J_r omega / (2 f) at the operating point,
    J_r the rotor inertia)."""
    rate = np.asarray(rate, dtype=float)
    n = (rate.shape[-1],)
    batch = batch_of((rate, n), (yaw_signs, n))
    rr, rs = rows_of(batch, (rate, n), (yaw_signs, n))
    out = np.zeros((int(np.prod(batch)), 3))
    _moment_rows(rr, rs, float(kappa), out)
    return out.reshape(batch + (3,))


def rotor_momentum(f: np.ndarray, yaw_signs, momentum: float) -> float:
    """The rotors' angular momentum along body ``+z`` [N m s] for produced thrusts ``f``
    [N] (:func:`rotor_momentum1`)."""
    f = np.ascontiguousarray(f, dtype=float)
    signs = np.ascontiguousarray(np.broadcast_to(np.asarray(yaw_signs, float), f.shape))
    return float(rotor_momentum1(f, signs, float(momentum)))


def gyroscopic_moment(w: np.ndarray, h: float) -> np.ndarray:
    """Body moment [N m] ``-w x (0, 0, h)`` (:func:`gyroscopic_moment3`)."""
    return np.array(gyroscopic_moment3(np.asarray(w, dtype=float), float(h)))


# the effect ------------------------------------------------------------------------------
@dataclass(frozen=True)
class RotorInertia(Compiled):
    """Yaw reaction of the rotors' inertia when their thrust changes:
    ``M_z = kappa sum_i s_i df_i/dt`` (``kappa`` [m s]; ``s_i`` the sign of rotor i's yaw
    torque: ``yaw_signs``, by default read from the flown vehicle's allocation at reset). The
    rate over a step is the step from the previous step's produced thrust
    (:func:`thrust_rate1`), so a jump in thrust gives the yaw-rate kick
    ``kappa sum_i s_i df_i / J_z``.

    With ``momentum`` > 0 [N m s / sqrt(N)] the spinning rotors also carry angular momentum
    ``h = -sum_i s_i momentum sqrt(f_i)`` along body z (:func:`rotor_momentum1`; a rotor
    ``J_r`` with ``f = k_f Omega^2`` has ``momentum = J_r / sqrt(k_f)``), which turns the body
    rate into the gyroscopic moment ``-w x h`` (:func:`gyroscopic_moment3`): nil while the
    rotors' momenta cancel (hover of a healthy quadrotor) and large once one rotor stops
    and the body spins. A consistent pair at hover thrust ``f_h`` has
    ``kappa = momentum / (2 sqrt(f_h))``."""

    kappa: float = 0.001
    yaw_signs: tuple | None = None
    momentum: float = 0.0
    name: ClassVar[str] = "rotor_inertia"
    order: ClassVar[int] = 10
    identifiability: ClassVar[Identifiability] = Identifiability(
        scales_with=("inertia", "torque_coefficient"),
        excitation="thrust changes (the yaw kick of rotors speeding up or down)",
        note="shows in the yaw rate when the rotors change speed",
    )
    explanation: ClassVar[str] = "the rotors' inertia: changing rotor speeds kick the body in yaw"
    values: ClassVar[tuple] = (1, 2)
    syntax: ClassVar[str] = "KAPPA [m s] | KAPPA,MOMENTUM [m s, N m s/sqrt(N)]"
    example: ClassVar[str] = "rotor_inertia=0.005"
    parameter: ClassVar[tuple] = ("kappa", "kappa_m_s")

    def __post_init__(self):
        number(self.kappa, "rotor_inertia kappa [m s]", 0.0, 10.0)
        number(self.momentum, "rotor_inertia momentum [N m s/sqrt(N)]", 0.0, 10.0)
        if self.yaw_signs is not None:
            signs = np.sign(
                vector(self.yaw_signs, len(np.ravel(self.yaw_signs)), "rotor_inertia yaw_signs")
            )
            object.__setattr__(self, "yaw_signs", tuple(float(s) for s in signs))

    def params(self):
        out = {"kappa_m_s": self.kappa}
        if self.momentum:
            out["momentum_N_m_s_per_sqrt_N"] = self.momentum
        return out

    @classmethod
    def from_params(cls, params):
        return cls(
            kappa=param(params, "kappa_m_s", cls.name),
            momentum=params.get("momentum_N_m_s_per_sqrt_N", 0.0),
        )

    @classmethod
    def from_values(cls, values, options):
        return cls(*values[:1], momentum=values[1] if len(values) > 1 else 0.0, **options)

    def true_vehicle(self, vehicle):
        self.__dict__["_signs"] = np.sign(vehicle.allocation[3])  # the flown rotors' spins
        self.__dict__.pop("_single", None)
        return vehicle

    def signs(self, n_rotors: int) -> np.ndarray:
        """Yaw-torque sign of each rotor: ``yaw_signs``, else the flown vehicle's (seen by
        ``true_vehicle``), else alternating -1, +1."""
        if self.yaw_signs is not None:
            return np.asarray(self.yaw_signs)
        s = self.__dict__.get("_signs")
        return s if s is not None and len(s) == n_rotors else np.resize([-1.0, 1.0], n_rotors)

    def _yaw_signs(self, n_rotors):
        return self.signs(n_rotors)

    def parameters(self, n_rotors, dt, yaw_signs=None):
        signs = self.yaw_signs if self.yaw_signs is not None else yaw_signs
        if signs is None:
            signs = np.resize([-1.0, 1.0], n_rotors)
        if len(signs) != n_rotors:
            raise ConfigError(
                f"rotor_inertia has {len(signs)} yaw signs, the vehicle {n_rotors} rotors"
            )
        return {
            "kappa": self.kappa,
            "momentum": self.momentum,
            "yaw_signs": [float(s) for s in signs],
        }

    @classmethod
    def candidate(cls, ctx):
        return RotorInertiaCandidate(
            cls.name,
            ("kappa [m s]",),
            (0.0,),
            (1.5 * ctx.c_yaw,),
            (0.0,),
            ((0.0,),),
            "wrench",
            affine=True,
        )


@dataclass(frozen=True)
class RotorInertiaCandidate(Candidate):
    uses_thrust: ClassVar[bool] = True
    needs_rate: ClassVar[bool] = True
    keys: ClassVar[tuple] = (("kappa_m_s", 0, 1),)

    def wrench(self, x, inp):
        signs = np.sign(inp.vehicle.allocation[3])
        return None, rotor_inertia_moment(inp.rate, signs, float(x[0]))
