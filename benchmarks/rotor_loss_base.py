"""Does the environment's base controller survive a partial rotor loss? Counts, with the zero
residual action, the ``QuadFaultRotorLoss-v0`` episodes that reach the end without
terminating, for each base allocation and estimator.

Per arm, the vector env (``QuadFaultVectorEnv``, which equals the single env reset with
seeds ``seed .. seed+N-1``) flies N seeded episodes of the registered task with
``scenario_options={"level": LOW, HIGH}`` (one rotor drops abruptly to an efficiency drawn
from that range between 3 and 6 s and stays there) and ``allocation`` = ``nominal`` (the
geometric controller's allocation inverse, today's default) or ``estimate-aware`` (gives up
yaw to keep thrust, roll and pitch, fed by the observation's estimate). Prints, per arm, the
survivors, each episode's level and the step of each termination.

    python benchmarks/rotor_loss_base.py                       # 10 episodes, level 0.1-0.5
    python benchmarks/rotor_loss_base.py --episodes 20 --seed 100 --arms estimate-aware:irls
"""

from __future__ import annotations

import argparse
import time

import numpy as np

ARMS = (
    "nominal:irls",
    "estimate-aware:irls",
    "estimate-aware:ekf",
    "estimate-aware:none",
    "estimate-aware:truth",
)


def survival(
    allocation: str, estimator: str, episodes: int = 10, seed: int = 0, level=(0.1, 0.5)
) -> dict:
    """Survivors of ``episodes`` seeded RotorLoss episodes with the zero residual action."""
    from quad_fault_env.tasks import registered_kwargs
    from quad_fault_env.vector import QuadFaultVectorEnv

    kw = registered_kwargs(
        "QuadFaultRotorLoss-v0", allocation=allocation, scenario_options={"level": tuple(level)}
    )
    kw.pop("estimator", None)
    vec = QuadFaultVectorEnv(episodes, estimator, **kw)
    vec.reset(seed=seed)
    levels = [min(f.level for f in sc.efficiency.faults) for sc in vec.scenarios]
    end = np.full(episodes, -1)
    reason = np.full(episodes, None, dtype=object)
    zero = np.zeros((episodes, 4))
    for k in range(int(vec.max_steps.max())):
        _, _, term, trunc, info = vec.step(zero)
        new = term & (end < 0)
        end[new], reason[new] = k + 1, info["termination_reason"][new]
        if (term | trunc | (end >= 0)).all():
            break
    vec.close()
    return {
        "survived": int((end < 0).sum()),
        "levels": levels,
        "end": end.tolist(),
        "reason": reason.tolist(),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0, help="episode i is seeded seed + i (0)")
    ap.add_argument("--level", type=float, nargs=2, default=[0.1, 0.5])
    ap.add_argument(
        "--arms",
        nargs="+",
        default=list(ARMS),
        help="allocation:estimator pairs (default: %(default)s)",
    )
    args = ap.parse_args(argv)
    print(
        f"QuadFaultRotorLoss-v0, level {args.level[0]:g}-{args.level[1]:g}, zero residual, "
        f"seeds {args.seed}..{args.seed + args.episodes - 1}\n"
    )
    print("| allocation | estimator | survived | crashed: level (end step, reason) | CPU s |")
    print("|---|---|---|---|---|")
    for arm in args.arms:
        allocation, estimator = arm.split(":")
        c0 = time.process_time()
        r = survival(allocation, estimator, args.episodes, args.seed, args.level)
        crashed = [
            f"{lv:.2f} ({e}, {why})"
            for lv, e, why in zip(r["levels"], r["end"], r["reason"])
            if e >= 0
        ]
        print(
            f"| {allocation} | {estimator} | {r['survived']}/{args.episodes} | "
            f"{', '.join(crashed) or '-'} | {time.process_time() - c0:.0f} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
