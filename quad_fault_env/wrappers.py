"""Small wrappers, one job each, that work on the env's measurement stream.

Every step of :class:`~quad_fault_env.envs.quad_fault.QuadFaultEnv` puts the measurements
of its physics substeps in ``info["samples"]`` (a list of :class:`estimators.base.Sample`,
one per substep, the command held over it), aligned with the first ``len(info["samples"])``
rows of ``info["eta_true_samples"]`` and ``info["specific_force_samples"]`` (one row per
substep of the step; NaN rows for substeps not flown) when made with ``info="full"``. The
env's own estimator reads every ``env.unwrapped.estimator_stride``-th sample; the wrappers
below read the same stream, so they need an env made with ``info="full"`` (a light one is a
``ConfigError``).

* :class:`EfficiencyEstimateObservation` -- fills the ``eta_hat`` / ``eta_sd`` slots from any
  online estimator object.
* :class:`EstimatorComparison` -- runs several estimators (IRLS and EKF by default) side by
  side and scores them against the truth in ``info``.
* :class:`RecordFlight` -- writes every episode as a ``quadfault-recording/1`` file.
"""

from __future__ import annotations

import math
from pathlib import Path

import gymnasium as gym
import numpy as np

from estimators.base import Estimate
from quad_fault_env.envs.config import require_full_info
from quad_fault_env.estimation import (
    TruthOracle,
    diagnostics_template,
    estimate_info,
    estimate_sd,
    make_estimator,
)
from quad_fault_env.observation import SD_MAX
from quadfault.errors import ConfigError
from quadfault.io.recording import Recording, write_recording
from quadfault.model.rotation import rot_to_quat


def _stream(info: dict, stride: int):
    return info.get("samples", [])[::stride]


def _flown(info: dict, key: str) -> np.ndarray:
    """The rows of a per-substep ``info`` array that belong to ``info["samples"]``."""
    return np.asarray(info[key])[: len(info.get("samples", []))]


def _prepare(estimator, env):
    """Bind the oracle to the episode's schedule, then reset."""
    if isinstance(estimator, TruthOracle):
        estimator.bind(env.unwrapped.scenario.efficiency)
    estimator.reset()


class EfficiencyEstimateObservation(gym.Wrapper):
    """Replace the ``eta_hat`` / ``eta_sd`` observation slots (and the estimator fields of
    ``info``) with the output of ``estimator`` fed on the env's measurement stream.

    Args:
        env: a QuadFaultEnv (possibly wrapped).
        estimator: an object with ``reset()`` and ``update(sample) -> Estimate``, or a name
            accepted by :func:`~quad_fault_env.estimation.make_estimator`.
        stride: use every ``stride``-th substep sample (default: the env's estimator stride).

    Before the first update the slots hold eta = 1 and sd = 10 (no information).
    """

    def __init__(self, env, estimator, stride: int | None = None):
        require_full_info(env, type(self).__name__)
        super().__init__(env)
        base = env.unwrapped
        self.estimator = make_estimator(estimator, base.vehicle)
        self.layout = base.layout
        self.stride = int(stride or base.estimator_stride)
        if self.stride < 1:
            raise ConfigError(f"stride must be >= 1, got {stride!r}")
        self.estimate = None
        self._template = diagnostics_template(self.estimator)

    def _fill(self, obs, info):
        n = self.env.unwrapped.vehicle.n_rotors
        est = self.estimate or Estimate(0.0, np.ones(n), None, "warmup")
        sd = estimate_sd(est, n)
        obs = self.layout.replace(obs, "eta_hat", est.eta)
        obs = self.layout.replace(obs, "eta_sd", SD_MAX if sd is None else sd)
        info = dict(info, **estimate_info(est, self.estimator, n, self._template))
        return obs, info

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        _prepare(self.estimator, self.env)
        self.estimate = None
        return self._fill(obs, info)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        for s in _stream(info, self.stride):
            self.estimate = self.estimator.update(s)
        obs, info = self._fill(obs, info)
        return obs, reward, terminated, truncated, info


class _EpisodeScore:
    """Per-sample estimates and truth of one estimator over one episode."""

    def __init__(self):
        self.t, self.eta, self.truth = [], [], []

    def add(self, t, eta, truth):
        self.t.append(float(t))
        self.eta.append(np.asarray(eta, dtype=float))
        self.truth.append(np.asarray(truth, dtype=float))

    def error(self) -> np.ndarray:
        return np.array(self.eta) - np.array(self.truth)

    def running_rmse(self, sq_sum: np.ndarray) -> np.ndarray:
        return np.sqrt(sq_sum / max(len(self.t), 1))


def _spike(t, err, faults, pad):
    """Max |error| of each motor over the other motors' fault windows, dilated by ``pad``
    [s] (seed-matlab-facts.md, section 6); None where a motor has no such window."""
    out = []
    for m in range(err.shape[1]):
        mask = np.zeros(len(t), dtype=bool)
        for f in faults:
            if f["motor"] != m + 1:
                mask |= (t >= f["onset"] - pad) & (t <= f["end"] + pad)
        out.append(float(np.max(np.abs(err[mask, m]))) if mask.any() else None)
    return out if any(x is not None for x in out) else None


def _latency(t, eta, truth, faults, fraction, n):
    """Seconds from each motor's first fault onset until eta_hat has covered ``fraction`` of
    the true drop; None for a motor without a fault, inf if never within the window."""
    out = [None] * n
    for f in sorted(faults, key=lambda f: f["onset"]):
        m = f["motor"] - 1
        if out[m] is not None or not (t.size and t[0] <= f["onset"] <= t[-1]):
            continue
        window = (t >= f["onset"]) & (t <= f["end"])
        before = t < f["onset"]
        pre = truth[before, m][-1] if before.any() else 1.0
        drop = pre - np.min(truth[window, m]) if window.any() else 0.0
        if drop < 0.02:  # too small a change to score
            continue
        hit = np.nonzero(window & (eta[:, m] <= pre - fraction * drop))[0]
        out[m] = float(t[hit[0]] - f["onset"]) if hit.size else math.inf
    return out


class EstimatorComparison(gym.Wrapper):
    """Run several online estimators side by side on the env's measurement stream.

    Each step adds ``info["comparison"][name] = {"eta", "sd", "status", "rmse"}`` (the running
    per-motor RMSE of the episode so far, truth taken at each sample's time).
    :meth:`summary` scores every finished episode and the current one, per estimator:

    * ``rmse`` [4]: sqrt(mean(e^2)) over the episode's updates, e = eta_hat - eta_true;
    * ``spike`` [4] or None: max |e_m| during the *other* motors' fault windows dilated by
      ``spike_pad`` (the reference code's definition); None without fault windows;
    * ``latency`` [4]: seconds from a motor's first fault onset until eta_hat has covered
      ``detection_fraction`` of the true drop; None without a fault on that motor, inf when
      not detected before the fault ended;
    * ``n_updates``.

    Args:
        env: a QuadFaultEnv (possibly wrapped).
        estimators: ``{name: estimator object or factory name}``; default IRLS and EKF.
        stride: substep stride of the stream (default: the env's).
    """

    def __init__(
        self,
        env,
        estimators: dict | None = None,
        stride: int | None = None,
        detection_fraction: float = 0.5,
        spike_pad: float = 0.03,
    ):
        require_full_info(env, type(self).__name__)
        super().__init__(env)
        base = env.unwrapped
        spec = estimators if estimators is not None else {"irls": "irls", "ekf": "ekf"}
        if not spec:
            raise ConfigError("EstimatorComparison needs at least one estimator")
        self.estimators = {name: make_estimator(e, base.vehicle) for name, e in spec.items()}
        self.stride = int(stride or base.estimator_stride)
        if not (0 < detection_fraction <= 1):
            raise ConfigError(f"detection_fraction must be in (0, 1], got {detection_fraction!r}")
        self.detection_fraction = float(detection_fraction)
        self.spike_pad = float(spike_pad)
        self.episodes: list[dict] = []
        self._scores = None
        self._faults = []

    def reset(self, **kwargs):
        self._finish()
        obs, info = self.env.reset(**kwargs)
        for est in self.estimators.values():
            _prepare(est, self.env)
        self._scores = {name: _EpisodeScore() for name in self.estimators}
        self._sq = {name: np.zeros(self.env.unwrapped.vehicle.n_rotors) for name in self._scores}
        self._faults = list(info.get("faults", []))
        return obs, info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        stream = _stream(info, self.stride)
        truth = _flown(info, "eta_true_samples")[:: self.stride]
        report = {}
        for name, est in self.estimators.items():
            estimate = None
            for s, eta_true in zip(stream, truth):
                estimate = est.update(s)
                self._scores[name].add(s.t, estimate.eta, eta_true)
                self._sq[name] += (np.asarray(estimate.eta, dtype=float) - eta_true) ** 2
            if estimate is not None:
                report[name] = {
                    "eta": np.asarray(estimate.eta, dtype=float),
                    "sd": estimate.sd,
                    "status": estimate.status,
                    "rmse": self._scores[name].running_rmse(self._sq[name]),
                }
        info = dict(info, comparison=report)
        return obs, reward, terminated, truncated, info

    def _score(self) -> dict | None:
        if self._scores is None:
            return None
        out = {}
        n = self.env.unwrapped.vehicle.n_rotors
        for name, sc in self._scores.items():
            if not sc.t:
                out[name] = {
                    "rmse": [math.nan] * n,
                    "spike": None,
                    "latency": [None] * n,
                    "n_updates": 0,
                }
                continue
            t, eta, truth = np.array(sc.t), np.array(sc.eta), np.array(sc.truth)
            err = eta - truth
            out[name] = {
                "rmse": np.sqrt(np.mean(err**2, axis=0)).tolist(),
                "spike": _spike(t, err, self._faults, self.spike_pad),
                "latency": _latency(t, eta, truth, self._faults, self.detection_fraction, n),
                "n_updates": len(t),
            }
        return out

    def _finish(self):
        score = self._score()
        if score is not None and any(v["n_updates"] for v in score.values()):
            self.episodes.append(score)
        self._scores = None

    def summary(self) -> dict:
        """``{"estimators": [names], "episodes": [score, ...], "current": score or None}``
        where a score is ``{name: {"rmse", "spike", "latency", "n_updates"}}``."""
        return {
            "estimators": list(self.estimators),
            "episodes": list(self.episodes),
            "current": self._score(),
        }


class RecordFlight(gym.Wrapper):
    """Write each episode as a recording (docs/formats.md): ``<path>_000.csv`` (+ JSON
    sidecar), ``<path>_001.csv``, ... at the physics rate, in ``frame``.

    Rows are the substep measurements of ``info["samples"]`` (state at ``t``, command held
    from ``t``), the accelerometer ``ax..az`` and the true efficiency ``eta1..eta4`` (truth for
    scoring, never read by estimators). An episode is written when it terminates or is
    truncated, or at the next ``reset()`` / ``close()`` if it was cut short. Existing files are
    never overwritten: the constructor refuses a ``path`` whose episode files exist.
    """

    def __init__(self, env, path, frame: str = "NED"):
        require_full_info(env, type(self).__name__)
        super().__init__(env)
        p = Path(path)
        self.stem = p.with_suffix("") if p.suffix == ".csv" else p
        if not self.stem.parent.is_dir():
            raise ConfigError(f"{self.stem.parent}: folder does not exist")
        taken = sorted(self.stem.parent.glob(f"{self.stem.name}_[0-9][0-9][0-9].*"))
        if taken:
            raise ConfigError(
                f"{taken[0]}: already exists; RecordFlight never overwrites, choose another path"
            )
        if frame not in ("NED", "ENU"):
            raise ConfigError(f"frame must be 'NED' or 'ENU', got {frame!r}")
        self.frame = frame
        self.paths: list[Path] = []
        self._rows = None

    def reset(self, **kwargs):
        self._write()
        obs, info = self.env.reset(**kwargs)
        self._rows = {"samples": [], "eta": [], "acc": []}
        return obs, info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self._rows is not None:
            self._rows["samples"] += info["samples"]
            self._rows["eta"].append(_flown(info, "eta_true_samples"))
            self._rows["acc"].append(_flown(info, "specific_force_samples"))
            if terminated or truncated:
                self._write()
        return obs, reward, terminated, truncated, info

    def close(self):
        self._write()
        super().close()

    def _write(self):
        rows, self._rows = self._rows, None
        if rows is None or len(rows["samples"]) < 2:
            return
        base = self.env.unwrapped
        s = rows["samples"]
        t = np.array([x.t for x in s])
        R = np.array([x.R for x in s])
        sc = base.scenario
        meta = {
            "scenario": sc.name,
            "seed": getattr(base, "np_random_seed", None),
            "dt": base.dt,
            "control_period": base.control_period,
            "thrust_noise": sc.thrust_noise,
            "fault_windows": [
                [m, a, b if math.isfinite(b) else None] for m, a, b in sc.fault_windows()
            ],
        }
        rec = Recording(
            t=t,
            omega=np.array([x.w for x in s]),
            thrust_cmd=np.array([x.f for x in s]),
            vehicle=base.vehicle,
            position=np.array([x.p for x in s]),
            velocity=np.array([x.v for x in s]),
            quaternion=rot_to_quat(R),
            accel=np.concatenate(rows["acc"]),
            vbat=None if sc.voltage is None else sc.voltage(t),
            eta_true=np.concatenate(rows["eta"]),
            frame="NED",
            source="quad_fault_env RecordFlight",
            meta=meta,
        )
        path = Path(f"{self.stem}_{len(self.paths):03d}.csv")
        write_recording(rec, path, frame=self.frame)
        self.paths.append(path)
