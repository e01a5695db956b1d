"""Does the environment's base controller survive a partial rotor loss? Counts, with the zero
residual action, the ``QuadFaultRotorLoss-v0`` episodes that reach the end without
terminating, for each base allocation and estimator.

Per arm, the vector env (``QuadFaultVectorEnv``, which equals the single env reset with
seeds ``seed .. seed+N-1``) flies N seeded episodes of the registered task with
``scenario_options={"level": LOW, HIGH}`` (one rotor drops abruptly to an efficiency drawn
from that range between 3 and 6 s and stays there) and ``allocation`` = ``nominal`` (the
geometric controller's allocation inverse, today's default) or ``estimate-aware`` (gives up
yaw to keep thrust, roll and pitch, fed by the observation's estimate) or ``relaxed-hover``
(the estimate-aware base until the estimate isolates a lost rotor, then the relaxed hover on
the other three). Prints, per arm, the survivors, the episodes that held the hover point
(within 1 m from 2 s after the loss to the end: the complete-loss task's success), each
crashed episode's level and the step of each termination.

``--env QuadFaultRotorLossComplete-v0`` flies the complete-loss task (the complete-loss
vehicle, its rate damping and rotor inertia) instead.

    python benchmarks/studies/rotor_loss_base.py                       # 10 episodes, level 0.1-0.5
    python benchmarks/studies/rotor_loss_base.py --episodes 20 --seed 100 --arms estimate-aware:irls
    python benchmarks/studies/rotor_loss_base.py --env QuadFaultRotorLossComplete-v0 --level 0 0 \
        --arms relaxed-hover:irls
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
    allocation: str,
    estimator: str,
    episodes: int = 10,
    seed: int = 0,
    level=(0.1, 0.5),
    env_id: str = "QuadFaultRotorLoss-v0",
) -> dict:
    """Survivors of ``episodes`` seeded RotorLoss episodes with the zero residual action."""
    from quad_fault_env.tasks import registered_kwargs
    from quad_fault_env.vector import QuadFaultVectorEnv

    kw = registered_kwargs(env_id, allocation=allocation, scenario_options={"level": tuple(level)})
    kw.pop("estimator", None)
    vec = QuadFaultVectorEnv(episodes, estimator, **kw)
    vec.reset(seed=seed)
    levels = [min(f.level for f in sc.efficiency.faults) for sc in vec.scenarios]
    end = np.full(episodes, -1)
    reason = np.full(episodes, None, dtype=object)
    zero = np.zeros((episodes, 4))
    onset = np.array([min(f.onset for f in sc.efficiency.faults) for sc in vec.scenarios])
    late_error = np.zeros(episodes)  # largest error from 2 s after the loss on
    for k in range(int(vec.max_steps.max())):
        _, _, term, trunc, info = vec.step(zero)
        t = vec.steps * vec.substeps * vec.dt
        err = np.linalg.norm(vec.state.p - vec._references_now()[0], axis=1)
        late = (t >= onset + 2.0) & (end < 0) & ~term
        late_error[late] = np.maximum(late_error[late], err[late])
        new = term & (end < 0)
        end[new], reason[new] = k + 1, info["termination_reason"][new]
        if (term | trunc | (end >= 0)).all():
            break
    vec.close()
    return {
        "survived": int((end < 0).sum()),
        "held": int(((end < 0) & (late_error <= 1.0)).sum()),
        "levels": levels,
        "end": end.tolist(),
        "reason": reason.tolist(),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0, help="episode i is seeded seed + i (0)")
    ap.add_argument("--level", type=float, nargs=2, default=[0.1, 0.5])
    ap.add_argument("--env", default="QuadFaultRotorLoss-v0", help="task id (%(default)s)")
    ap.add_argument(
        "--arms",
        nargs="+",
        default=list(ARMS),
        help="allocation:estimator pairs (default: %(default)s)",
    )
    args = ap.parse_args(argv)
    print(
        f"{args.env}, level {args.level[0]:g}-{args.level[1]:g}, zero residual, "
        f"seeds {args.seed}..{args.seed + args.episodes - 1}\n"
    )
    print(
        "| allocation | estimator | survived | held within 1 m | "
        "crashed: level (end step, reason) | CPU s |"
    )
    print("|---|---|---|---|---|---|")
    for arm in args.arms:
        allocation, estimator = arm.split(":")
        c0 = time.process_time()
        r = survival(allocation, estimator, args.episodes, args.seed, args.level, args.env)
        crashed = [
            f"{lv:.2f} ({e}, {why})"
            for lv, e, why in zip(r["levels"], r["end"], r["reason"])
            if e >= 0
        ]
        print(
            f"| {allocation} | {estimator} | {r['survived']}/{args.episodes} | "
            f"{r['held']}/{args.episodes} | "
            f"{', '.join(crashed) or '-'} | {time.process_time() - c0:.0f} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
