"""Settings and per-window diagnostics of the sliding-window IRLS estimator.

:class:`IRLSConfig` holds every setting of :class:`estimators.irls.SlidingWindowIRLS`
(defaults: the authors' reference code; :meth:`IRLSConfig.improved` the options beyond the
paper); :class:`IRLSDiagnostics` says what happened in one window update
(:func:`window_diagnostics` builds it from the outcome of the compiled window solve), and
:class:`LazyWindowDiagnostics` is the same built on first read. All are re-exported by
:mod:`estimators.irls`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from estimators.accelerometer import check_mode
from estimators.base import STATUSES
from estimators.ipm import IPMSettings
from estimators.residuals import residual_weights
from quadfault.errors import ConfigError

SCALINGS = ("reference", "paper")


@dataclass(frozen=True)
class IRLSConfig:
    """Settings of :class:`SlidingWindowIRLS` (defaults: the authors' reference code).

    Attributes:
        window: samples per window n (n - 1 segments).
        g_v, g_x, g_omega, g_R: diagonal of the per-segment weight G_i (eq. 23) for the
            velocity [1/(m/s)^2], position [1/m^2], rate [1/(rad/s)^2] and rotation residuals.
        gamma: smoothness weight (gamma/2)||eta - eta_prev||^2.
        eta_min, eta_max: physical bounds of the efficiency; bound_eps widens them
            (the reference's bound_safe_eps) so the box is [eta_min - eps, eta_max + eps].
        scaling: "reference" (no 1/sqrt(n) factor, weights divided by their median, w_min
            unused) or "paper" (residual scaled by 1/sqrt(segments), w_min floor, no median
            normalisation).
        z_soft, soft_power, z_hard, hard_drop, w_min, mad_eps: robust weights (eqs. 27-30).
        max_irls: outer IRLS rounds N_IRLS; irls_tol: stop when ||x_new - x||_inf < irls_tol.
        ipm: interior-point settings (Algorithm 1).
        cond_max: conditioning guard on the 1-norm condition number of J^T G J.
        min_thrust: a window whose mean commanded collective thrust is below this [N] carries
            no information (``no_excitation``).
        clip_commands: clip the commanded thrusts to ``[0, vehicle.rotor_max_thrust]`` before
            use (a rotor cannot deliver more than its limit; without this a saturated weak
            motor looks weaker than it is); ``run(recording)`` clips above only when the
            recording does not say its flight was unsaturated (sidecar ``saturated``,
            :func:`estimators.base.command_limit`). ``False`` = the reference code (no
            clipping).
        record_history: keep per-round KKT histories in the diagnostics (slower).
        change_completion: beyond the paper (off = the paper/reference): when the estimate
            moves by more than ``change_threshold`` [1] on some motor over ``window - 1``
            windows, complete the
            change's weak-direction (yaw-differential) component by the sparsest
            (single-motor) change for the next ``change_hold`` windows instead of leaving it
            to the smoothness prior (:mod:`estimators.change_completion`, docs/irls.md).
        output_median: beyond the paper: the reported estimate is the causal running median
            of the last ``output_median`` estimates [samples] (1 = off, the paper). Only the
            output is filtered; the next window is still anchored to the unfiltered estimate.
            Delays a step by about ``output_median / 2`` samples.
        prefilter: beyond the paper: the time constant [s] of the low-pass filter applied
            to both sides of each segment's residual, ``r0`` and ``J``
            (:func:`estimators.residuals.prefilter_into`; 0 = off, the paper). Against
            sensor noise: the noise differenced between two samples 1 ms apart falls by
            about ``dt / prefilter``, a change is delayed by about ``prefilter``.
        accelerometer: beyond the paper: where the thrust rows come from
            (:mod:`estimators.accelerometer`): ``"off"`` the differenced velocity (the
            paper), ``"auto"`` the accelerometer's specific force wherever a sample has it
            (the position rows then unused), ``"on"`` the same, and a recording or sample
            without an accelerometer is said once. True / False mean ``"on"`` / ``"off"``.
    """

    window: int = 10
    g_v: float = 50.0
    g_x: float = 50.0
    g_omega: float = 1.0
    g_R: float = 50.0
    gamma: float = 5e-3
    eta_min: float = 0.0
    eta_max: float = 1.0
    bound_eps: float = 1e-3
    scaling: str = "reference"
    z_soft: float = 2.5
    soft_power: float = 7.0
    z_hard: float = 2.5
    hard_drop: bool = True
    w_min: float = 0.03
    mad_eps: float = 1e-9
    max_irls: int = 3
    irls_tol: float = 1e-3
    ipm: IPMSettings = field(default_factory=IPMSettings)
    cond_max: float = 1e4
    min_thrust: float = 1e-3
    clip_commands: bool = True
    record_history: bool = False
    change_completion: bool = False
    change_threshold: float = 0.2
    change_hold: int = 20
    output_median: int = 1
    prefilter: float = 0.0
    accelerometer: str = "off"

    @classmethod
    def improved(cls, **changes) -> IRLSConfig:
        """The reference settings plus the options beyond the paper (docs/irls.md): the
        spike guards, change completion and a 21-sample causal output median ("Spikes"),
        the residual prefilter of 10 ms against sensor noise ("Sensor noise") and the
        thrust rows from the accelerometer wherever the data has one ("Accelerometer")."""
        return cls(
            **{
                "change_completion": True,
                "output_median": 21,
                "prefilter": 0.01,
                "accelerometer": "auto",
                **changes,
            }
        )

    @classmethod
    def from_options(
        cls,
        improved: bool = False,
        median: int | None = None,
        prefilter: float | None = None,
        accelerometer: str | bool | None = None,
    ) -> IRLSConfig:
        """The configuration of ``quadfault estimate``'s options (the registry's
        ``from_options``): ``improved`` the options beyond the paper (:meth:`improved`),
        ``median`` the online output median [samples] (overrides ``improved``'s 21),
        ``prefilter`` the residual prefilter's time constant [s] (overrides ``improved``'s),
        ``accelerometer`` where the thrust rows come from (overrides ``improved``'s)."""
        changes = {} if median is None else {"output_median": int(median)}
        if prefilter is not None:
            changes["prefilter"] = float(prefilter)
        if accelerometer is not None:
            changes["accelerometer"] = accelerometer
        return cls.improved(**changes) if improved else cls(**changes)

    def __post_init__(self):
        if not (isinstance(self.window, int) and self.window >= 3):
            raise ConfigError(f"IRLS window must be an integer >= 3 samples, got {self.window!r}")
        for key in (
            "g_v",
            "g_x",
            "g_omega",
            "g_R",
            "gamma",
            "bound_eps",
            "z_soft",
            "soft_power",
            "z_hard",
            "w_min",
            "mad_eps",
            "irls_tol",
            "cond_max",
            "min_thrust",
            "change_threshold",
            "prefilter",
        ):
            value = getattr(self, key)
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float))
                or not math.isfinite(value)
                or value < 0
            ):
                raise ConfigError(f"IRLS setting {key} must be a finite number >= 0, got {value!r}")
        if not (
            math.isfinite(self.eta_min)
            and math.isfinite(self.eta_max)
            and self.eta_min < self.eta_max
        ):
            raise ConfigError(
                f"IRLS bounds need eta_min < eta_max, got {self.eta_min!r}, {self.eta_max!r}"
            )
        if self.scaling not in SCALINGS:
            raise ConfigError(f"IRLS scaling must be one of {SCALINGS}, got {self.scaling!r}")
        if not (isinstance(self.max_irls, int) and self.max_irls >= 1):
            raise ConfigError(f"IRLS max_irls must be an integer >= 1, got {self.max_irls!r}")
        if not isinstance(self.ipm, IPMSettings):
            raise ConfigError("IRLS ipm must be an IPMSettings")
        for key in ("change_hold", "output_median"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"IRLS setting {key} must be an integer >= 1, got {value!r}")
        object.__setattr__(self, "accelerometer", check_mode("IRLSConfig", self.accelerometer))
        if not isinstance(self.change_completion, bool):
            raise ConfigError(
                f"IRLS change_completion must be True or False, got {self.change_completion!r}"
            )

    @property
    def lower(self) -> float:
        """Lower bound of the box [1]."""
        return self.eta_min - self.bound_eps

    @property
    def upper(self) -> float:
        """Upper bound of the box [1]."""
        return self.eta_max + self.bound_eps

    @property
    def segment_weights(self) -> np.ndarray:
        """Diagonal of G_i, (10,)."""
        return residual_weights(self.g_v, self.g_x, self.g_omega, self.g_R)


@dataclass(frozen=True)
class IRLSDiagnostics:
    """What happened in one window update.

    Attributes:
        status, message: outcome (see :data:`estimators.base.STATUSES`).
        inner_iterations: interior-point iterations of each IRLS round.
        weights: final robust segment weights (segments,), or None when no round ran.
        rejected: indices of segments with weight 0 (0 = oldest segment of the window).
        cond: 1-norm condition number of J^T G J in the last round.
        dual_history, cent_history, gap_history: per round, ``||r_dual||``, ``||r_cent||``
            and the surrogate gap after each interior-point iteration (record_history only).
        residual_history: per round, the weighted residual norm ``sqrt(r^T G r)`` after each
            iteration (the paper's "primal residual", record_history only).
    """

    status: str
    message: str = ""
    inner_iterations: tuple = ()
    weights: np.ndarray | None = None
    rejected: tuple = ()
    cond: float = float("nan")
    dual_history: tuple | None = None
    cent_history: tuple | None = None
    gap_history: tuple | None = None
    residual_history: tuple | None = None


def window_diagnostics(
    code: int, rounds: int, cond: float, iters, weights, cfg: IRLSConfig, hist=None
) -> IRLSDiagnostics:
    """The :class:`IRLSDiagnostics` of a window solve (:func:`estimators.window.solve_window_into`:
    status ``code``, ``rounds`` IRLS rounds with ``iters`` interior-point iterations each,
    final weights, condition number, and the per-round histories ``hist`` when recorded)."""
    status = STATUSES[code]
    message = ""
    if status == "rejected":
        message = "every segment rejected"
    elif status == "max_iter":
        message = f"interior point stopped at {cfg.ipm.max_iter} iterations"
    elif status == "ill_conditioned":
        message = f"cond(J^T G J) = {cond:.3g} > {cfg.cond_max:g}"
    w = np.array(weights, dtype=float)
    its = tuple(int(k) for k in np.asarray(iters)[:rounds])
    kw = {}
    if hist is not None:
        n = hist.shape[2] - 4
        kw = {
            name: tuple(hist[r, :k, col].copy() for r, k in enumerate(its))
            for name, col in (
                ("dual_history", 0),
                ("cent_history", 1),
                ("gap_history", 2),
                ("residual_history", 3 + n),
            )
        }
    return IRLSDiagnostics(
        status, message, its, w, tuple(int(i) for i in np.flatnonzero(w == 0)), float(cond), **kw
    )


class LazyWindowDiagnostics(IRLSDiagnostics):
    """The :class:`IRLSDiagnostics` of an online window solve, built on first read.

    The online update runs at every physics substep while its diagnostics are mostly
    ignored, so it keeps only the raw outcome (status code, IRLS rounds, condition number, a
    copy of the interior-point iteration counts and of the final weights); any field read
    builds them (:func:`window_diagnostics`). It is an ``IRLSDiagnostics`` in every respect:
    same fields, ``dataclasses.fields`` / ``asdict``.
    """

    def __init__(self, code: int, rounds: int, cond: float, iters, weights, config):
        object.__setattr__(self, "_raw", (code, rounds, cond, iters, weights, config))
        object.__setattr__(self, "_built", None)

    def _get(self, name):
        built = self._built
        if built is None:
            built = window_diagnostics(*self._raw)
            object.__setattr__(self, "_built", built)
        return getattr(built, name)

    @property
    def status(self) -> str:
        return STATUSES[self._raw[0]]

    @property
    def weights(self):
        return self._raw[4]


for _name in IRLSDiagnostics.__dataclass_fields__:
    if _name not in ("status", "weights"):
        setattr(LazyWindowDiagnostics, _name, property(lambda self, _n=_name: self._get(_n)))
del _name
