"""Fly the paper's combined scenario and plot the true motor efficiencies and the tracking error.

python examples/simulate_and_plot.py --duration 20 --out flight.png
"""

from __future__ import annotations

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from quadfault.fileio import atomic_savefig  # noqa: E402
from quadfault.model.scenarios import named_scenario  # noqa: E402
from quadfault.sim.simulator import simulate  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="combined")
    p.add_argument("--duration", type=float, default=20.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="flight.png")
    p.add_argument("--force", action="store_true")
    args = p.parse_args(argv)

    scenario = named_scenario(args.scenario, args.duration)
    rec = simulate(scenario, seed=args.seed)
    err = np.linalg.norm(rec.position - scenario.trajectory(rec.t).position, axis=1)

    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(8, 5))
    for i in range(4):
        ax1.plot(rec.t, rec.eta_true[:, i], label=f"motor {i + 1}")
    ax1.set_ylabel("true efficiency eta")
    ax1.legend(ncol=4, fontsize=8)
    ax2.plot(rec.t, 100 * err)
    ax2.set_ylabel("position error [cm]")
    ax2.set_xlabel("t [s]")
    fig.suptitle(f"{scenario.name}: sigma_f = {scenario.thrust_noise}, seed {args.seed}")
    fig.tight_layout()
    atomic_savefig(fig, args.out, force=args.force, dpi=120)
    mask = rec.t > 2.0
    print(
        f"position error RMS after 2 s: {np.sqrt(np.mean(err[mask] ** 2)) * 100:.2f} cm; "
        f"wrote {args.out}"
    )
    return 0


if __name__ == "__main__":
    from quadfault.errors import QuadfaultError

    try:
        raise SystemExit(main())
    except QuadfaultError as exc:
        raise SystemExit(f"error: {exc}") from None
