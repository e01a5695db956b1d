"""Controllers as policies with stable-baselines3's ``predict`` interface.

:class:`GeometricPolicy` maps a QuadFault observation (:mod:`quad_fault_env.observation`)
to an action in ``[-1, 1]^4`` with the geometric controller (paper eqs. 9-10), so the
baseline runs through the same evaluation code as a trained model::

    policy = GeometricPolicy.from_env(env)               # or estimate_aware=True
    action, _ = policy.predict(obs, deterministic=True)

The observation holds tracking errors, attitude, body rate, ``eta_hat`` and the reference
acceleration but not the reference heading, so the policy holds the *current* heading
(heading-free tracking; angular feed-forward off). Per action mode:

* ``"residual"``: the environment adds the action to its own geometric controller, so the
  plain policy returns zeros (exactly the baseline). With ``estimate_aware=True`` it returns
  the difference between the estimate-aware allocation (:mod:`quadfault.model.allocation`, using the
  observation's ``eta_hat``) and the nominal one, divided by ``residual_scale`` and clipped
  to [-1, 1] (so its authority is bounded by ``residual_scale`` [N] per rotor).
* ``"motor"``: ``a_i = 2 f_i / f_max - 1`` for the (estimate-aware or nominal) commands.
* ``"wrench"``: thrust and moments scaled as the environment expects (nominal only).
"""

from __future__ import annotations

import numpy as np

from quad_fault_env.observation import ObservationLayout
from quadfault.errors import ConfigError
from quadfault.model.allocation import AllocationConfig, EstimateAwareAllocator
from quadfault.model.controller import ControllerConfig, GeometricController
from quadfault.model.trajectory import FlatOutput, Hover
from quadfault.model.vehicle import Vehicle

ACTION_MODES = ("motor", "residual", "wrench")


class GeometricPolicy:
    """The geometric controller (optionally estimate-aware) as an SB3-like policy.

    Args:
        vehicle: the nominal vehicle (the environment's).
        action_mode: the environment's action mode.
        estimate_aware: allocate with the observation's ``eta_hat``.
        layout: the environment's :class:`~quad_fault_env.observation.ObservationLayout`
            (default: the standard flat layout with ``ref_acc``).
        residual_scale: thrust per unit residual action [N].
        moment_scale: moment per unit wrench action (Mx, My, Mz) [N m].
        controller: geometric controller gains (feed-forward of acceleration on).
        allocation: allocation options (eta floor, priorities).
    """

    def __init__(
        self,
        vehicle: Vehicle | None = None,
        action_mode: str = "residual",
        *,
        estimate_aware: bool = False,
        layout=None,
        residual_scale: float = 1.0,
        moment_scale: tuple = (1.0, 1.0, 0.05),
        controller: ControllerConfig | None = None,
        allocation: AllocationConfig | None = None,
    ):
        if action_mode not in ACTION_MODES:
            raise ConfigError(f"action_mode must be one of {ACTION_MODES}, got {action_mode!r}")
        if estimate_aware and action_mode == "wrench":
            raise ConfigError(
                "an estimate-aware policy cannot act in 'wrench' mode (the "
                "environment allocates wrenches with the nominal inverse)"
            )
        if layout is None:
            layout = ObservationLayout(True)
        self.vehicle = vehicle or Vehicle()
        self.action_mode = action_mode
        self.estimate_aware = bool(estimate_aware)
        self.layout = layout
        self.residual_scale = float(residual_scale)
        self.moment_scale = np.asarray(moment_scale, dtype=float)
        base = controller or ControllerConfig()
        cfg = ControllerConfig(
            gains=base.gains,
            acceleration_feedforward=True,
            angular_feedforward=False,
            normalize_b2d=True,
        )
        self.controller = GeometricController(self.vehicle, Hover(), cfg)
        self.allocator = EstimateAwareAllocator(self.vehicle, allocation)
        self._has_ref_acc = any(s.name == "ref_acc" for s in layout.slots)
        self._zero = np.zeros(3)

    @classmethod
    def from_env(cls, env, estimate_aware: bool = False, **kwargs) -> GeometricPolicy:
        """A policy matching ``env`` (a QuadFault env, possibly wrapped) or a VecEnv of it."""
        if hasattr(env, "get_attr"):  # a VecEnv
            inner = env.get_attr("unwrapped", [0])[0]
        else:
            inner = env.unwrapped
        ac = inner.action_config
        return cls(
            inner.vehicle,
            ac.mode,
            estimate_aware=estimate_aware,
            layout=inner.layout,
            residual_scale=ac.residual_scale,
            moment_scale=ac.moment_scale,
            **kwargs,
        )

    @property
    def name(self) -> str:
        return "estimate-aware-policy" if self.estimate_aware else "geometric-policy"

    def _action(self, obs) -> np.ndarray:
        get = self.layout.get
        ex = np.asarray(get(obs, "pos_err"), float)
        ev = np.asarray(get(obs, "vel_err"), float)
        r6 = np.asarray(get(obs, "rot6"), float)
        b1, b2 = r6[:3], r6[3:]
        R = np.column_stack((b1, b2, np.cross(b1, b2)))
        w = np.asarray(get(obs, "omega"), float)
        acc = np.asarray(get(obs, "ref_acc"), float) if self._has_ref_acc else self._zero
        heading = np.array([b1[0], b1[1], 0.0])
        n = np.linalg.norm(heading)
        heading = heading / n if n > 1e-6 else np.array([1.0, 0.0, 0.0])
        ref = FlatOutput(self._zero, self._zero, acc, heading)
        out = self.controller.compute(0.0, ex, ev, R, w, ref)
        wrench = np.concatenate(([float(out.thrust)], out.moment))
        veh, f_max = self.vehicle, self.vehicle.rotor_max_thrust
        if self.action_mode == "wrench":
            a = np.concatenate(
                ([2.0 * wrench[0] / (veh.n_rotors * f_max) - 1.0], wrench[1:] / self.moment_scale)
            )
            return np.clip(a, -1.0, 1.0)
        if self.action_mode == "residual" and not self.estimate_aware:
            return np.zeros(veh.n_rotors)
        eta_hat = np.asarray(get(obs, "eta_hat"), float) if self.estimate_aware else None
        f = self.allocator.allocate(wrench, eta_hat).f
        if self.action_mode == "motor":
            return np.clip(2.0 * f / f_max - 1.0, -1.0, 1.0)
        f_nominal = np.clip(veh.rotor_thrust(wrench), 0.0, f_max)
        return np.clip((f - f_nominal) / self.residual_scale, -1.0, 1.0)

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        """``(action, state)`` like SB3's ``predict``; batched observations give batched
        actions (float32)."""
        if isinstance(observation, dict):
            first = next(iter(observation.values()))
            if np.ndim(first) == 2:
                rows = [{k: v[i] for k, v in observation.items()} for i in range(len(first))]
                return np.stack([self._action(r) for r in rows]).astype(np.float32), state
            return self._action(observation).astype(np.float32), state
        obs = np.asarray(observation)
        if obs.ndim == 2:
            return np.stack([self._action(o) for o in obs]).astype(np.float32), state
        if obs.ndim != 1 or obs.shape[0] != self.layout.size:
            raise ConfigError(
                f"observation must have {self.layout.size} elements (the "
                f"environment's layout), got shape {obs.shape}"
            )
        return self._action(obs).astype(np.float32), state
