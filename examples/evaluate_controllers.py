"""Evaluate the bundled controllers: the plain geometric controller and the estimate-aware
fault-tolerant controller with eta_hat from IRLS, the EKF, the oracle and no estimator.

    python examples/evaluate_controllers.py --out results/controllers            # quick suite
    python examples/evaluate_controllers.py --suite paper --seeds 0 --out results/paper

Equivalent to ``quadfault evaluate`` with the default agents; writes ``results.md``,
``results.json`` and ``fault_<scenario>.png`` into ``--out`` and prints the table.
"""

from __future__ import annotations

import argparse
import sys

AGENTS = [
    "geometric",
    "estimate-aware:irls",
    "estimate-aware:ekf",
    "estimate-aware:truth",
    "estimate-aware:none",
]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="evaluate the bundled controllers")
    parser.add_argument("--out", default="results/controllers")
    parser.add_argument("--suite", default="quick")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--agents", nargs="+", default=AGENTS)
    parser.add_argument("--duration", type=float, help="override scenario durations [s]")
    parser.add_argument("--force", action="store_true")
    args = parser.parse_args(argv)

    from quadfault.cli import main as cli_main

    cli = [
        "evaluate",
        "--agents",
        *args.agents,
        "--suite",
        args.suite,
        "--seeds",
        *map(str, args.seeds),
        "--out",
        args.out,
    ]
    if args.duration is not None:
        cli += ["--duration", str(args.duration)]
    if args.force:
        cli.append("--force")
    return cli_main(cli)


if __name__ == "__main__":
    sys.exit(main())
