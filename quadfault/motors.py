"""Motor model: saturation, efficiency and thrust noise (paper eqs. 11, 13 and Sec. IV-A).

For each rotor i and physics step::

    f_i = eta_i * clip(f_cmd_i, 0, f_max) * exp(eps_i),   eps_i ~ N(0, sigma_f)

* ``eta`` is the efficiency E = diag(eta) of eq. (13) (1 = nominal).
* Saturation acts on the command: a motor cannot be driven past ``f_max`` (the default is
  thrust-to-weight 2, 4.9 N for the paper's vehicle), and a weak motor at full command gives
  ``eta * f_max``. The reference code clips only at zero (``saturate=False`` reproduces it:
  ``max(0, eta f exp(eps))``, the same thing below the upper limit).
* The noise is multiplicative and i.i.d. per motor per step, as in the paper.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadfault.errors import ConfigError


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

    def apply(self, f_cmd: np.ndarray, eta: np.ndarray, f_max: float,
              rng: np.random.Generator | None) -> np.ndarray:
        """Thrust [N] each rotor produces for commands ``f_cmd`` [N] (``(..., n)``)."""
        f = np.asarray(f_cmd, dtype=float)
        f = np.clip(f, 0.0, f_max) if self.saturate else np.maximum(f, 0.0)
        f = f * eta
        if self.thrust_noise > 0:
            if rng is None:
                raise ConfigError("thrust noise needs a numpy Generator (rng)")
            f = f * np.exp(self.thrust_noise * rng.standard_normal(f.shape))
        return f
