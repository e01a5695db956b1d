"""Parameters of the environment that are not physics: actions, reward, termination, resets.

The physics parameters live in the core package (:class:`quadfault.model.vehicle.Vehicle`,
:class:`quadfault.model.motors.MotorModel`, :class:`quadfault.sim.simulator.SensorNoise`,
:class:`quadfault.model.scenarios.Scenario`); these dataclasses say how the agent sees and drives it.
"""

from __future__ import annotations

import difflib
import inspect
import math
from dataclasses import dataclass

import numpy as np

from quadfault.errors import ConfigError
from quadfault.jit import jit

ACTION_MODES = ("motor", "residual", "wrench")
#: how a wrench becomes rotor commands: the nominal allocation inverse, or the estimate-aware
#: allocation (quadfault.model.allocation) with the observation's estimate
ALLOCATIONS = ("nominal", "estimate-aware", "relaxed-hover")
ESTIMATOR_RATES = ("physics", "control")
OBSERVATION_KINDS = ("flat", "dict")
TERMINATION_REASONS = ("crash", "out_of_bounds", "excessive_tilt", "non_finite")
#: trajectories of random scenarios (``quadfault.model.scenarios.random_scenario``)
RANDOM_TRAJECTORIES = ("random", "circle", "hover", "lissajous")
#: what ``info`` holds (the single and the vector env): ``"light"`` the keys of
#: :func:`light_info` alone, ``"full"`` every diagnostic as well
INFO_LEVELS = ("light", "full")


def light_info(termination_reason) -> dict:
    """The light ``info`` of a reset or a step, the one definition both environments use
    (the vector env passes arrays over its sub-envs): why the episode terminated (a name of
    :data:`TERMINATION_REASONS`), or None while it goes on. A full ``info`` holds these keys
    and more."""
    return {"termination_reason": termination_reason}


#: the keys of a light ``info``
LIGHT_INFO_KEYS = tuple(light_info(None))


def require_full_info(env, reader: str) -> None:
    """A one-line :class:`ConfigError` when ``env`` (a QuadFault environment, possibly
    wrapped) gives the light ``info`` and ``reader`` reads the full one."""
    if getattr(getattr(env, "unwrapped", env), "info_level", "full") != "full":
        raise ConfigError(
            f"{reader} reads the full info (the measurement stream and the "
            f"truth); make the environment with info='full'"
        )


def keywords_of(init) -> tuple:
    """The keyword names a constructor takes (``self`` and ``*args`` / ``**kwargs`` left out)."""
    kinds = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    return tuple(
        name
        for name, p in inspect.signature(init).parameters.items()
        if p.kind in kinds and name != "self"
    )


def _closest(word, valid) -> str | None:
    """The entry of ``valid`` closest to ``word`` (difflib), or None when none is close."""
    close = difflib.get_close_matches(str(word), [str(v) for v in valid], n=1, cutoff=0.6)
    return close[0] if close else None


def check_keywords(kwargs, valid, owner: str) -> None:
    """Raise a one-line :class:`ConfigError` for the first keyword of ``kwargs`` not in
    ``valid``, naming the closest valid one (``gym.make("QuadFault-v1", estimater="ekf")``)."""
    for key in kwargs:
        if key not in valid:
            close = _closest(key, valid)
            hint = (
                f"did you mean {close!r}?"
                if close
                else f"valid keywords: {', '.join(sorted(valid))}"
            )
            raise ConfigError(f"{owner}: unknown keyword {key!r}; {hint}")


def check_choice(name: str, value, valid: tuple):
    """``value`` when it is one of ``valid``; otherwise a one-line :class:`ConfigError` that
    names the keyword, the valid values and the closest one (``info="ful"``)."""
    if isinstance(value, str) and value in valid:
        return value
    close = _closest(value, valid) if isinstance(value, str) else None
    hint = f"; did you mean {close!r}?" if close else ""
    raise ConfigError(f"{name} must be one of {', '.join(map(repr, valid))}, got {value!r}{hint}")


def _check_nonnegative(obj, names):
    for name in names:
        value = getattr(obj, name)
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
            raise ConfigError(
                f"{type(obj).__name__}.{name} must be a finite number >= 0, got {value!r}"
            )


@dataclass(frozen=True)
class ActionConfig:
    """How an action in [-1, 1]^4 becomes rotor thrust commands [N].

    * ``"motor"``: ``f_i = (a_i + 1) / 2 * f_max``.
    * ``"residual"``: ``f = f_ctrl + residual_scale * a`` where ``f_ctrl`` are the geometric
      controller's commands (nominal allocation; divided by eta_hat when ``compensate``).
    * ``"wrench"``: collective thrust ``T = (a_1 + 1) / 2 * n f_max`` [N] and moments
      ``M_j = a_{j+1} * moment_scale_j`` [N m], through the nominal allocation inverse.

    In every mode the result is clipped to ``[0, f_max]`` (the command the recording stores).

    Attributes:
        mode: one of :data:`ACTION_MODES`.
        residual_scale: thrust added per unit action in residual mode [N].
        moment_scale: moment per unit action in wrench mode (Mx, My, Mz) [N m].
    """

    mode: str = "residual"
    residual_scale: float = 1.0
    moment_scale: tuple = (1.0, 1.0, 0.05)

    def __post_init__(self):
        if self.mode not in ACTION_MODES:
            raise ConfigError(f"action_mode must be one of {ACTION_MODES}, got {self.mode!r}")
        _check_nonnegative(self, ("residual_scale",))
        ms = tuple(float(x) for x in self.moment_scale)
        if len(ms) != 3 or any(not (math.isfinite(x) and x > 0) for x in ms):
            raise ConfigError(
                f"moment_scale must be three positive numbers [N m], got {self.moment_scale!r}"
            )
        object.__setattr__(self, "moment_scale", ms)

    def commands(
        self,
        action: np.ndarray,
        vehicle,
        f_ctrl=None,
        eta_hat=None,
        compensate: bool = False,
        allocator=None,
    ) -> np.ndarray:
        """Rotor thrust commands [N] for checked actions ``(..., 4)`` (one vehicle or a
        batch); ``f_ctrl`` the geometric controller's commands [N] (residual mode), divided by
        ``eta_hat`` (floored at 0.1) with ``compensate``. With ``allocator`` (a
        :class:`~quadfault.model.allocation.EstimateAwareAllocator`) the controller's wrench
        (residual mode) or the agent's (wrench mode) is allocated with ``eta_hat`` instead,
        giving up yaw first when the rotors cannot realise it."""
        f_max = vehicle.rotor_max_thrust
        if allocator is not None and self.mode != "motor":
            if self.mode == "wrench":
                wrench = np.concatenate(
                    (
                        0.5 * (action[..., :1] + 1.0) * vehicle.n_rotors * f_max,
                        action[..., 1:] * np.asarray(self.moment_scale),
                    ),
                    axis=-1,
                )
                f = _allocated(allocator, wrench, eta_hat)
            else:  # the controller's wrench (eq. 12: w = A f_ctrl)
                f = _allocated(allocator, f_ctrl @ vehicle.allocation.T, eta_hat)
                f = f + self.residual_scale * action
            return np.minimum(np.maximum(f, 0.0), f_max)
        a = np.ascontiguousarray(action, dtype=float)
        n = vehicle.n_rotors
        out = np.empty(a.shape[:-1] + (n,))
        rows = a.reshape(-1, a.shape[-1])
        B = len(rows)
        mode, comp, scale, ms = self.params(bool(compensate))
        # the kernel reads the controller's commands in residual mode and the estimate only
        # with compensation; otherwise it is given its output there (not read)
        ctrl = out.reshape(B, n)
        if mode == 1:
            ctrl = np.ascontiguousarray(np.broadcast_to(f_ctrl, (B, n)), dtype=float)
        eta = out.reshape(B, n)
        if mode == 1 and comp:
            eta = np.ascontiguousarray(np.broadcast_to(eta_hat, (B, n)), dtype=float)
        _action_rows(
            rows,
            ctrl,
            eta,
            mode,
            comp,
            scale,
            ms[0],
            ms[1],
            ms[2],
            float(f_max),
            vehicle.allocation_inverse,
            out.reshape(B, n),
        )
        return out

    def params(self, compensate: bool = False) -> tuple:
        """The mapping as the compiled one (:func:`action_commands_row`) takes it: the mode's
        index in :data:`ACTION_MODES`, whether the controller's commands are divided by the
        estimate, the residual scale and the three moment scales."""
        ms = self.moment_scale
        return (
            ACTION_MODES.index(self.mode),
            bool(compensate),
            float(self.residual_scale),
            (float(ms[0]), float(ms[1]), float(ms[2])),
        )


@jit(inline="always")
def action_commands_row(a, f_ctrl, eta_hat, params, f_max, allocation_inverse, out):
    """:meth:`ActionConfig.commands` of one vehicle without an estimate-aware allocator: the
    one definition of the action mapping, compiled (the single env and the vector env's
    fused step call it). ``a`` the checked action (4,), ``f_ctrl`` the geometric
    controller's commands [N] (residual mode), ``eta_hat`` the estimate (with compensation),
    ``params`` :meth:`ActionConfig.params`; the commands [N], clipped to [0, f_max], into
    ``out``."""
    mode, compensate, residual_scale, ms = params
    n = out.shape[0]
    if mode == 0:  # motor
        for j in range(n):
            out[j] = 0.5 * (a[j] + 1.0) * f_max
    elif mode == 2:  # wrench: collective thrust and moments through the nominal inverse
        w0 = 0.5 * (a[0] + 1.0) * n * f_max
        w1, w2, w3 = a[1] * ms[0], a[2] * ms[1], a[3] * ms[2]
        for j in range(n):
            B = allocation_inverse[j]
            out[j] = w0 * B[0] + w1 * B[1] + w2 * B[2] + w3 * B[3]
    else:  # residual on the controller's commands
        for j in range(n):
            f = f_ctrl[j]
            if compensate:
                f = f / max(eta_hat[j], 0.1)
            out[j] = f + residual_scale * a[j]
    for j in range(n):  # NaN stays NaN, as numpy's minimum / maximum
        if out[j] < 0.0:
            out[j] = 0.0
        if out[j] > f_max:
            out[j] = f_max


@jit
def _action_rows(a, f_ctrl, eta_hat, mode, comp, scale, ms0, ms1, ms2, f_max, alloc_inv, out):
    """:func:`action_commands_row` per row."""
    params = (mode, comp, scale, (ms0, ms1, ms2))
    for i in range(out.shape[0]):
        action_commands_row(a[i], f_ctrl[i], eta_hat[i], params, f_max, alloc_inv, out[i])


def _allocated(allocator, wrench: np.ndarray, eta_hat) -> np.ndarray:
    """Rotor commands [N] of wrenches ``(..., 4)`` through ``allocator`` with ``eta_hat``."""
    rows = wrench.reshape(-1, wrench.shape[-1])
    eta = np.broadcast_to(np.asarray(eta_hat, dtype=float), rows.shape)
    return allocator.allocate_rows(rows, eta).f.reshape(wrench.shape)


@dataclass(frozen=True)
class RewardConfig:
    """Per-step reward::

        r = exp(-(|e_x| + velocity_weight |e_v|) / position_scale)      tracking, in (0, 1]
            - effort_weight * mean((f_cmd / f_max)^2)                   thrust effort
            - action_weight * mean(a^2)                                 action effort
            + survival_bonus        (on every step that does not terminate)
            - termination_penalty   (on the step that terminates; not on truncation)

    with the *true* tracking errors ``e_x`` [m], ``e_v`` [m/s] at the end of the step, the
    rotor commands ``f_cmd`` held over it and the agent's action ``a`` in [-1, 1]^4 (in
    residual mode the correction it adds to the geometric controller). A step whose terms are
    not finite (a diverged state) counts 0 before the penalty.

    With ``survival_bonus >= effort_weight + action_weight`` (the defaults) every step that
    does not terminate earns at least 0, and a terminating one at most
    ``1 - termination_penalty``: an episode that terminates at any step scores below one that
    flies on with the same tracking and effort, by the penalty plus what the remaining steps
    would have earned. The defaults are the ``-v1`` reward; the ``-v0`` ids use
    ``position_scale=1``, no action effort, no survival bonus and no penalty
    (:data:`quad_fault_env.tasks.REWARD_V0`).

    Attributes:
        position_scale: error at which the tracking term falls to 1/e [m].
        velocity_weight: weight of |e_v| relative to |e_x| [s].
        effort_weight: weight of the thrust effort term [-].
        action_weight: weight of the action effort term [-].
        survival_bonus: added on every step that does not terminate [-].
        termination_penalty: subtracted once on termination [-].
    """

    position_scale: float = 0.5
    velocity_weight: float = 0.1
    effort_weight: float = 0.01
    action_weight: float = 0.1
    survival_bonus: float = 0.11
    termination_penalty: float = 100.0

    def __post_init__(self):
        _check_nonnegative(
            self,
            (
                "velocity_weight",
                "effort_weight",
                "action_weight",
                "survival_bonus",
                "termination_penalty",
            ),
        )
        if not (math.isfinite(self.position_scale) and self.position_scale > 0):
            raise ConfigError(f"position_scale must be positive [m], got {self.position_scale!r}")

    def params(self) -> tuple:
        """The weights as the compiled reward (:func:`reward_row`) takes them."""
        return (
            float(self.position_scale),
            float(self.velocity_weight),
            float(self.effort_weight),
            float(self.action_weight),
            float(self.survival_bonus),
            float(self.termination_penalty),
        )

    def __call__(self, pos_err, vel_err, f_cmd, f_max: float, terminated, action=None):
        """The reward: a float for one vehicle, an array for rows (the vector env:
        ``pos_err`` (N, 3), ``terminated`` (N,), ``action`` (N, 4)). ``action`` None counts
        as zero."""
        pe = np.ascontiguousarray(pos_err, dtype=float)
        f = np.ascontiguousarray(f_cmd, dtype=float)
        a = np.zeros_like(f) if action is None else np.ascontiguousarray(action, dtype=float)
        out = np.empty(pe.shape[:-1])
        _rewards(
            pe.reshape(-1, 3),
            np.ascontiguousarray(vel_err, dtype=float).reshape(-1, 3),
            f.reshape(-1, f.shape[-1]),
            float(f_max),
            np.ascontiguousarray(terminated, dtype=np.bool_).reshape(-1),
            a.reshape(-1, a.shape[-1]),
            *self.params(),  # numbers, not a tuple: a tuple argument costs numba's dispatch
            out.reshape(-1),
        )
        return float(out) if out.ndim == 0 else out


@jit(inline="always")
def reward_row(pe, ve, f_cmd, f_max, terminated, action, params):
    """:class:`RewardConfig` of one vehicle: the one definition of the reward, compiled (the
    single env, the vector env's rows and its fused step call it). ``pe``, ``ve`` the true
    position and velocity errors (3 numbers each, any indexable), ``f_cmd`` the rotor
    commands held [N] and ``action`` the agent's action (arrays), ``params``
    :meth:`RewardConfig.params`."""
    scale, w_vel, w_effort, w_action, bonus, penalty = params
    track = math.sqrt(pe[0] * pe[0] + pe[1] * pe[1] + pe[2] * pe[2]) + w_vel * math.sqrt(
        ve[0] * ve[0] + ve[1] * ve[1] + ve[2] * ve[2]
    )
    effort = 0.0
    for j in range(f_cmd.shape[0]):
        u = f_cmd[j] / f_max
        effort += u * u
    r = math.exp(-track / scale) - w_effort * (effort / f_cmd.shape[0])
    if w_action != 0.0:
        act = 0.0
        for j in range(action.shape[0]):
            act += action[j] * action[j]
        r -= w_action * (act / action.shape[0])
    if not np.isfinite(r):
        r = 0.0
    return r - penalty if terminated else r + bonus


@jit
def _rewards(
    pos_err, vel_err, f_cmd, f_max, terminated, action, scale, w_vel, w_eff, w_act, bonus, pen, out
):
    """:func:`reward_row` per row."""
    params = (scale, w_vel, w_eff, w_act, bonus, pen)
    for i in range(out.shape[0]):
        out[i] = reward_row(
            pos_err[i], vel_err[i], f_cmd[i], f_max, terminated[i], action[i], params
        )


@dataclass(frozen=True)
class TerminationLimits:
    """When an episode terminates (checked on the true state after every control step).

    Attributes:
        ground_altitude: ``"crash"`` when the altitude ``-p_z`` falls below this [m].
        max_position_error: ``"out_of_bounds"`` when ``|p - p_ref|`` exceeds this [m].
        max_tilt: ``"excessive_tilt"`` when the angle between body z and world z exceeds this
            [rad].
    ``"non_finite"`` is reported when the state stops being finite.
    """

    ground_altitude: float = 0.0
    max_position_error: float = 5.0
    max_tilt: float = math.radians(80.0)

    def __post_init__(self):
        if not math.isfinite(self.ground_altitude):
            raise ConfigError("ground_altitude must be finite [m]")
        if not (self.max_position_error > 0):
            raise ConfigError(
                f"max_position_error must be positive [m], got {self.max_position_error!r}"
            )
        if not (0 < self.max_tilt <= math.pi):
            raise ConfigError(f"max_tilt must be in (0, pi] [rad], got {self.max_tilt!r}")

    def params(self) -> tuple:
        """The limits as the compiled check (:func:`termination_code`) takes them."""
        return (float(self.ground_altitude), float(self.max_position_error), float(self.max_tilt))

    def reasons(self, p, R, p_ref) -> np.ndarray:
        """Termination reasons of true positions ``p`` (N, 3), attitudes ``R`` (N, 3, 3)
        against the references ``p_ref`` (N, 3): an object array of names or None."""
        return REASONS[self.codes(p, R, p_ref)]

    def codes(self, p, R, p_ref) -> np.ndarray:
        """:meth:`reasons` as integer codes (N,): the index of each reason in
        :data:`REASONS` (0: none)."""
        codes = np.empty(len(p), dtype=np.int64)
        _termination_codes(
            np.ascontiguousarray(p, dtype=float),
            np.ascontiguousarray(R, dtype=float),
            np.ascontiguousarray(p_ref, dtype=float),
            *self.params(),
            codes,
        )
        return codes

    def reason(self, p, R, p_ref) -> str | None:
        """The termination reason for one true position ``p``, attitude ``R``, or None."""
        return self.reasons(np.asarray(p)[None], np.asarray(R)[None], np.asarray(p_ref)[None])[0]


#: termination codes of :func:`_termination_codes` -> reasons
REASONS = np.array([None, "excessive_tilt", "out_of_bounds", "crash", "non_finite"], dtype=object)


@jit(inline="always")
def termination_code(p, R, p_ref, limits):
    """:class:`TerminationLimits` of one vehicle: the one definition of termination, compiled
    (the single env, the vector env's rows and its fused step call it). ``p`` the true
    position, ``R`` the true attitude as 9 numbers row by row, ``p_ref`` the reference
    position (3 numbers each), ``limits`` :meth:`TerminationLimits.params`. The code in
    :data:`REASONS`, by precedence: non_finite (4), crash (3), out_of_bounds (2),
    excessive_tilt (1); 0 = none."""
    ground, max_error, max_tilt = limits
    finite = np.isfinite(p[0]) and np.isfinite(p[1]) and np.isfinite(p[2])
    for k in range(9):
        finite = finite and np.isfinite(R[k])
    d0, d1, d2 = p[0] - p_ref[0], p[1] - p_ref[1], p[2] - p_ref[2]
    if not finite:
        return 4
    if -p[2] < ground:
        return 3
    if math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) > max_error:
        return 2
    c = min(max(R[8], -1.0), 1.0)
    # the tilt acos(c) is at most pi sqrt((1 - c) / 2), below max_tilt / sqrt(2) when
    # (1 - c) pi^2 < max_tilt^2: no acos needed (the margin dwarfs any rounding)
    if (1.0 - c) * (math.pi * math.pi) < max_tilt * max_tilt:
        return 0
    if math.acos(c) > max_tilt:
        return 1
    return 0


@jit(inline="always")
def row3(a, i):
    """Row ``i`` of an (N, 3) array as 3 numbers (no view: a view takes a reference count)."""
    return (a[i, 0], a[i, 1], a[i, 2])


@jit(inline="always")
def row33(a, i):
    """Row ``i`` of an (N, 3, 3) array as 9 numbers, row by row."""
    return (
        a[i, 0, 0],
        a[i, 0, 1],
        a[i, 0, 2],
        a[i, 1, 0],
        a[i, 1, 1],
        a[i, 1, 2],
        a[i, 2, 0],
        a[i, 2, 1],
        a[i, 2, 2],
    )


@jit
def _termination_codes(p, R, p_ref, ground, max_error, max_tilt, out):
    """:func:`termination_code` per row."""
    limits = (ground, max_error, max_tilt)
    for i in range(out.shape[0]):
        out[i] = termination_code(row3(p, i), row33(R, i), row3(p_ref, i), limits)


@dataclass(frozen=True)
class InitialStateSpread:
    """Uniform perturbation of the initial state around the reference's start.

    Each component is drawn from ``U(-x, x)`` with ``self.np_random``.

    Attributes:
        position: per-axis half-width [m].
        velocity: per-axis half-width [m/s].
        attitude: per-axis half-width of a rotation vector [rad].
        rate: per-axis half-width of the body rate [rad/s].
    """

    position: float = 0.0
    velocity: float = 0.0
    attitude: float = 0.0
    rate: float = 0.0

    def __post_init__(self):
        _check_nonnegative(self, ("position", "velocity", "attitude", "rate"))


def config_of(value, cls, name: str):
    """An environment keyword that takes a configuration dataclass: None (its defaults), an
    instance of ``cls``, or a dict of its fields (``quadfault train --env-kwargs`` JSON)."""
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    if isinstance(value, dict):
        try:
            return cls(**value)
        except TypeError:
            known = ", ".join(cls.__dataclass_fields__)
            raise ConfigError(
                f"{name} has unknown keys {sorted(value)}; choose from {known}"
            ) from None
    raise ConfigError(f"{name} must be a {cls.__name__} or a dict of its fields, got {value!r}")


def validate_action(action, shape: tuple, name: str = "action") -> np.ndarray:
    """An agent's action as a float array of ``shape`` inside [-1, 1].

    Raises ValueError naming the problem (non-numeric, wrong shape, NaN/inf, outside the box
    by more than 1e-6); values within the tolerance are clipped.
    """
    try:
        a = np.asarray(action, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numeric, got {action!r}") from None
    if a.shape != tuple(shape):
        raise ValueError(f"{name} has shape {a.shape}, expected {tuple(shape)}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or inf: {a.tolist()}")
    if np.any(np.abs(a) > 1.0 + 1e-6):
        raise ValueError(f"{name} outside [-1, 1]: {a.tolist()} (the agent must clip)")
    return np.clip(a, -1.0, 1.0)


def number_at_least(value, low: float) -> bool:
    """Whether ``value`` is a finite real number >= ``low``."""
    return (
        isinstance(value, (int, float, np.integer, np.floating))
        and not isinstance(value, bool)
        and math.isfinite(value)
        and value >= low
    )


#: keywords of ``random_faults``: (low, high) ranges and probabilities of ``random_scenario``
_RANGE_KEYS = ("n_faults", "severity", "xi_range", "thrust_noise")
_PROB_KEYS = ("degradation_prob", "ramp_prob")


def check_random_faults(spec) -> dict:
    """Validate ``random_faults`` (None: the defaults of ``random_scenario``)."""
    if spec is None:
        return {}
    if not isinstance(spec, dict):
        raise ConfigError(f"random_faults must be a dict of random_scenario keywords, got {spec!r}")
    out = {}
    for key, value in spec.items():
        if key in _PROB_KEYS:
            if not (number_at_least(value, 0.0) and value <= 1.0):
                raise ConfigError(
                    f"random_faults[{key!r}] must be a probability in [0, 1], got {value!r}"
                )
            out[key] = float(value)
        elif key in _RANGE_KEYS:
            try:
                low, high = (float(v) for v in value)
            except (TypeError, ValueError):
                raise ConfigError(
                    f"random_faults[{key!r}] must be a (low, high) pair, got {value!r}"
                ) from None
            if not (math.isfinite(low) and math.isfinite(high) and 0.0 <= low <= high):
                raise ConfigError(
                    f"random_faults[{key!r}] must satisfy 0 <= low <= high, got {value!r}"
                )
            if key == "n_faults":
                if low != int(low) or high != int(high):
                    raise ConfigError(
                        f"random_faults['n_faults'] must be whole numbers, got {value!r}"
                    )
                out[key] = (int(low), int(high))
            elif key == "severity" and high > 1.0:
                raise ConfigError(
                    f"random_faults['severity'] levels are efficiencies in [0, 1], got {value!r}"
                )
            else:
                out[key] = (low, high)
        else:
            raise ConfigError(
                f"random_faults has unknown key {key!r}; choose from "
                f"{', '.join(_RANGE_KEYS + _PROB_KEYS)}"
            )
    return out
