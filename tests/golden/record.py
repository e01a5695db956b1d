"""Record the golden outputs that ``tests/test_golden.py`` compares with.

Run from the repository root: ``python tests/golden/record.py`` (writes
``tests/golden/golden.npz``). The goldens pin the numbers users get through the public
paths -- ``quadfault simulate``, ``quadfault estimate``, ``gym.make`` rollouts, the agents'
closed-loop flights -- so a refactoring that is meant to change no result can prove it.
Re-record only when a change of results is intended, and say so in CHANGELOG.md.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROW_STRIDE = 7  # keep every 7th row of long series: small files, every code path still pinned

#: name -> ``quadfault simulate`` arguments
FLIGHTS = {
    "combined_clean": ["--scenario", "combined", "--duration", "12", "--seed", "0"],
    "combined_sensor_noise": [
        "--scenario",
        "combined",
        "--duration",
        "6",
        "--seed",
        "3",
        "--sensor-noise",
        "0.01,0.02,0.005,0.01,0.05",
    ],
    "hover_fault_100hz": [
        "--scenario",
        "hover_fault",
        "--duration",
        "5",
        "--seed",
        "1",
        "--control-rate",
        "100",
    ],
    "reference_mode": [
        "--scenario",
        "abrupt",
        "--duration",
        "5",
        "--seed",
        "2",
        "--integrator",
        "reference",
    ],
    "effects_drag_lag": [
        "--scenario",
        "lissajous",
        "--duration",
        "4",
        "--seed",
        "4",
        "--effect",
        "drag=0.3",
        "--effect",
        "motor_lag=0.04",
    ],
}
#: name -> (flight, ``quadfault estimate`` arguments)
ESTIMATES = {
    "irls": ("combined_clean", ["--estimator", "irls"]),
    "irls_improved": ("combined_clean", ["--estimator", "irls", "--improved"]),
    "ekf": ("combined_clean", ["--estimator", "ekf"]),
    "irls_noisy": ("combined_sensor_noise", ["--estimator", "irls"]),
}
#: name -> (env id, gym.make kwargs, steps)
ROLLOUTS = {
    "QuadFault-v0_irls": ("QuadFault-v0", {"estimator": "irls"}, 300),
    "QuadFault-v0_ekf": ("QuadFault-v0", {"estimator": "ekf"}, 300),
    "QuadFault-v0_none": ("QuadFault-v0", {"estimator": "none"}, 300),
    "QuadFaultHover-v0_irls": ("QuadFaultHover-v0", {"estimator": "irls"}, 300),
    "QuadFaultHover-v0_noise": (
        "QuadFaultHover-v0",
        {"estimator": "irls", "sensor_noise": "0.01,0.02,0.005,0.01,0.05"},
        200,
    ),
}
VECTOR = {"QuadFaultHover-v0_vec_irls": ("QuadFaultHover-v0", {"estimator": "irls"}, 4, 150)}
#: name -> (scenario, controller, estimator, duration)
AGENT_FLIGHTS = {
    "agent_estimate_aware_irls": ("abrupt", "estimate-aware", "irls", 8.0),
    "agent_geometric": ("combined", "geometric", "none", 6.0),
}


def _cli(args):
    from quadfault import cli

    code = cli.main(list(args) + ["--quiet"])
    if code not in (0, None):
        raise SystemExit(f"quadfault {' '.join(args)} exited {code}")


def _table(path: Path) -> dict[str, np.ndarray]:
    import csv

    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    head, body = rows[0], rows[1:]
    out = {}
    for j, name in enumerate(head):
        try:
            out[name] = np.array([float(r[j]) if r[j] != "" else np.nan for r in body])
        except ValueError:  # a text column (status)
            continue
    return out


def flights(tmp: Path) -> dict[str, np.ndarray]:
    out = {}
    for name, args in FLIGHTS.items():
        path = tmp / f"{name}.csv"
        _cli(["simulate", *args, "--out", str(path)])
        for col, values in _table(path).items():
            out[f"sim/{name}/{col}"] = values[::ROW_STRIDE]
    for name, (flight, args) in ESTIMATES.items():
        est = tmp / f"est_{name}.csv"
        _cli(["estimate", str(tmp / f"{flight}.csv"), *args, "--out", str(est)])
        for col, values in _table(est).items():
            out[f"est/{name}/{col}"] = values[::ROW_STRIDE]
    return out


def rollouts() -> dict[str, np.ndarray]:
    import gymnasium as gym

    import quad_fault_env  # noqa: F401  (registers the ids)

    out = {}
    from quadfault.sim.simulator import SensorNoise

    for name, (env_id, kwargs, steps) in ROLLOUTS.items():
        kwargs = dict(kwargs)
        if isinstance(kwargs.get("sensor_noise"), str):  # kept as text: the class may move
            kwargs["sensor_noise"] = SensorNoise(*map(float, kwargs["sensor_noise"].split(",")))
        env = gym.make(env_id, **kwargs)
        obs, _ = env.reset(seed=7)
        obs_l, rew_l, done_l = [obs], [], []
        zero = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
        for _ in range(steps):
            obs, r, term, trunc, _ = env.step(zero)
            obs_l.append(obs)
            rew_l.append(r)
            done_l.append(float(term) + 2 * float(trunc))
            if term or trunc:
                obs, _ = env.reset()
                obs_l.append(obs)
        env.close()
        out[f"env/{name}/obs"] = np.asarray(obs_l, dtype=float)
        out[f"env/{name}/reward"] = np.asarray(rew_l, dtype=float)
        out[f"env/{name}/done"] = np.asarray(done_l, dtype=float)
    for name, (env_id, kwargs, n, steps) in VECTOR.items():
        env = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **kwargs)
        obs, _ = env.reset(seed=11)
        obs_l, rew_l = [obs], []
        zero = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
        for _ in range(steps):
            obs, r, term, trunc, _ = env.step(zero)
            obs_l.append(obs)
            rew_l.append(r)
        env.close()
        out[f"vec/{name}/obs"] = np.asarray(obs_l, dtype=float)
        out[f"vec/{name}/reward"] = np.asarray(rew_l, dtype=float)
    return out


def agent_flights() -> dict[str, np.ndarray]:
    from agents.rollout import fly
    from quadfault.model.scenarios import named_scenario

    out = {}
    for name, (scen, controller, estimator, duration) in AGENT_FLIGHTS.items():
        flight = fly(named_scenario(scen, duration=duration), controller, estimator, seed=5)
        for field in ("t", "p", "f_cmd", "eta_hat"):
            out[f"agent/{name}/{field}"] = np.asarray(getattr(flight, field), dtype=float)
    return out


def record() -> dict[str, np.ndarray]:
    with tempfile.TemporaryDirectory() as tmp:
        out = flights(Path(tmp))
    out.update(rollouts())
    out.update(agent_flights())
    return out


if __name__ == "__main__":
    target = HERE / "golden.npz"
    if target.exists() and "--force" not in sys.argv:
        raise SystemExit(f"{target} exists; pass --force to re-record it")
    data = record()
    np.savez_compressed(target, **data)
    print(f"wrote {len(data)} arrays to {target} ({target.stat().st_size / 1e3:.0f} kB)")
