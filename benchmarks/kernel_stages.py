"""Where the compiled physics kernel's time goes: each stage timed alone, on one core.

Each stage of one closed-loop vehicle-step of ``quadfault._sim_numba.step_batch`` runs in its
own compiled loop over N vehicles x ``horizon`` steps (hover-like states, angular rates of a
few rad/s), on the calling thread; the result is CPU nanoseconds per vehicle-step (best of
``repeats`` timings). The stages call the kernels by the names they have had since the
batched kernel exists (``_expm``, ``_rk4``, ``_motor_wrench``, ``_controller``,
``plant_step``), so the same loops time an older checkout too::

    python benchmarks/kernel_stages.py                          # this checkout
    git clone /work/main /tmp/ref && git -C /tmp/ref checkout <commit>
    python benchmarks/kernel_stages.py --compare /tmp/ref        # both, side by side

With ``--compare`` the other checkout runs in a subprocess (``--repo`` puts it first on
``sys.path``), alternating with this one, and the table shows both and their ratio.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if "--repo" in sys.argv:  # before anything imports quadfault
    sys.path.insert(0, sys.argv[sys.argv.index("--repo") + 1])
else:
    sys.path.insert(0, str(ROOT))

import numpy as np

STAGES = (
    ("expm", "5 SO(3) exponentials (the ones of one RKMK4 step)"),
    ("rk4", "RKMK4 step (4 derivatives, 5 exponentials, 3 dexp^-1)"),
    ("motors", "motor model + allocation (saturation, efficiency)"),
    ("motors_noise", "motor model + allocation + thrust noise (4 exp)"),
    ("controller", "geometric controller + allocation inverse"),
    ("plant_step", "plant_step (motors with noise + RKMK4)"),
    ("serial", "step_batch closed loop, one thread (controller + plant_step)"),
    ("parallel", "step_batch closed loop, numba threads (per CPU second)"),
)


def _loops():
    """The stage loops, compiled against whichever ``quadfault`` is on ``sys.path``."""
    from numba import njit

    from quadfault import _numba_kernels as K

    jit = njit(cache=False, error_model="numpy")

    @jit
    def expm(w, k, dt):
        acc = 0.0
        for i in range(w.shape[0]):
            phi = (w[i, 0] * dt, w[i, 1] * dt, w[i, 2] * dt)
            for _ in range(k):
                for s in range(5):
                    E = K._expm(phi)
                    acc += E[1]
                    phi = (phi[0] + 1e-9 * E[2], phi[1], phi[2] + 1e-9 * s)
        return acc

    @jit
    def rk4(p, v, R, w, T, M, k, body, dt):
        acc = 0.0
        for i in range(p.shape[0]):
            pi, vi, wi = K._vec(p[i]), K._vec(v[i]), K._vec(w[i])
            Ri = K._mat(R[i])
            Mi = K._vec(M[i])
            for _ in range(k):
                pi, vi, Ri, wi = K._rk4(pi, vi, Ri, wi, T[i], Mi, body, dt)
            acc += pi[2] + Ri[0] + wi[0]
        return acc

    @jit
    def motors(f_cmd, eta, sigma, z, k, body):
        acc = 0.0
        for i in range(f_cmd.shape[0]):
            fi, ei, zi = f_cmd[i], eta[i], z[i]
            for j in range(k):
                T, M = K._motor_wrench(fi, ei, j, True, sigma, zi, 4 * j, body)
                acc += T + M[0]
        return acc

    @jit
    def controller(p, v, R, w, refs, gains, body, out, k):
        acc = 0.0
        for i in range(p.shape[0]):
            pi, vi, wi, Ri = K._vec(p[i]), K._vec(v[i]), K._vec(w[i]), K._mat(R[i])
            ri, oi = refs[i], out[i]
            for _ in range(k):
                K._controller(pi, vi, Ri, wi, ri, gains, body, oi)
                acc += oi[0]
                pi = (pi[0] + 1e-9 * oi[1], pi[1], pi[2])
        return acc

    @jit
    def plant(p, v, R, w, f_cmd, eta, sigma, z, k, body, dt):
        acc = 0.0
        for i in range(p.shape[0]):
            pi, vi, wi, Ri = K._vec(p[i]), K._vec(v[i]), K._vec(w[i]), K._mat(R[i])
            fi, ei, zi = f_cmd[i], eta[i], z[i]
            for j in range(k):
                pi, vi, Ri, wi, _, _ = K.plant_step(pi, vi, Ri, wi, fi, ei, j, True, sigma, zi,
                                                    4 * j, body, dt)
            acc += pi[2] + Ri[0]
        return acc

    return expm, rk4, motors, controller, plant


def _best(fn, work: int, repeats: int) -> float:
    """CPU ns per unit of work of ``fn()`` (best of ``repeats``)."""
    best = float("inf")
    for _ in range(repeats):
        c0 = time.process_time()
        fn()
        best = min(best, (time.process_time() - c0) * 1e9 / work)
    return best


def stage_ns(N: int = 4096, horizon: int = 50, repeats: int = 5) -> dict[str, float]:
    """CPU ns per vehicle-step of each stage of :data:`STAGES` at N vehicles."""
    import numba

    from quadfault import _sim_numba as S
    from quadfault.controller import GeometricController
    from quadfault.trajectory import Hover
    from quadfault.vehicle import Vehicle

    rng = np.random.default_rng(0)
    veh = Vehicle()
    body = S.body_of(veh)
    dt = 1e-3
    p = np.zeros((N, 3))
    p[:, 2] = -1.0
    v = 0.1 * rng.standard_normal((N, 3))
    R = np.ascontiguousarray(np.broadcast_to(np.eye(3), (N, 3, 3)))
    w = rng.standard_normal((N, 3))
    T = np.full(N, veh.weight)
    M = 1e-4 * rng.standard_normal((N, 3))
    f_cmd = np.full((N, 4), veh.weight / 4) + 0.01 * rng.standard_normal((N, 4))
    eta = np.ones((N, horizon, 4))
    z = rng.standard_normal((N, 4 * horizon))
    refs = np.zeros((N, 6, 3))
    refs[:, 0, 2], refs[:, 3, 0] = -1.0, 1.0
    gains = S.gains_of(GeometricController(veh, Hover(position=(0.0, 0.0, -1.0))))
    out = np.empty((N, 4))
    expm, rk4, motors, controller, plant = _loops()
    calls = {
        "expm": lambda: expm(w, horizon, dt / 2),
        "rk4": lambda: rk4(p, v, R, w, T, M, horizon, body, dt),
        "motors": lambda: motors(f_cmd, eta, 0.0, z, horizon, body),
        "motors_noise": lambda: motors(f_cmd, eta, 0.07, z, horizon, body),
        "controller": lambda: controller(p, v, R, w, refs, gains, body, out, horizon),
        "plant_step": lambda: plant(p, v, R, w, f_cmd, eta, 0.07, z, horizon, body, dt),
    }
    z_off = np.ascontiguousarray(np.broadcast_to(4 * np.arange(horizon), (N, horizon)))
    sigma = np.full(N, 0.07)

    def batch(kernel):
        s = (p.copy(), v.copy(), R.copy(), w.copy(), f_cmd.copy())
        return lambda: kernel(*s, eta, sigma, z, z_off, True, body, dt, 1, refs, gains, body)

    calls["serial"] = batch(S._step_batch_serial)
    calls["parallel"] = batch(S._step_batch_parallel)
    for fn in calls.values():
        fn()  # compile
    result = {name: _best(fn, N * horizon, repeats) for name, fn in calls.items()}
    result["threads"] = numba.get_num_threads()
    return result


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=4096, help="vehicles (4096)")
    ap.add_argument("--horizon", type=int, default=50, help="steps per timing (50)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--compare", default=None, help="another checkout, timed side by side")
    ap.add_argument("--rounds", type=int, default=2, help="alternations with --compare (2)")
    ap.add_argument("--repo", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.n < 1 or args.horizon < 1:
        print("kernel_stages: --n and --horizon must be >= 1", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(stage_ns(args.n, args.horizon, args.repeats)))
        return 0
    os.environ.setdefault("OMP_WAIT_POLICY", "passive")
    repos = [str(ROOT)] + ([args.compare] if args.compare else [])
    best: dict[str, dict[str, float]] = {r: {} for r in repos}
    for _ in range(args.rounds if args.compare else 1):
        for repo in repos:
            cmd = [sys.executable, __file__, "--json", "--repo", repo, "--n", str(args.n),
                   "--horizon", str(args.horizon), "--repeats", str(args.repeats)]
            got = json.loads(subprocess.run(cmd, check=True, capture_output=True,
                                            text=True).stdout.strip().splitlines()[-1])
            for k, x in got.items():
                best[repo][k] = min(best[repo].get(k, float("inf")), x)
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"# CPU ns per vehicle-step at N = {args.n}, horizon {args.horizon} (best of "
          f"{args.repeats} x {args.rounds if args.compare else 1} rounds); load average {load} "
          f"on {os.cpu_count()} cpus")
    if args.compare:
        print(f"| stage | {args.compare} | this checkout | speed-up |\n|---|---|---|---|")
    else:
        print("| stage | CPU ns per vehicle-step |\n|---|---|")
    for key, label in STAGES:
        now = best[str(ROOT)][key]
        if args.compare:
            old = best[args.compare][key]
            print(f"| {label} | {old:.0f} | {now:.0f} | {old / now:.2f}x |")
        else:
            print(f"| {label} | {now:.0f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
