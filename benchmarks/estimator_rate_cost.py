"""What ``estimator_rate="control"`` costs in accuracy and what it saves in CPU.

``estimator_rate="physics"`` (the default) lets the environment's estimator read every physics
substep (1 kHz); ``"control"`` only the first substep of each control step (100 Hz), one window
update per env step. This flies the same seeded episodes both ways with the zero-residual
estimate-aware base (the estimate drives the allocation, so a worse estimate shows in the
flight too) and reports, per estimator and rate:

* ``eta RMSE``: RMS of ``eta_hat - eta_true`` over every step and rotor of every episode;
* ``detect [ms]``: median time from the fault's onset until the faulty rotor's estimate first
  falls below the midpoint of 1 and the fault's level (``nan`` if it never does);
* ``track RMSE [m]``: RMS tracking error of the flights; ``crashes``;
* ``CPU/step [ms]``: process CPU per env step (the estimator's cost included).

    python benchmarks/estimator_rate_cost.py                  # 5 seeds, irls and ekf
    python benchmarks/estimator_rate_cost.py --seeds 0 1 --estimators irls
"""

from __future__ import annotations

import argparse
import sys
import time

import gymnasium as gym
import numpy as np

import quad_fault_env  # noqa: F401  (registers the ids)

ENV_ID = "QuadFaultRotorLoss-v0"
ENV_KWARGS = {"allocation": "estimate-aware", "scenario_options": {"level": [0.1, 0.5]}}


def fly(estimator: str, rate: str, seed: int) -> dict:
    """One zero-residual episode: the per-step estimate, truth and tracking error, CPU."""
    env = gym.make(ENV_ID, estimator=estimator, estimator_rate=rate, info="full", **ENV_KWARGS)
    zero = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
    env.reset(seed=seed)  # compile and warm up outside the timing
    for _ in range(3):
        env.step(zero)
    env.reset(seed=seed)
    faults = env.unwrapped.scenario.efficiency.faults
    t, hat, true, err = [], [], [], []
    c0, done, terminated = time.process_time(), False, False
    while not done:
        _, _, terminated, truncated, info = env.step(zero)
        t.append(info["t"])
        hat.append(info["eta_hat"])
        true.append(info["eta_true"])
        err.append(info["tracking_error"])
        done = terminated or truncated
    cpu = time.process_time() - c0
    env.close()
    t, hat, true = np.asarray(t), np.asarray(hat, float), np.asarray(true, float)
    detect = np.nan
    if faults:
        f = faults[0]
        threshold = 0.5 * (1.0 + f.level)
        after = (t >= f.onset) & (hat[:, f.motor - 1] < threshold)
        if after.any():
            detect = 1e3 * (t[np.argmax(after)] - f.onset)
    return {
        "sq": np.square(hat - true).ravel(),
        "detect": detect,
        "err": np.asarray(err),
        "crashed": bool(terminated),
        "cpu_step": cpu / len(t),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument(
        "--estimators", nargs="+", default=["irls", "ekf"], choices=("irls", "ekf", "rls", "ukf")
    )
    args = ap.parse_args(argv)
    print(f"{ENV_ID}, {ENV_KWARGS}, zero residual, seeds {args.seeds}")
    print(
        f"{'estimator':9} {'rate':8} {'eta RMSE':>9} {'detect [ms]':>12} "
        f"{'track RMSE [m]':>15} {'crashes':>8} {'CPU/step [ms]':>14}"
    )
    for est in args.estimators:
        rows = {}
        for rate in ("physics", "control"):
            runs = [fly(est, rate, s) for s in args.seeds]
            rows[rate] = r = {
                "eta": float(np.sqrt(np.mean(np.concatenate([x["sq"] for x in runs])))),
                "detect": float(np.nanmedian([x["detect"] for x in runs]))
                if any(np.isfinite(x["detect"]) for x in runs)
                else float("nan"),
                "track": float(np.sqrt(np.mean(np.concatenate([x["err"] for x in runs]) ** 2))),
                "crashes": sum(x["crashed"] for x in runs),
                "cpu": 1e3 * float(np.mean([x["cpu_step"] for x in runs])),
            }
            print(
                f"{est:9} {rate:8} {r['eta']:9.4f} {r['detect']:12.0f} {r['track']:15.4f} "
                f"{r['crashes']:>5}/{len(runs)} {r['cpu']:14.3f}",
                flush=True,
            )
        p, c = rows["physics"], rows["control"]
        print(
            f"{est:9} {'ratio':8} {c['eta'] / p['eta']:9.2f} "
            f"{c['detect'] / p['detect']:12.2f} {c['track'] / p['track']:15.2f} "
            f"{'':>8} {c['cpu'] / p['cpu']:14.2f}   (control / physics)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
