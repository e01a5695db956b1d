"""Fuzz benchmark: generated broken recordings through the reader and the CLI entry points.

    python benchmarks/fuzz_recordings.py [--cases 1000] [--seed 0] [--timeout 30]

Each case (``tests/support/fuzzing.py``: truncated files, missing or broken sidecars, wrong types,
NaN/inf, repeated or decreasing time, bad quaternions, absurd vehicles, ...) goes through
``read_recording`` and, in-process via ``quadfault.cli.main``, through
``quadfault estimate`` and ``quadfault diagnose``. Every run is classified:

* ``clean``: a one-line error naming the file and the column / key / row (exit 2 for the CLI,
  no output file written);
* ``unclean``: an error message that is multi-line or does not say where;
* ``traceback``: an exception other than ``QuadfaultError`` escaped;
* ``hang``: no answer within ``--timeout`` seconds;
* ``accepted``: a broken file was read or processed as if it were fine (silently wrong);
* ``output``: the CLI failed but left an output file behind.

Target: every run clean. Exit status 1 otherwise.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import io
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from quadfault.cli import main as cli_main
from quadfault.errors import QuadfaultError
from quadfault.io.recording import read_recording
from quadfault.progress import progress_bar

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from support.fuzzing import (  # noqa: E402  (the tests' case generators)
    MUTATION_NAMES,
    Hang,
    bad_case,
    error_is_clean,
    time_limit,
    write_case,
)


def check_reader(case, csv_path, side_path, timeout) -> tuple[str, str]:
    try:
        with time_limit(timeout):
            read_recording(csv_path)
    except Hang:
        return "hang", ""
    except QuadfaultError as exc:
        why = error_is_clean(str(exc), case, csv_path, side_path)
        return ("clean", "") if why is None else ("unclean", f"{why}: {exc}")
    except Exception as exc:  # noqa: BLE001 - that is what we are counting
        return "traceback", f"{type(exc).__name__}: {exc}"
    return "accepted", ""


def check_cli(argv, case, csv_path, side_path, outputs, timeout) -> tuple[str, str]:
    err, out = io.StringIO(), io.StringIO()
    try:
        with time_limit(timeout), contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            code = cli_main(argv)
    except Hang:
        return "hang", ""
    except SystemExit as exc:
        code = exc.code
    except Exception as exc:  # noqa: BLE001
        return "traceback", f"{type(exc).__name__}: {exc}"
    text = err.getvalue().strip()
    if code == 0:
        return "accepted", ""
    if any(Path(p).exists() for p in outputs):
        return "output", text
    prefix = f"quadfault {argv[0]}: error: "
    if not text.startswith(prefix):
        return "unclean", text
    why = error_is_clean(text[len(prefix) :], case, csv_path, side_path)
    return ("clean", "") if why is None and code == 2 else ("unclean", f"{why}: {text}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cases", type=int, default=1000, help="generated recordings (default 1000)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--timeout", type=float, default=30.0, help="per run [s]")
    p.add_argument("--quiet", action="store_true")
    args = p.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    tally = collections.Counter()
    per_mutation = collections.defaultdict(collections.Counter)
    examples = {}
    start = time.perf_counter()
    bar = progress_bar(
        total=args.cases, desc="fuzz", unit="file", disable=True if args.quiet else None
    )
    for k in range(args.cases):
        case = bad_case(rng, k % len(MUTATION_NAMES))
        with tempfile.TemporaryDirectory() as folder:
            csv_path, side_path = write_case(case, folder)
            est = Path(folder) / "est.csv"
            diag = Path(folder) / "diag.json"
            runs = {
                "read_recording": check_reader(case, csv_path, side_path, args.timeout),
                "estimate": check_cli(
                    ["estimate", str(csv_path), "--out", str(est), "--quiet"],
                    case,
                    csv_path,
                    side_path,
                    [est, est.with_suffix(".json")],
                    args.timeout,
                ),
                "diagnose": check_cli(
                    ["diagnose", str(csv_path), "--json", str(diag), "--quiet"],
                    case,
                    csv_path,
                    side_path,
                    [diag],
                    args.timeout,
                ),
            }
        for entry, (verdict, detail) in runs.items():
            tally[(entry, verdict)] += 1
            per_mutation[case.name][verdict] += 1
            if verdict != "clean":
                examples.setdefault((entry, case.name, verdict), detail)
        bar.update(1)
    bar.close()
    seconds = time.perf_counter() - start
    runs_total = sum(tally.values())
    clean = sum(v for (e, verdict), v in tally.items() if verdict == "clean")
    print(
        f"fuzz_recordings: {args.cases} broken recordings x 3 entry points = {runs_total} runs "
        f"in {seconds:.1f} s (seed {args.seed})"
    )
    for entry in ("read_recording", "estimate", "diagnose"):
        counts = {
            v: tally[(entry, v)]
            for v in ("clean", "unclean", "traceback", "hang", "accepted", "output")
        }
        print(f"  {entry:15s} " + "  ".join(f"{v} {n}" for v, n in counts.items()))
    print(
        f"  mutations: {len(per_mutation)} kinds, "
        + ", ".join(f"{m} {sum(c.values())}" for m, c in sorted(per_mutation.items()))
    )
    print(f"clean: {clean}/{runs_total}")
    for (entry, name, verdict), detail in sorted(examples.items())[:20]:
        print(f"  NOT CLEAN {entry} {name} {verdict}: {detail[:200]}")
    return 0 if clean == runs_total else 1


if __name__ == "__main__":
    sys.exit(main())
