"""Scale-out for sweeps: run independent tasks in local processes or on a Ray cluster.

:func:`run_sweep` is the whole backend layer: ``run_sweep(fn, tasks, backend=..., workers=N)``
returns ``[fn(t) for t in tasks]`` in task order, computed

* ``"serial"``: in this process (debugging, ``workers=1``);
* ``"local"`` (default): in ``workers`` local processes (``concurrent.futures``);
* ``"ray"``: as Ray tasks -- on the cluster named by ``RAY_ADDRESS`` / ``address=`` or on a
  local Ray instance started with ``num_cpus=workers``. Ray is optional (``pip install ray``)
  and imported only here, lazily; without it the backend raises a one-line ``ConfigError``.

``fn`` must be a module-level function (picklable) and each task deterministic in its own
arguments (seeds travel inside the task), so every backend gives the same results.

Sweeps on it: :func:`agents.evaluate.evaluate` (agents x scenarios x seeds;
``quadfault evaluate --backend ray --workers 8``) and the blinded diagnosis study
(``python benchmarks/blinded_study.py --backend ray``).
"""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor, as_completed

from quadfault.errors import ConfigError
from quadfault.progress import progress_bar

BACKENDS = ("serial", "local", "ray")


def _check_workers(workers) -> int:
    if workers is None:
        return os.cpu_count() or 1
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ConfigError(f"workers must be an integer >= 1, got {workers!r}")
    return workers


def _ray():
    try:
        import ray
    except ImportError:
        raise ConfigError("backend 'ray' needs Ray: pip install ray (the 'ray' extra)") from None
    return ray


def run_sweep(
    fn,
    tasks,
    *,
    backend: str = "local",
    workers: int | None = None,
    progress: bool = False,
    desc: str = "sweep",
    address: str | None = None,
) -> list:
    """``[fn(t) for t in tasks]`` in task order on ``backend`` (see the module docstring)."""
    if backend not in BACKENDS:
        raise ConfigError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    workers = _check_workers(workers)
    tasks = list(tasks)
    bar = progress_bar(total=len(tasks), desc=desc, unit="task", disable=None if progress else True)
    try:
        if backend == "serial" or not tasks:
            out = []
            for t in tasks:
                out.append(fn(t))
                bar.update(1)
            return out
        if backend == "local":
            out = [None] * len(tasks)
            with ProcessPoolExecutor(max_workers=min(workers, len(tasks))) as pool:
                futures = {pool.submit(fn, t): k for k, t in enumerate(tasks)}
                for fut in as_completed(futures):
                    out[futures[fut]] = fut.result()
                    bar.update(1)
            return out
        ray = _ray()
        if not ray.is_initialized():
            address = address or os.environ.get("RAY_ADDRESS")
            if address:
                ray.init(address=address)
            else:
                ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
        remote = ray.remote(fn)
        refs = [remote.remote(t) for t in tasks]
        pending = list(refs)
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            bar.update(len(done))
        return ray.get(refs)
    finally:
        bar.close()
