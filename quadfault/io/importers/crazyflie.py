"""Crazyflie 2.1 vehicle constants, in one place, shared by the Crazyflie importers.

Every number names its source. Rotor positions and spin directions are given as the data
sets' READMEs give them (body FLU, standard Crazyflie numbering M1 front-right, M2 back-right,
M3 back-left, M4 front-left) and converted here, once, to quadfault's FRD convention.

Sources:
- [Eschmann] J. Eschmann, D. Albani, G. Loianno, "Data-Driven System Identification of
  Quadrotors Subject to Motor Delays", IROS 2024 (arXiv:2404.07837); the notebook model quoted
  in ``eschmann-cf21-sysid/README.md``: m = 0.027 kg, rotors at (+-0.028, +-0.028) m FLU,
  yaw-torque directions (-1, +1, -1, +1) FLU.
- [Foerster] J. Foerster, "System Identification of the Crazyflie 2.0 Nano Quadrocopter",
  BSc thesis, ETH Zurich, 2015: per-rotor thrust vs 16-bit PWM
  ``F = 2.130295e-11 PWM^2 + 1.032633e-6 PWM + 5.484560e-4`` [N], thrust-to-torque ratio
  0.005964552 m, inertia diag(16.571710, 16.655602, 29.261652) 1e-6 kg m^2 (also the values
  in the Bitcraze firmware).
- [Busetto] R. Busetto et al., "Nonlinear System Identification for a Nano-drone Benchmark",
  Control Eng. Practice 172 (2026), arXiv:2512.14450; quoted in ``nanodrone-cf21bl/README.md``:
  Crazyflie 2.1 Brushless, m = 0.045 kg, Jxx = Jyy = 2.3951e-5, Jzz = 3.2347e-5 kg m^2,
  L = 0.0353 m per axis, k_F = 3.72e-8 N/(rad/s)^2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadfault.errors import ConfigError
from quadfault.model.effects import curve_thrust
from quadfault.model.vehicle import Vehicle, allocation_from_rotors

#: Standard Crazyflie rotor order in FLU, in units of the per-axis offset:
#: M1 front-right, M2 back-right, M3 back-left, M4 front-left.
CRAZYFLIE_ROTOR_XY_FLU = ((1.0, -1.0), (-1.0, -1.0), (-1.0, 1.0), (1.0, 1.0))
#: Sign of each rotor's reaction torque about +z_FLU ([Eschmann]; confirmed on both data sets:
#: yaw acceleration correlates negatively with m1 + m3 - m2 - m4, see tests).
CRAZYFLIE_YAW_SIGNS_FLU = (-1.0, 1.0, -1.0, 1.0)
#: [Foerster] thrust curve per rotor in u = PWM / 65536: f = a + b u + c u^2 [N].
FOERSTER_THRUST_CURVE = (5.484560e-4, 1.032633e-6 * 65536.0, 2.130295e-11 * 65536.0**2)
#: [Foerster] yaw torque per newton of thrust [m].
FOERSTER_TORQUE_COEFFICIENT = 0.005964552
#: [Foerster] inertia of the Crazyflie 2.0 (diagonal) [kg m^2].
FOERSTER_INERTIA = (16.571710e-6, 16.655602e-6, 29.261652e-6)
#: m/s^2 per g used by the Crazyflie firmware logs (the data READMEs convert with 9.81).
G_CRAZYFLIE = 9.81
#: Mechanical rotor speed per electrical RPM of the brushless motors (6 pole pairs) [rad/s].
ERPM_TO_RAD_S = 2.0 * np.pi / (6.0 * 60.0)


@dataclass(frozen=True)
class CrazyflieSpec:
    """Nominal constants of one Crazyflie variant.

    Attributes:
        name: variant name.
        mass: take-off mass [kg].
        arm: per-axis rotor offset d [m] (rotor at (+-d, +-d)).
        inertia: diagonal inertia (Jxx, Jyy, Jzz) [kg m^2], FLU = FRD diagonal.
        torque_coefficient: yaw torque per newton of thrust [m].
        sources: where each constant comes from (free text, copied into the sidecar).
    """

    name: str
    mass: float
    arm: float
    inertia: tuple
    torque_coefficient: float
    sources: dict

    def allocation(self) -> np.ndarray:
        """(4, 4) FRD allocation, columns in Crazyflie motor order M1..M4."""
        return crazyflie_allocation(self.arm, self.torque_coefficient)

    def vehicle(self, *, mass: float | None = None, max_thrust: float | None = None) -> Vehicle:
        """The nominal vehicle in FRD (``mass`` [kg] overrides the spec's)."""
        return Vehicle(
            mass=self.mass if mass is None else mass,
            inertia=np.diag(self.inertia),
            allocation=self.allocation(),
            gravity=G_CRAZYFLIE,
            max_thrust=max_thrust,
            name=self.name,
        )


def crazyflie_allocation(arm: float, torque_coefficient: float) -> np.ndarray:
    """FRD allocation of the standard Crazyflie X layout (motor order M1..M4).

    FLU -> FRD flips y (positions) and z (so each reaction-torque sign flips too).
    """
    xy_flu = np.asarray(CRAZYFLIE_ROTOR_XY_FLU) * arm
    xy_frd = xy_flu * np.array([1.0, -1.0])
    yaw_frd = -np.asarray(CRAZYFLIE_YAW_SIGNS_FLU)
    return allocation_from_rotors(xy_frd, yaw_frd, torque_coefficient)


#: Crazyflie 2.1 (brushed 7 mm motors, 45 mm propellers) as modelled in [Eschmann].
CF21_BRUSHED = CrazyflieSpec(
    name="Crazyflie 2.1 (brushed)",
    mass=0.027,
    arm=0.028,
    inertia=FOERSTER_INERTIA,
    torque_coefficient=FOERSTER_TORQUE_COEFFICIENT,
    sources={
        "mass": "Eschmann et al. 2024 notebook model (data README)",
        "geometry": "Eschmann et al. 2024: rotors at (+-0.028, +-0.028) m, yaw signs "
        "(-1,+1,-1,+1) FLU",
        "inertia": "Foerster 2015 (Crazyflie 2.0), not fitted to these logs",
        "torque_coefficient": "Foerster 2015: 0.005964552 m",
        "thrust_curve": "Foerster 2015 PWM curve, scaled on the calibration segment",
    },
)

#: Crazyflie 2.1 Brushless as modelled in [Busetto].
CF21_BRUSHLESS = CrazyflieSpec(
    name="Crazyflie 2.1 Brushless",
    mass=0.045,
    arm=0.0353,
    inertia=(2.3951e-5, 2.3951e-5, 3.2347e-5),
    torque_coefficient=FOERSTER_TORQUE_COEFFICIENT,
    sources={
        "mass": "Busetto et al. 2026 (data README)",
        "geometry": "Busetto et al. 2026: L = 0.0353 m per axis; yaw signs (-1,+1,-1,+1) FLU "
        "from the data (the README's tau_z formula has the opposite sign)",
        "inertia": "Busetto et al. 2026 (data README)",
        "torque_coefficient": "Foerster 2015 ratio 0.005964552 m (the authors' K_c/k_F = "
        "2.1e-4 m is flagged in the README as implausibly small)",
        "thrust_curve": "fitted on the calibration segment: k_F omega^2 (measured eRPM, "
        "k_F = 3.72e-8) against the command",
    },
)

#: The brushless motors' thrust coefficient [N/(rad/s)^2] ([Busetto]).
BRUSHLESS_KF = 3.72e-8


def scale_curve_on_segment(
    curve, u: np.ndarray, thrust_measured: np.ndarray, mask: np.ndarray
) -> tuple[tuple, float]:
    """Scale a thrust curve so the summed rotor thrust matches the measured collective thrust
    on average over the calibration rows ``mask``.

    ``thrust_measured`` is m times the accelerometer's specific force along the thrust axis
    [N] (m g in hover; any manoeuvre works, as long as the vehicle is airborne and drag along
    the thrust axis is small). Returns the scaled curve and the scale factor.
    """
    predicted = curve_thrust(curve, u[mask]).sum(axis=1)
    ok = np.isfinite(predicted) & np.isfinite(thrust_measured[mask])
    if ok.sum() < 5 or np.mean(predicted[ok]) <= 0:
        raise ConfigError(
            "calibration segment has fewer than 5 usable airborne samples; "
            "choose another one (--calibration T0,T1)"
        )
    scale = float(np.mean(thrust_measured[mask][ok]) / np.mean(predicted[ok]))
    return tuple(float(scale * c) for c in curve), scale


def calibration_mask(t: np.ndarray, segment) -> np.ndarray:
    """Rows with ``segment[0] <= t <= segment[1]``."""
    return (t >= segment[0]) & (t <= segment[1])
