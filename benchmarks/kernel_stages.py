"""Where the closed loop's time goes: each kernel timed alone, on one core.

Each stage of one closed-loop vehicle-step (``quadfault.model.closed_loop``) runs in its own
compiled loop over N vehicles x ``horizon`` steps (hover-like states, angular rates of a few
rad/s), on the calling thread; the result is CPU nanoseconds per vehicle-step (best of
``repeats`` timings). The last two rows are the loop itself (``fly_batch`` with the
controller in it), on one thread and on numba's threads (per CPU second).

    python benchmarks/kernel_stages.py                 # N = 4096, horizon 50
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

STAGES = (
    ("expm", "5 SO(3) exponentials (the ones of one RKMK4 step)"),
    ("rk4", "RKMK4 step (4 derivatives, 5 exponentials, 3 dexp^-1)"),
    ("motors", "motor model + allocation (saturation, efficiency)"),
    ("motors_noise", "motor model + allocation + thrust noise (4 draws, 4 exp)"),
    ("controller", "geometric controller + allocation inverse"),
    ("sensors", "sensors (position, velocity, attitude, gyro: 12 draws)"),
    ("serial", "fly_batch closed loop + controller, one thread"),
    ("parallel", "fly_batch closed loop + controller, numba threads (per CPU second)"),
)


def _loops():
    """The stage loops (compiled here, not cached: they time the kernels as they are)."""
    from numba import njit

    from quadfault.model.closed_loop import _tuples
    from quadfault.model.controller import (
        controller_tuples,
        geometric_control,
        reference_row,
        rotor_commands,
    )
    from quadfault.model.dynamics import rkmk4_step, rotor_wrench
    from quadfault.model.motors import motor_thrust
    from quadfault.model.rotation import expm3, mat3, vec3
    from quadfault.model.sensors import measure3

    jit = njit(cache=False, error_model="numpy")

    @jit
    def expm(w, k, dt):
        acc = 0.0
        for i in range(w.shape[0]):
            phi = (w[i, 0] * dt, w[i, 1] * dt, w[i, 2] * dt)
            for _ in range(k):
                for s in range(5):
                    E = expm3(phi)
                    acc += E[1]
                    phi = (phi[0] + 1e-9 * E[2], phi[1], phi[2] + 1e-9 * s)
        return acc

    @jit
    def rk4(p, v, R, w, T, M, k, C, V, dt):
        acc = 0.0
        for i in range(p.shape[0]):
            rigid = _tuples(C, V, i)[0]
            pi, vi, wi, Ri, Mi = vec3(p[i]), vec3(v[i]), vec3(w[i]), mat3(R[i]), vec3(M[i])
            for _ in range(k):
                pi, vi, Ri, wi, _ = rkmk4_step(pi, vi, Ri, wi, T[i], Mi, rigid, dt)
            acc += pi[2] + Ri[0] + wi[0]
        return acc

    @jit
    def motors(f_cmd, eta, sigma, gen, k, C, V, f):
        acc = 0.0
        for i in range(f_cmd.shape[0]):
            fi, ei, out = f_cmd[i], eta[i], f[i]
            for j in range(k):
                motor_thrust(fi, ei, j, V.f_max[i], True, sigma, gen, out)
                T, M = rotor_wrench(C.allocation, out)
                acc += T + M[0]
        return acc

    @jit
    def controller(p, v, R, w, refs, K, out, k):
        gains, nominal = controller_tuples(K)
        acc = 0.0
        for i in range(p.shape[0]):
            pi, vi, wi, Ri = vec3(p[i]), vec3(v[i]), vec3(w[i]), mat3(R[i])
            oi = out[i]
            for _ in range(k):
                u = geometric_control(pi, vi, Ri, wi, reference_row(refs, i), gains, nominal)
                rotor_commands(u[0], u[1], K.allocation_inverse, oi)
                acc += oi[0]
                pi = (pi[0] + 1e-9 * oi[1], pi[1], pi[2])
        return acc

    @jit
    def sensors(p, v, R, w, C, V, gen, k):
        acc = 0.0
        for i in range(p.shape[0]):
            noise = _tuples(C, V, i)[1]
            pi, vi, wi, Ri = vec3(p[i]), vec3(v[i]), vec3(w[i]), mat3(R[i])
            for _ in range(k):
                mp, _, mR, _ = measure3(pi, vi, Ri, wi, noise, gen)
                acc += mp[0] + mR[1]
        return acc

    return expm, rk4, motors, controller, sensors


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

    from quadfault.model import closed_loop
    from quadfault.model.controller import GeometricController
    from quadfault.model.motors import MotorModel
    from quadfault.model.plant import Plant
    from quadfault.model.sensors import SensorNoise
    from quadfault.model.trajectory import Hover
    from quadfault.model.vehicle import Vehicle

    rng = np.random.default_rng(0)
    veh = Vehicle()
    dt = 1e-3
    plant = Plant(veh, MotorModel(0.07), dt=dt, n_vehicles=N)
    V = plant.vehicles
    V.p[:, 2] = -1.0
    V.v[:] = 0.1 * rng.standard_normal((N, 3))
    V.w[:] = rng.standard_normal((N, 3))
    V.f_cmd[:] = veh.weight / 4 + 0.01 * rng.standard_normal((N, 4))
    T = np.full(N, veh.weight)
    M = 1e-4 * rng.standard_normal((N, 3))
    eta = np.ones((N, horizon, 4))
    refs = np.zeros((N, horizon, 6, 3))
    refs[:, :, 0, 2], refs[:, :, 3, 0] = -1.0, 1.0
    K = GeometricController(veh, Hover(position=(0.0, 0.0, -1.0))).constants
    C = closed_loop.constants(plant, SensorNoise(0.01, 0.01, 0.001, 0.01), 1)
    gen = np.random.default_rng(1)
    out = np.empty((N, 4))
    expm, rk4, motors, controller, sensors = _loops()
    calls = {
        "expm": lambda: expm(V.w, horizon, dt / 2),
        "rk4": lambda: rk4(V.p, V.v, V.R, V.w, T, M, horizon, C, V, dt),
        "motors": lambda: motors(V.f_cmd, eta, 0.0, gen, horizon, C, V, out),
        "motors_noise": lambda: motors(V.f_cmd, eta, 0.07, gen, horizon, C, V, out),
        "controller": lambda: controller(V.p, V.v, V.R, V.w, refs[:, 0], K, out, horizon),
        "sensors": lambda: sensors(V.p, V.v, V.R, V.w, C, V, gen, horizon),
    }
    gens = closed_loop.generators([np.random.default_rng(i) for i in range(N)])
    tables = closed_loop.Tables(np.zeros(N, np.int64), eta, refs)
    none = closed_loop.Records.none(N, 4)
    active, k0 = np.ones(N, dtype=bool), np.zeros(N, dtype=np.int64)
    closed_loop.fly_batch(gens, active[:1], k0[:1], 1, True, C, V, tables, none, K)  # compile

    def batch(threads):
        def fn():
            before = numba.get_num_threads()
            numba.set_num_threads(threads)
            try:
                closed_loop.fly_batch(gens, active, k0, horizon, True, C, V, tables, none, K)
            finally:
                numba.set_num_threads(before)

        return fn

    calls["serial"] = batch(1)
    calls["parallel"] = batch(numba.get_num_threads())
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
    args = ap.parse_args(argv)
    if args.n < 1 or args.horizon < 1:
        print("kernel_stages: --n and --horizon must be >= 1", file=sys.stderr)
        return 2
    os.environ.setdefault("OMP_WAIT_POLICY", "passive")
    ns = stage_ns(args.n, args.horizon, args.repeats)
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(
        f"# CPU ns per vehicle-step at N = {args.n}, horizon {args.horizon} (best of "
        f"{args.repeats}); {ns['threads']} numba threads; load average {load} on "
        f"{os.cpu_count()} cpus"
    )
    print("| stage | CPU ns per vehicle-step |\n|---|---|")
    for key, label in STAGES:
        print(f"| {label} | {ns[key]:.0f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
