"""Motor model: saturation, efficiency and thrust noise (paper eqs. 11, 13 and Sec. IV-A).

For each rotor i and physics step::

    f_i = eta_i * clip(f_cmd_i, 0, f_max) * exp(eps_i),   eps_i ~ N(0, sigma_f)

* ``eta`` is the efficiency E = diag(eta) of eq. (13) (1 = nominal).
* Saturation acts on the command: a motor cannot be driven past ``f_max`` (the default is
  thrust-to-weight 2, 4.9 N for the paper's vehicle), and a weak motor at full command gives
  ``eta * f_max``. The reference code clips only at zero (``saturate=False`` reproduces it:
  ``max(0, eta f exp(eps))``, the same thing below the upper limit).
* The noise is multiplicative and i.i.d. per motor per step, as in the paper, drawn from the
  caller's generator in rotor order.

:func:`motor_thrust` is the kernel (one vehicle, one step); :meth:`MotorModel.apply` runs it
over the rows of an array.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadfault.errors import ConfigError
from quadfault.jit import jit

#: a generator that is never drawn from (the kernels' stand-in when there is no noise)
_NO_DRAWS = np.random.default_rng(0)


@jit(inline="always")
def motor_thrust(f_cmd, eta, row, f_max, saturate, sigma, gen, out):
    """Thrust [N] each rotor produces (eqs. 11, 13) into ``out`` (n,): command ``f_cmd`` (n,)
    [N] clipped to ``[0, f_max]`` (only at 0 without ``saturate``), times the efficiency
    ``eta[row]`` and, when ``sigma > 0``, ``exp(sigma eps)`` with ``eps`` drawn from ``gen``.

    Arrays are indexed element by element (no slice per step: a view would touch the
    parent's reference count, an atomic operation the threads of a parallel loop contend for).
    """
    for i in range(out.shape[0]):
        fi = max(f_cmd[i], 0.0)
        if saturate:
            fi = min(fi, f_max)
        fi = fi * eta[row, i]
        if sigma > 0:
            fi = fi * math.exp(sigma * gen.standard_normal())
        out[i] = fi


@jit
def _motor_rows(f_cmd, eta, f_max, saturate, sigma, gen, out):
    for r in range(f_cmd.shape[0]):
        motor_thrust(f_cmd[r], eta, r, f_max, saturate, sigma, gen, out[r])


@dataclass(frozen=True)
class MotorModel:
    """Actuator non-idealities of the true plant.

    Attributes:
        thrust_noise: sigma_f, standard deviation of the log-thrust noise (0.07 in the paper).
        saturate: clip commands to ``[0, f_max]``; ``False`` clips only at 0 (reference code).
    """

    thrust_noise: float = 0.0
    saturate: bool = True

    def __post_init__(self):
        if not (math.isfinite(self.thrust_noise) and self.thrust_noise >= 0):
            raise ConfigError(f"thrust_noise must be >= 0, got {self.thrust_noise!r}")

    def apply(
        self, f_cmd: np.ndarray, eta, f_max: float, rng: np.random.Generator | None
    ) -> np.ndarray:
        """Thrust [N] each rotor produces for commands ``f_cmd`` [N] (``(..., n)``), row by row
        (:func:`motor_thrust`; the noise of a row drawn after the previous row's)."""
        f = np.asarray(f_cmd, dtype=float)
        if self.thrust_noise > 0 and rng is None:
            raise ConfigError("thrust noise needs a numpy Generator (rng)")
        flat = np.ascontiguousarray(f.reshape(-1, f.shape[-1]))
        e = np.ascontiguousarray(
            np.broadcast_to(np.asarray(eta, dtype=float), f.shape).reshape(flat.shape)
        )
        out = np.empty_like(flat)
        _motor_rows(
            flat,
            e,
            float(f_max),
            bool(self.saturate),
            float(self.thrust_noise),
            rng if rng is not None else _NO_DRAWS,
            out,
        )
        return out.reshape(f.shape)
