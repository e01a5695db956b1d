"""Thrust-stage effects: the thrust each rotor produces for its command.

Canonical chain (``order``): command-to-thrust curve, battery voltage, efficiency or common
scale, ground effect, delay, lag. Each is a frozen dataclass of parameters; its physics is
its entry in the compiled effect chain (:mod:`quadfault.effects.chain`, the kernels of
:mod:`quadfault.effects.kernels`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar


from quadfault.effects.base import Compiled, Identifiability, number, param, vector
from quadfault.errors import ConfigError

IDENTITY_CURVE = (0.0, 1.0, 0.0)


def _curve(value, what) -> tuple:
    c = vector(value, 3, what)
    if c[1] <= 0 and c[2] <= 0:
        raise ConfigError(f"{what} (a, b, c) needs b > 0 or c > 0 (thrust growing with the "
                          f"command), got {c}")
    return c


@dataclass(frozen=True)
class ThrustCurve(Compiled):
    """The rotors follow another command-to-thrust curve than the nominal one.

    The command is ``u = nominal^-1(f)`` (for the default identity nominal curve, the commanded
    thrust ``f`` [N] itself; for a ``u``-command recording, the sidecar's curve) and the
    produced thrust ``f' = a + b u + c u^2`` [N] with ``curve = (a, b, c)``.
    """

    curve: tuple = IDENTITY_CURVE
    nominal: tuple = IDENTITY_CURVE
    name: ClassVar[str] = "thrust_curve"
    identifiability: ClassVar[Identifiability] = Identifiability(
        direct=("rotor_speed",),
        excitation="commands spanning a range of thrust (climbs, descents, manoeuvres)",
        note="near hover a curve is a thrust scale; its slope and curvature need thrust changes")
    order: ClassVar[int] = 0

    def __post_init__(self):
        object.__setattr__(self, "curve", _curve(self.curve, "thrust_curve curve"))
        object.__setattr__(self, "nominal", _curve(self.nominal, "thrust_curve nominal"))

    def params(self):
        return {"curve": list(self.curve), "nominal_curve": list(self.nominal)}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "curve", cls.name),
                   params.get("nominal_curve", IDENTITY_CURVE))


@dataclass(frozen=True)
class BatteryThrust(Compiled):
    """Thrust that follows the battery voltage: ``f' = f (V / v_ref)^exponent``.

    The voltage falls linearly from ``v_start`` to ``v_end`` [V] over ``duration`` [s] (then
    stays); ``v_ref`` [V] is the voltage at which the nominal curve holds (default: the
    middle of the discharge); over a physics step the thrust follows the voltage at the
    step's middle. ``quadfault simulate`` records the same voltage as ``vbat``.
    """

    exponent: float = 2.0
    v_start: float = 12.0
    v_end: float = 11.0
    duration: float = 80.0
    v_ref: float | None = None
    name: ClassVar[str] = "battery_thrust"
    identifiability: ClassVar[Identifiability] = Identifiability(
        channels=("battery",), direct=("rotor_speed",),
        excitation="a battery voltage that changes over the log",
        note="the thrust follows the logged voltage; without vbat there is nothing to follow")
    order: ClassVar[int] = 1

    def __post_init__(self):
        number(self.exponent, "battery_thrust exponent", -5.0, 10.0)
        number(self.v_start, "battery_thrust v_start [V]", 0.0, 1e3, open_lo=True)
        number(self.v_end, "battery_thrust v_end [V]", 0.0, 1e3, open_lo=True)
        number(self.duration, "battery_thrust duration [s]", 0.0, 1e9, open_lo=True)
        if self.v_ref is None:
            object.__setattr__(self, "v_ref", 0.5 * (self.v_start + self.v_end))
        number(self.v_ref, "battery_thrust v_ref [V]", 0.0, 1e3, open_lo=True)

    def params(self):
        return {"exponent": self.exponent, "v_ref_V": self.v_ref, "v_start_V": self.v_start,
                "v_end_V": self.v_end, "duration_s": self.duration}

    @classmethod
    def from_params(cls, params):
        kw = {k: params[p] for k, p in (("v_start", "v_start_V"), ("v_end", "v_end_V"),
                                         ("duration", "duration_s"), ("v_ref", "v_ref_V"))
              if p in params}
        return cls(param(params, "exponent", cls.name), **kw)


@dataclass(frozen=True)
class MotorEfficiency(Compiled):
    """Per-rotor thrust factor ``eta`` [-] (1 = nominal; paper eq. 13)."""

    eta: tuple = (1.0, 1.0, 1.0, 1.0)
    name: ClassVar[str] = "motor_efficiency"
    identifiability: ClassVar[Identifiability] = Identifiability(
        note="a per-rotor loss shows as the unequal rotor split that keeps the moments "
             "balanced; a loss common to all rotors is a thrust_scale")
    order: ClassVar[int] = 2

    def __post_init__(self):
        eta = vector(self.eta, 4, "motor_efficiency eta")
        if not all(0.0 <= e <= 2.0 for e in eta):
            raise ConfigError(f"motor_efficiency eta must be in [0, 2], got {eta}")
        object.__setattr__(self, "eta", eta)

    def params(self):
        return {"eta": list(self.eta)}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "eta", cls.name))


@dataclass(frozen=True)
class ThrustScale(Compiled):
    """Common thrust factor ``scale`` [-] of all rotors."""

    scale: float = 1.0
    name: ClassVar[str] = "thrust_scale"
    identifiability: ClassVar[Identifiability] = Identifiability(note="shows in the vertical acceleration for the commanded thrust")
    order: ClassVar[int] = 2

    def __post_init__(self):
        number(self.scale, "thrust_scale", 0.0, 3.0, open_lo=True)

    def params(self):
        return {"scale": self.scale}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "scale", cls.name))


@dataclass(frozen=True)
class GroundEffect(Compiled):
    """Cheeseman-Bennett ground effect: rotor radius [m], ground plane ``z = ground_z`` [m]
    (world NED; 0 = the height where the recording's z is 0)."""

    rotor_radius: float = 0.1
    ground_z: float = 0.0
    name: ClassVar[str] = "ground_effect"
    identifiability: ClassVar[Identifiability] = Identifiability(
        channels=("position",),
        excitation="heights that vary within a few rotor radii of the ground",
        note="the gain depends on the height above the ground, z = 0")
    order: ClassVar[int] = 3

    def __post_init__(self):
        number(self.rotor_radius, "ground_effect rotor radius [m]", 0.0, 2.0)
        number(self.ground_z, "ground_effect ground_z [m]")

    def params(self):
        return {"rotor_radius_m": self.rotor_radius, "ground_z_m": self.ground_z}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "rotor_radius_m", cls.name), params.get("ground_z_m", 0.0))


@dataclass(frozen=True)
class Delay(Compiled):
    """Pure input delay [s] of the rotor thrust (over a step: the mean of the delayed
    zero-order-hold command, so fractional delays are exact)."""

    delay: float = 0.02
    name: ClassVar[str] = "delay"
    identifiability: ClassVar[Identifiability] = Identifiability(
        min_command_rate=20.0, timescale="delay_s", direct=("rotor_speed",),
        excitation="sharp command changes",
        note="a delay shorter than about half a command interval cannot be told from none")
    order: ClassVar[int] = 4

    def __post_init__(self):
        number(self.delay, "delay [s]", 0.0, 2.0)

    def params(self):
        return {"delay_s": self.delay}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "delay_s", cls.name))


@dataclass(frozen=True)
class MotorLag(Compiled):
    """First-order rotor thrust dynamics ``tau f'' = f - f'`` with time constant ``tau`` [s],
    exact for a held command (the kernel of :func:`~quadfault.effects.physics.lag_series`)."""

    tau: float = 0.05
    name: ClassVar[str] = "motor_lag"
    identifiability: ClassVar[Identifiability] = Identifiability(
        min_command_rate=20.0, timescale="tau_s", direct=("rotor_speed",),
        excitation="sharp command changes",
        note="a lag shorter than about half a command interval cannot be told from none "
             "(motor outputs at 10 Hz do not show a lag below about 50 ms); measured rotor "
             "speeds show it directly")
    order: ClassVar[int] = 5

    def __post_init__(self):
        number(self.tau, "motor_lag tau [s]", 0.0, 5.0, open_lo=True)

    def params(self):
        return {"tau_s": self.tau}

    @classmethod
    def from_params(cls, params):
        return cls(param(params, "tau_s", cls.name))
