"""Blinded study of the model-mismatch diagnosis.

Each recording hides an effect drawn at random -- none, one of the effects of
``quadfault.model.effects.EFFECT_NAMES``, or a pair of effects from different classes -- on a
randomised vehicle (mass 0.03-3 kg with inertia, arm and yaw coefficient scaled consistently),
a randomised trajectory (circle or Lissajous; low altitude for ground effect), random sensor
and thrust noise, written in NED or ENU with ``f`` or ``u`` commands and read back. The
diagnosis sees only the recording file (truth stripped) and its nominal vehicle.

Magnitude: a 5 s pilot flight with the effect at unit magnitude measures its signal against
the residual noise (RMS in the diagnosis' normalised block channels); the effect is then scaled
to a random signal-to-noise ratio of 3-10 (clipped to physical bounds; the achieved SNR is
reported). Classes (``quadfault.diagnosis.library.EQUIVALENT``): ``thrust_scale``,
``motor_efficiency``, ``thrust_curve`` and ``mass`` count as one ("thrust"), ``delay`` and
``motor_lag`` as one ("timing"). The held-out seed (default 2026) was never used for tuning.

    python benchmarks/blinded_study.py --n 200 --seed 2026 --workers 2
    python benchmarks/blinded_study.py --n 200 --backend ray     # on a Ray cluster

Flights use 250 Hz physics and recording rate and 15 s by default (``--rate``,
``--duration``), in parallel over ``--workers`` processes.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import tempfile
import time
from collections import Counter
from multiprocessing import Pool

import numpy as np

import quadfault.diagnosis.locate  # imported before forking the workers (and not timed)
import quadfault.diagnosis.prediction  # noqa: F401
from quadfault.diagnosis import Diagnosis
from quadfault.diagnosis.identifiability import TIMING_SAMPLES
from quadfault.diagnosis.library import EQUIVALENT, build_library, predict
from quadfault.diagnosis.residuals import noise_scale, prepare
from quadfault.fileio import atomic_write_text
from quadfault.io.recording import read_recording, write_recording
from quadfault.model import effects as fx
from quadfault.model.effects.model import frame_vectors
from quadfault.model.effects.registry import identifiability
from quadfault.model.scenarios import LinearVoltage, named_scenario
from quadfault.model.trajectory import Circle, Lissajous
from quadfault.model.vehicle import PAPER_YAW_SIGNS, Vehicle
from quadfault.sim.simulator import SensorNoise, SimConfig, simulate

#: the effects hidden, in the order the study's seeds draw them from (every registered effect)
NAMES = (
    "motor_efficiency",
    "thrust_scale",
    "drag",
    "motor_lag",
    "delay",
    "wind",
    "ground_effect",
    "com_offset",
    "inertia",
    "blade_flapping",
    "rotor_inertia",
    "battery_thrust",
    "thrust_curve",
    "mass",
    "rate_damping",
)
assert sorted(NAMES) == sorted(fx.EFFECT_NAMES), "a new effect: add it to the study's NAMES"


def cls(name):
    return EQUIVALENT.get(name, name)


def random_vehicle(rng):
    m = float(math.exp(rng.uniform(math.log(0.03), math.log(3.0))))
    d = 0.2 * m ** (1 / 3) * rng.uniform(0.85, 1.15)
    dy = d * rng.uniform(0.8, 1.2)
    jxx = m * d * d * rng.uniform(0.25, 0.4)
    jyy = m * dy * dy * rng.uniform(0.25, 0.4)
    jzz = (jxx + jyy) * rng.uniform(0.8, 1.0)
    pos = [(d, dy), (d, -dy), (-d, -dy), (-d, dy)]
    return Vehicle.from_rotors(
        pos,
        PAPER_YAW_SIGNS,
        d * rng.uniform(0.03, 0.06),
        mass=m,
        inertia=(jxx, jyy, jzz),
        gravity=9.81,
        thrust_to_weight=float(rng.uniform(2.0, 2.6)),
        name=f"random {m:.3f} kg",
    )


def random_trajectory(rng, scale, low=None):
    alt = float(rng.uniform(1.0, 2.0)) if low is None else low
    if low is not None:  # ground effect needs the height to vary (else it is a thrust scale)
        return Lissajous(
            amplitude=(
                float(rng.uniform(0.5, 1.5) * scale),
                float(rng.uniform(0.5, 1.5) * scale),
                float(rng.uniform(0.3, 0.5) * low),
            ),
            frequency=float(rng.uniform(0.12, 0.22)),
            altitude=alt,
            yaw_rate=float(rng.uniform(-0.2, 0.2)),
        )
    if rng.random() < 0.5:
        return Circle(
            radius=float(rng.uniform(0.8, 2.0) * scale),
            frequency=float(rng.uniform(0.12, 0.25)),
            altitude=alt,
            yaw_frequency=float(rng.uniform(0.0, 0.05)),
        )
    amp = (
        float(rng.uniform(0.8, 2.0) * scale),
        float(rng.uniform(0.5, 1.5) * scale),
        float(rng.uniform(0.05, 0.3) * (scale if low is None else 0.3 * low)),
    )
    return Lissajous(
        amplitude=amp,
        frequency=float(rng.uniform(0.12, 0.22)),
        altitude=alt,
        yaw_rate=float(rng.uniform(-0.2, 0.2)),
    )


def make_effect(name, delta, veh, rng_params, nominal_curve=None, duration=15.0):
    """Effect ``name`` at magnitude ``delta`` (relative units, 1 = the pilot's unit).

    ``nominal_curve``: the recording's command-to-thrust curve for ``u`` commands (a concealed
    ``thrust_curve`` is a quadratic in those commands), None for thrust commands;
    ``duration``: the flight's (a battery discharges over it)."""
    m, d = veh.mass, float(np.max(np.abs(veh.allocation[2])))
    c_yaw = float(np.mean(np.abs(veh.allocation[3])))
    J = np.diag(veh.inertia)
    p = rng_params
    if name == "motor_efficiency":
        eta = [1.0] * 4
        eta[p["motor"]] = max(0.3, 1.0 - 0.1 * delta)
        return fx.MotorEfficiency(tuple(eta))
    if name == "thrust_scale":
        return fx.ThrustScale(float(np.clip(1.0 + p["sign"] * 0.05 * delta, 0.6, 1.4)))
    if name == "drag":
        k = min(0.3 * delta, 2.5) * m
        return fx.Drag((k, k * p["ky"], k * p["kz"]))
    if name == "motor_lag":
        return fx.MotorLag(float(np.clip(0.02 * delta, 0.003, 0.25)))
    if name == "delay":
        return fx.Delay(float(np.clip(0.015 * delta, 0.002, 0.15)))
    if name == "wind":
        v = min(2.0 * delta, 12.0)
        return fx.Wind(
            (v * math.cos(p["dir"]), v * math.sin(p["dir"]), 0.0),
            gust=0.1 * v,
            gust_tau=3.0,
            k=(0.3 * m,) * 3,
            seed=p["seed"],
        )
    if name == "ground_effect":
        return fx.GroundEffect(float(np.clip(0.6 * d * math.sqrt(delta), 0.05 * d, 1.2 * d)))
    if name == "com_offset":
        r = min(0.05 * d * delta, 0.35 * d)
        return fx.ComOffset((r * math.cos(p["dir"]), r * math.sin(p["dir"])))
    if name == "inertia":
        s = float(np.clip(1.0 + p["sign"] * 0.25 * delta, 0.55, 1.9))
        return fx.Inertia((s, s, 1.0 + (s - 1.0) * p["kz"]))
    if name == "blade_flapping":
        kf = min(0.02 * delta, 0.25)
        return fx.BladeFlapping(kf, p["ratio"] * d * kf)
    if name == "rotor_inertia":
        return fx.RotorInertia(min(0.03 * c_yaw * delta, 1.2 * c_yaw))
    if name == "battery_thrust":
        cells = 1 if m < 0.1 else (3 if m < 1.5 else 4)
        v0 = 4.2 * cells
        return fx.BatteryThrust(float(np.clip(0.4 * delta, 0.2, 3.5)), v0, v0 * p["drop"], duration)
    if name == "thrust_curve":
        nominal = nominal_curve or fx.thrust_curve.IDENTITY_CURVE
        changes = np.clip(
            np.array([p["s0"] * 0.02, p["sign"] * 0.05, p["s2"] * 0.05]) * delta, -0.45, 0.45
        )  # inside the plausible bounds (+-0.5)
        return fx.ThrustCurve(
            tuple(fx.curve_from_changes(nominal, veh.hover_thrust, changes)), nominal
        )
    if name == "mass":
        return fx.Mass(float(np.clip(1.0 + p["sign"] * 0.04 * delta, 0.7, 1.5)))
    if name == "rate_damping":
        lin = np.minimum(J * 0.5 * delta * np.array([1.0, p["ky"], p["kz"]]), J / 0.03)
        quad = np.minimum(p["quad"] * lin / 2.0, 0.5 * J)  # well inside the plausible [0, J]
        return fx.RateDamping(tuple(lin), tuple(quad))
    raise KeyError(name)


def truth_x(effect, lib):
    """The library parameter vector equivalent to a true effect (for SNR only)."""
    return lib[effect.name].x_from_params(effect.params())


def snr(rec, effects, veh):
    """Signal-to-noise ratio of each true effect in the diagnosis' normalised channels."""
    rp = prepare(rec.without_truth(), veh)
    lib = {c.name: c for c in build_library(rp, NAMES)}
    terms = [(lib[e.name], truth_x(e, lib)) for e in effects]
    base = predict(rp, [])
    scale = noise_scale(rp, rp.measured - predict(rp, terms))
    out = []
    for t in terms:
        sig = (predict(rp, [t]) - base) / scale
        out.append(float(np.sqrt(np.mean(np.sum(sig**2, axis=1)) / 1.0)))
    noise = float(
        np.sqrt(np.mean(np.sum(((rp.measured - predict(rp, terms)) / scale) ** 2, axis=1)))
    )
    return [s / max(noise, 1e-12) for s in out]


def fly(veh, traj, effects, noise, thrust_noise, rate, duration, seed, vbat=None):
    """``vbat``: ``(v_start, v_end)`` [V] of a recorded battery voltage (a ``battery_thrust``
    effect records its own), or None."""
    dt = 1.0 / rate
    battery = [e for e in effects if isinstance(e, fx.BatteryThrust)]
    voltage = None
    if battery:
        voltage = LinearVoltage(battery[0].v_start, battery[0].v_end, battery[0].duration)
    elif vbat is not None:
        voltage = LinearVoltage(vbat[0], vbat[1], duration)
    sc = named_scenario("nominal", duration, dt).replace(trajectory=traj, voltage=voltage)
    cfg = SimConfig(dt=dt, sensor_noise=noise)
    return simulate(
        sc, vehicle=veh, config=cfg, seed=seed, effects=tuple(effects), thrust_noise=thrust_noise
    )


def draw_case(seed, i):
    rng = np.random.default_rng([seed, i])
    u = rng.random()
    if u < 0.2:
        names = []
    elif u < 0.8:
        names = [str(rng.choice(NAMES))]
    else:
        while True:
            pair = [str(x) for x in rng.choice(NAMES, 2, replace=False)]
            if cls(pair[0]) != cls(pair[1]):
                break
        names = pair
    veh = random_vehicle(rng)
    d = float(np.max(np.abs(veh.allocation[2])))
    scale = float(np.clip(veh.mass ** (1 / 3), 0.4, 1.4))
    low = float(rng.uniform(1.2, 2.5) * d) + 0.05 if "ground_effect" in names else None
    traj = random_trajectory(rng, scale, low)
    noise = SensorNoise(
        float(rng.uniform(0.001, 0.005)),
        float(rng.uniform(0.002, 0.008)),
        float(rng.uniform(0.0005, 0.002)),
        float(rng.uniform(0.0005, 0.003)),
    )
    params = {
        n: {
            "motor": int(rng.integers(4)),
            "sign": float(rng.choice([-1.0, 1.0])),
            "ky": float(rng.uniform(0.8, 1.2)),
            "kz": float(rng.uniform(0.3, 1.0)),
            "dir": float(rng.uniform(0, 2 * math.pi)),
            "seed": int(rng.integers(1 << 30)),
        }
        for n in names
    }
    target = [float(rng.uniform(3.0, 10.0)) for _ in names]
    case = dict(
        names=names,
        veh=veh,
        traj=traj,
        noise=noise,
        thrust_noise=float(rng.uniform(0.0, 0.05)),
        params=params,
        target=target,
        frame=str(rng.choice(["NED", "ENU"])),
        commands=str(rng.choice(["f", "u"])),
        sim_seed=int(rng.integers(1 << 30)),
    )
    for n in names:
        params[n].update(
            ratio=float(rng.uniform(0.2, 0.6)),
            drop=float(rng.uniform(0.85, 0.92)),
            s0=float(rng.choice([-1.0, 1.0])),
            s2=float(rng.choice([-1.0, 1.0])),
            quad=float(rng.uniform(0.0, 0.5)),
        )
    case["vbat"] = (12.6, 12.6 * float(rng.uniform(0.85, 0.92))) if rng.random() < 0.5 else None
    return case


#: what users simulate and fly (``quadfault simulate --trajectory ...``), and the effect
#: sizes they meet: the ``users`` distribution
USER_TRAJECTORIES = ("lissajous", "circle", "hover")
USER_EFFECTS = ("motor_efficiency", "inertia", "com_offset", "mass")


def draw_user_case(seed, i):
    """A flight as a user makes it: the default vehicle and controller, a named trajectory
    with its defaults (Lissajous, circle or hover), 10-60 s, the simulator's default sensor
    noise; none or one effect at the sizes users meet -- a weak rotor at 0.65-0.9, inertia
    x1.2-1.5, a CoM offset of 5-15 mm, mass +-10-20 %."""
    rng = np.random.default_rng([seed, i, 7])
    u = rng.random()
    names = [] if u < 0.2 else [str(rng.choice(USER_EFFECTS))]
    effects = []
    truth = {}
    for n in names:
        if n == "motor_efficiency":
            k = int(rng.integers(4))
            eta = [1.0] * 4
            eta[k] = float(rng.uniform(0.65, 0.9))
            effects.append(fx.MotorEfficiency(tuple(eta)))
            truth["rotor"] = k + 1
        elif n == "inertia":
            effects.append(fx.Inertia((float(rng.uniform(1.2, 1.5)),) * 3))
        elif n == "com_offset":
            r, a = float(rng.uniform(0.005, 0.015)), float(rng.uniform(0, 2 * math.pi))
            effects.append(fx.ComOffset((r * math.cos(a), r * math.sin(a))))
        else:
            sign = float(rng.choice([-1.0, 1.0]))
            effects.append(fx.Mass(1.0 + sign * float(rng.uniform(0.1, 0.2))))
    return dict(
        names=names,
        effects=effects,
        truth=truth,
        trajectory=str(rng.choice(USER_TRAJECTORIES)),
        duration=float(rng.uniform(10.0, 60.0)),
        frame=str(rng.choice(["NED", "ENU"])),
        sim_seed=int(rng.integers(1 << 30)),
    )


def fly_user(c, rate):
    from quadfault.model.trajectory import Hover

    dt = 1.0 / rate
    traj = {"circle": Circle, "lissajous": Lissajous, "hover": Hover}[c["trajectory"]]()
    sc = named_scenario("nominal", c["duration"], dt).replace(trajectory=traj)
    return simulate(
        sc,
        config=SimConfig(dt=dt, sensor_noise=SensorNoise()),
        seed=c["sim_seed"],
        effects=tuple(c["effects"]),
    )


def weak_rotors(doc) -> tuple:
    """The rotors a diagnosis JSON names weak: ``(accepted, in an indistinguishable set)``."""
    acc = [e["params"] for e in doc["effects"] if e["name"] == "motor_efficiency"]
    alike = [
        e["params"]
        for n in doc["indistinguishable"]
        for one in n.get("sets", ())
        for e in one
        if e["name"] == "motor_efficiency"
    ]
    return (
        [int(np.argmin(p["eta"])) + 1 for p in acc],
        [int(np.argmin(p["eta"])) + 1 for p in alike],
    )


def audit(doc) -> dict:
    """Counts the targets forbid: parameters outside their own bounds (effects, suspects,
    rejected and indistinguishable sets), accepted effects with a held-out gain <= 0 or at
    a bound."""
    entries = [e for key in ("effects", "suspect", "rejected") for e in doc[key]]
    entries += [e for n in doc["indistinguishable"] for one in n.get("sets", ()) for e in one]
    outside = 0
    for e in entries:
        for key, (lo, hi) in (e.get("bounds") or {}).items():
            if key not in e["params"]:
                continue
            v = np.asarray(e["params"][key], dtype=float)
            span = np.abs(np.asarray(hi, dtype=float) - np.asarray(lo, dtype=float))
            tol = 1e-9 * np.maximum(span, 1e-12)
            outside += int(np.any((v < np.asarray(lo) - tol) | (v > np.asarray(hi) + tol)))
    return {
        "outside_bounds": outside,
        "accepted_gain_le_0": sum(e["improvement"] <= 0 for e in doc["effects"]),
        "accepted_at_bound": sum(bool(e["at_bound"]) for e in doc["effects"]),
    }


def run_user(job):
    seed, i, rate, permute = job
    c = draw_user_case(seed, i)
    t0 = time.perf_counter()
    rec = fly_user(c, rate)
    t_sim = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "flight.csv")
        write_recording(rec.without_truth(), path, frame=c["frame"], force=True)
        blind = read_recording(path)
    t1, c1 = time.perf_counter(), time.process_time()
    res = Diagnosis().fit(blind)
    t_diag, cpu_diag = time.perf_counter() - t1, time.process_time() - c1
    doc = json.loads(res.to_json())
    row = dict(
        i=i,
        distribution="users",
        truth=c["names"],
        truth_rotor=c["truth"].get("rotor"),
        trajectory=c["trajectory"],
        duration=c["duration"],
        found=res.effect_names,
        indistinguishable=[n["names"] for n in res.indistinguishable],
        rival_sets=[n["names"] for n in res.indistinguishable if "sets" in n],
        weak_rotor=weak_rotors(doc),
        verdict=res.verdict,
        improvement=res.model_improvement,
        t_diag=t_diag,
        cpu_diag=cpu_diag,
        t_sim=t_sim,
        samples=len(blind),
        params={f.name: f.params for f in res.effects},
        truth_params=[e.describe() for e in c["effects"]],
        **audit(doc),
    )
    if permute:  # the same recording with the library in reverse order
        import quadfault.diagnosis.diagnose as diagnose_module

        build = diagnose_module.build_library
        diagnose_module.build_library = lambda rp, names=None: build(rp, names)[::-1]
        try:
            other = Diagnosis().fit(blind)
        finally:
            diagnose_module.build_library = build
        row["order_independent"] = order_agrees(res, other)
    return row


def order_agrees(a, b, rtol=0.01) -> bool:
    """Same verdict, effects and indistinguishable sets, parameters within ``rtol``."""
    if a.verdict != b.verdict or a.effect_names != b.effect_names:
        return False
    if sorted(sorted(n["names"]) for n in a.indistinguishable) != sorted(
        sorted(n["names"]) for n in b.indistinguishable
    ):
        return False
    for ea, eb in zip(a.effects, b.effects):
        for k in ea.params:
            x, y = np.asarray(ea.params[k], float), np.asarray(eb.params[k], float)
            if x.shape != y.shape or not np.allclose(x, y, rtol=rtol, atol=1e-6):
                return False
    return True


def user_verdict(r) -> str:
    """``"right"`` (the concealed effect accepted and first -- or an effect of its class,
    ``EQUIVALENT``, for all but a weak rotor, which must be named with the right rotor), ``"indistinguishable"`` (it is in a set of rivals the flight
    cannot tell apart, the right rotor for a weak one), ``"wrong"``; for an effect-free
    flight ``"right"`` when nothing is accepted nor named, else ``"false alarm"``."""
    if not r["truth"]:
        return "right" if not r["found"] and not r["rival_sets"] else "false alarm"
    name = r["truth"][0]
    accepted, alike = r["weak_rotor"]
    rotor_ok = name != "motor_efficiency" or r["truth_rotor"] in accepted + alike
    top = r["found"][0] if r["found"] else None
    same = top == name or (top and name != "motor_efficiency" and cls(top) == cls(name))
    if same and rotor_ok:
        return "right"
    if any(name in n for n in r["rival_sets"]) and rotor_ok:
        return "indistinguishable"
    return "wrong"


def summarise_users(rows) -> dict:
    for r in rows:
        r["score"] = user_verdict(r)
    eff = [r for r in rows if r["truth"]]
    none = [r for r in rows if not r["truth"]]
    moving = [r for r in eff if r["trajectory"] != "hover"]
    by = Counter((r["truth"][0], r["trajectory"], r["score"]) for r in eff)
    weak = [r for r in eff if r["truth"][0] == "motor_efficiency" and r["trajectory"] != "hover"]
    com = [r for r in eff if r["truth"][0] == "com_offset" and r["trajectory"] != "hover"]
    out = {
        "n": len(rows),
        "n_with_effect": len(eff),
        "n_effect_free": len(none),
        "right": float(np.mean([r["score"] == "right" for r in eff])) if eff else None,
        "right_exact_name": (
            float(np.mean([bool(r["found"]) and r["found"][0] == r["truth"][0] for r in eff]))
            if eff
            else None
        ),
        "right_moving": (
            float(np.mean([r["score"] == "right" for r in moving])) if moving else None
        ),
        "right_or_indistinguishable": (
            float(np.mean([r["score"] in ("right", "indistinguishable") for r in eff]))
            if eff
            else None
        ),
        "wrong": float(np.mean([r["score"] == "wrong" for r in eff])) if eff else None,
        "false_alarm_rate": (
            float(np.mean([r["score"] == "false alarm" for r in none])) if none else None
        ),
        "weak_rotor_named_moving": (
            float(np.mean([r["score"] in ("right", "indistinguishable") for r in weak]))
            if weak
            else None
        ),
        "weak_rotor_com_offset_alone": sum(
            "com_offset" in r["found"] and not r["weak_rotor"][0] and not r["weak_rotor"][1]
            for r in weak
        ),
        "com_offset_weak_rotor_alone": sum(
            bool(r["weak_rotor"][0]) and not r["rival_sets"] for r in com
        ),
        "outside_bounds": sum(r["outside_bounds"] for r in rows),
        "accepted_gain_le_0": sum(r["accepted_gain_le_0"] for r in rows),
        "accepted_at_bound": sum(r["accepted_at_bound"] for r in rows),
        "order_independent": (
            sum(r["order_independent"] for r in rows if "order_independent" in r),
            sum("order_independent" in r for r in rows),
        ),
        "by_case": {f"{a} {b}: {c}": v for (a, b, c), v in sorted(by.items())},
        "cpu_seconds_per_recording_median": float(np.median([r["cpu_diag"] for r in rows])),
    }
    return out


def print_users(s):
    print(
        f"\nBlinded study, users' flights: {s['n']} recordings ({s['n_with_effect']} with an "
        f"effect, {s['n_effect_free']} effect-free)"
    )
    for k, v in s.items():
        if k in ("n", "n_with_effect", "n_effect_free", "by_case"):
            continue
        print(f"{k:<40} {v if not isinstance(v, float) else f'{v:.3f}'}")
    print("by case (concealed effect, trajectory: score):")
    for k, v in s["by_case"].items():
        print(f"  {k} {v}")


def param_error(true, found, veh):
    """Relative error of the effect's main magnitude (deviation from nominal); ``found``'s
    direction parameters in NED / FRD, as the truth."""
    n = true.name
    p = found.params
    if n == "motor_efficiency":
        i = int(np.argmin(true.eta))
        return abs(p["eta"][i] - true.eta[i]) / max(1 - true.eta[i], 1e-9)
    if n == "thrust_scale":
        return abs(p["scale"] - true.scale) / abs(1 - true.scale)
    if n == "drag":
        k = np.array(true.k[:2])
        return float(np.linalg.norm(np.array(p["k_N_s_per_m"][:2]) - k) / np.linalg.norm(k))
    if n == "motor_lag":
        return abs(p["tau_s"] - true.tau) / true.tau
    if n == "delay":
        return abs(p["delay_s"] - true.delay) / true.delay
    if n == "wind":
        F = true.steady_force()[:2]
        return float(np.linalg.norm(np.array(p["force_N"][:2]) - F) / np.linalg.norm(F))
    if n == "ground_effect":
        return abs(p["rotor_radius_m"] - true.rotor_radius) / true.rotor_radius
    if n == "com_offset":
        r = np.array(true.offset)
        return float(np.linalg.norm(np.array(p["offset_m"]) - r) / np.linalg.norm(r))
    if n == "inertia":
        s = np.array(true.scale[:2])
        return float(np.linalg.norm(np.array(p["scale"][:2]) - s) / np.linalg.norm(s - 1))
    if n == "blade_flapping":
        return 0.5 * (
            abs(p["k_force_s_per_m"] - true.k_force) / true.k_force
            + abs(p["k_moment_s"] - true.k_moment) / abs(true.k_moment)
        )
    if n == "rotor_inertia":
        return abs(p["kappa_m_s"] - true.kappa) / true.kappa
    if n == "battery_thrust":
        return abs(p["exponent"] - true.exponent) / true.exponent
    if n == "mass":
        return abs(p["scale"] - true.scale) / abs(true.scale - 1)
    if n == "rate_damping":
        d = np.array(true.linear[:2])
        return float(
            np.linalg.norm(np.array(p["linear_N_m_s_per_rad"][:2]) - d) / np.linalg.norm(d)
        )
    if n == "thrust_curve":  # the thrust change over commands of 0.6-1.4 times hover thrust
        f = np.linspace(0.6, 1.4, 41) * veh.hover_thrust
        dtrue = fx.recurve(f, true.nominal, true.curve) - f
        dfound = fx.recurve(f, p["nominal_curve"], p["curve"]) - f
        return float(np.sqrt(np.mean((dfound - dtrue) ** 2) / np.mean(dtrue**2)))
    return float("nan")


def u_curve(c):
    """The nominal curve of a case's ``u`` commands, None for thrust commands."""
    return (0.0, 0.0, 1e-5 * c["veh"].mass) if c["commands"] == "u" else None


def as_commands(rec, curve):
    """``rec`` with its thrust commands written as ``u`` through ``curve`` (None: kept)."""
    if curve is None:
        return rec
    u = fx.curve_command(curve, rec.thrust_cmd)
    return dataclasses.replace(
        rec, commands_u=u, thrust_curve=curve, thrust_cmd=fx.curve_thrust(curve, u)
    )


def run_one(job):
    seed, i, rate, duration, store, reuse = job
    c = draw_case(seed, i)
    veh = c["veh"]
    curve = u_curve(c)
    t0 = time.perf_counter()
    effects, achieved, deltas = [], [], []
    stem = None if store is None else os.path.join(store, f"case_{seed}_{i:04d}")

    def make(n, delta, dur):
        return make_effect(n, delta, veh, c["params"][n], curve, dur)

    if reuse and os.path.exists(stem + ".truth.json"):  # kept by an earlier --store run
        with open(stem + ".truth.json") as fh:
            saved = json.load(fh)
        deltas, achieved, t_sim = saved["deltas"], saved["snr"], saved["t_sim"]
        effects = [make(n, d, duration) for n, d in zip(c["names"], deltas)]
        blind = read_recording(stem + ".csv")
    else:
        if c["names"]:
            unit = [make(n, 1.0, 5.0) for n in c["names"]]
            pilot = fly(
                veh,
                c["traj"],
                unit,
                c["noise"],
                c["thrust_noise"],
                rate,
                5.0,
                c["sim_seed"],
                c["vbat"],
            )
            s0 = snr(as_commands(pilot, curve), unit, veh)
            for n, s, k in zip(c["names"], s0, c["target"]):
                ratio = k / max(s, 1e-6)
                delta = ratio**0.5 if n == "ground_effect" else ratio  # signal ~ r^2 there
                deltas.append(float(delta))
                effects.append(make(n, delta, duration))
        rec = fly(
            veh,
            c["traj"],
            effects,
            c["noise"],
            c["thrust_noise"],
            rate,
            duration,
            c["sim_seed"],
            c["vbat"],
        )
        rec = as_commands(rec, curve)
        if effects:
            achieved = snr(rec, effects, veh)
        t_sim = time.perf_counter() - t0
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(
                tmp if stem is None else store,
                "flight.csv" if stem is None else os.path.basename(stem) + ".csv",
            )
            write_recording(rec.without_truth(), path, frame=c["frame"], force=True)
            blind = read_recording(path)
        if stem is not None:
            atomic_write_text(
                stem + ".truth.json",
                json.dumps(
                    {"names": c["names"], "deltas": deltas, "snr": achieved, "t_sim": t_sim}
                ),
                force=True,
            )
    t1, c1 = time.perf_counter(), time.process_time()
    res = Diagnosis().fit(blind)
    t_diag, cpu_diag = time.perf_counter() - t1, time.process_time() - c1
    found = res.effect_names
    frame = res.to_dict().get("frame", "NED")  # direction parameters: in the file's frame
    errs = {}
    for e in effects:
        match = [f for f in res.effects if f.name == e.name]
        if match:
            f = dataclasses.replace(match[0], params=frame_vectors(match[0].params, frame))
            errs[e.name] = param_error(e, f, veh)
    return dict(
        i=i,
        truth=c["names"],
        found=found,
        snr=achieved,
        target=c["target"],
        indistinguishable=[n["names"] for n in res.indistinguishable],
        verdict=res.verdict,
        below_resolution=[n["held_out"] for n in res.indistinguishable if "held_out" in n],
        mass=veh.mass,
        frame=c["frame"],
        commands=c["commands"],
        improvement=res.model_improvement,
        param_errors=errs,
        t_diag=t_diag,
        cpu_diag=cpu_diag,
        t_sim=t_sim,
        samples=len(blind),
        params={f.name: f.params for f in res.effects},
        truth_params=[e.describe() for e in effects],
    )


def resolvable(row, rate) -> list:
    """The concealed effects of ``row`` the recording can show: a time constant (a motor lag,
    a delay) shorter than ``TIMING_SAMPLES`` sample periods is below what the diagnosis
    resolves by its own rule (docs/diagnosis.md, "Identifiability"), so it is left out of
    what the diagnosis is expected to find."""
    floor = TIMING_SAMPLES / rate
    keep = []
    for name, spec in zip(row["truth"], row.get("truth_params") or [{}] * len(row["truth"])):
        key = identifiability(name).timescale
        value = (spec.get("params") or {}).get(key) if key else None
        if value is None or float(np.ravel(value)[0]) >= floor:
            keep.append(name)
    return keep


def summarise(rows, rate, duration) -> dict:
    rows_all = rows
    below = [r for r in rows if r["truth"] and not resolvable(r, rate)]
    top_all = [
        bool(r["found"]) and cls(r["found"][0]) in {cls(n) for n in r["truth"]}
        for r in rows
        if r["truth"]
    ]
    rows = [
        dict(r, truth=resolvable(r, rate))
        for r in rows
        if not (r["truth"] and not resolvable(r, rate))
    ]
    with_eff = [r for r in rows if r["truth"]]
    none = [r for r in rows if not r["truth"]]
    top_ok = [
        bool(r["found"]) and cls(r["found"][0]) in {cls(n) for n in r["truth"]} for r in with_eff
    ]
    all_ok = [{cls(n) for n in r["found"]} == {cls(n) for n in r["truth"]} for r in with_eff]
    exact_top = [bool(r["found"]) and r["found"][0] in r["truth"] for r in with_eff]
    fa = [bool(r["found"]) for r in none]
    perr = [v for r in rows for v in r["param_errors"].values() if np.isfinite(v)]
    per_name = {}
    for r in rows:
        for k, v in r["param_errors"].items():
            per_name.setdefault(k, []).append(v)
    imp = [r["improvement"] for r in with_eff]
    conf = Counter()
    for r in rows:
        truth = "+".join(sorted(cls(n) for n in r["truth"])) or "none"
        found = cls(r["found"][0]) if r["found"] else "none"
        conf[(truth, found)] += 1
    tdiag = np.array([r["t_diag"] for r in rows])
    per60k = tdiag * (60.0 * 1000.0) / np.array([r["samples"] for r in rows])
    return {
        "n": len(rows_all),
        "n_with_effect": len(with_eff),
        "n_effect_free": len(none),
        "n_below_resolution": len(below),
        "below_resolution_found_nothing": sum(not r["found"] for r in below),
        "below_resolution_found": {
            n: sum(bool(r["found"]) and r["found"][0] == n for r in below)
            for n in sorted({r["found"][0] for r in below if r["found"]})
        },
        # an effect named indistinguishable from the time constant (the entries of the time
        # constant itself, with their figures, are counted apart)
        "below_resolution_indistinguishable": sum(
            len(r.get("indistinguishable", [])) > len(r.get("below_resolution", [])) for r in below
        ),
        "below_resolution_mismatch": sum(r.get("verdict") == "mismatch" for r in below),
        "below_resolution_gain": [
            min(
                (b["improvement"] for r in below for b in r.get("below_resolution", [])),
                default=None,
            ),
            max(
                (b["improvement"] for r in below for b in r.get("below_resolution", [])),
                default=None,
            ),
        ],
        "top_effect_correct": float(np.mean(top_ok)) if top_ok else None,
        "top_effect_correct_every_concealed": float(np.mean(top_all)) if top_all else None,
        "top_effect_exact_name": float(np.mean(exact_top)) if exact_top else None,
        "all_effects_correct": float(np.mean(all_ok)) if all_ok else None,
        "false_alarm_rate": float(np.mean(fa)) if fa else None,
        "median_param_error": float(np.median(perr)) if perr else None,
        "median_param_error_by_effect": {k: float(np.median(v)) for k, v in per_name.items()},
        "held_out_improvement_median": float(np.median(imp)) if imp else None,
        "held_out_improvement_ge_50pct": float(np.mean(np.array(imp) >= 0.5)) if imp else None,
        "seconds_per_recording_median": float(np.median(tdiag)),
        "cpu_seconds_per_recording_median": float(
            np.median([r.get("cpu_diag", np.nan) for r in rows])
        ),
        "seconds_per_60s_at_1kHz_extrapolated_median": float(np.median(per60k)),
        "snr_achieved_median": float(np.median([s for r in rows for s in r["snr"]]))
        if with_eff
        else None,
        "confusion": {f"{a} -> {b}": v for (a, b), v in sorted(conf.items())},
        "rate_hz": rate,
        "duration_s": duration,
    }


def print_summary(s, rows):
    print(
        f"\nBlinded study: {s['n']} recordings ({s['n_with_effect']} with effects, "
        f"{s['n_effect_free']} effect-free), {s['rate_hz']:.0f} Hz, {s['duration_s']:.0f} s"
    )
    classes = {}
    for name, c in EQUIVALENT.items():
        classes.setdefault(c, []).append(name)
    print(
        "classes: "
        + ", ".join(f"{c} = {{{', '.join(v)}}}" for c, v in classes.items())
        + " (not separable in general; each counted as one class)"
    )
    truths = sorted({k.split(" -> ")[0] for k in s["confusion"]})
    founds = sorted({k.split(" -> ")[1] for k in s["confusion"]})
    w = max(len(t) for t in truths) + 2
    print("\nconfusion (rows: concealed classes, columns: top reported class)")
    print(" " * w + "".join(f"{f[:9]:>10}" for f in founds))
    for t in truths:
        print(f"{t:<{w}}" + "".join(f"{s['confusion'].get(f'{t} -> {f}', 0):>10}" for f in founds))
    print()
    for key in (
        "top_effect_correct",
        "top_effect_exact_name",
        "all_effects_correct",
        "false_alarm_rate",
        "median_param_error",
        "held_out_improvement_median",
        "held_out_improvement_ge_50pct",
        "seconds_per_recording_median",
        "cpu_seconds_per_recording_median",
        "seconds_per_60s_at_1kHz_extrapolated_median",
        "snr_achieved_median",
    ):
        v = s[key]
        print(f"{key:<46} {'n/a' if v is None else f'{v:.3f}'}")
    if s["n_below_resolution"]:
        print(
            f"{s['n_below_resolution']} concealed time constants shorter than "
            f"{TIMING_SAMPLES:g} sample periods (below what the recording resolves; left out "
            f"of the scores above): nothing accepted on {s['below_resolution_found_nothing']}"
            + "".join(f", {k} on {v}" for k, v in s["below_resolution_found"].items())
            + (
                f" (on {s['below_resolution_indistinguishable']} of them an effect named "
                "indistinguishable from the time constant, and not accepted)"
                if s["below_resolution_indistinguishable"]
                else ""
            )
            + f"; verdict mismatch on {s['below_resolution_mismatch']}"
            + (
                ""
                if s["below_resolution_gain"][0] is None
                else " (a time constant below the resolution explains "
                f"{100 * s['below_resolution_gain'][0]:.0f}-"
                f"{100 * s['below_resolution_gain'][1]:.0f} % held out)"
            )
            + f"; top effect correct counting them: "
            f"{s['top_effect_correct_every_concealed']:.3f}"
        )
    print(
        "median parameter error by effect:",
        ", ".join(f"{k} {v:.3f}" for k, v in sorted(s["median_param_error_by_effect"].items())),
    )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=200, help="number of recordings (default 200)")
    ap.add_argument(
        "--seed",
        type=int,
        default=2026,
        help="study seed (default 2026, the held-out seed never used for tuning)",
    )
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument(
        "--backend",
        choices=("pool", "ray"),
        default="pool",
        help="local process pool (default) or Ray (agents.sweep.run_sweep)",
    )
    ap.add_argument("--rate", type=float, default=250.0, help="physics and recording rate [Hz]")
    ap.add_argument("--duration", type=float, default=15.0, help="flight duration [s]")
    ap.add_argument("--out", default=None, help="write rows and summary to this JSON file")
    ap.add_argument(
        "--only",
        default=None,
        metavar="NAME,...",
        help="development: keep only cases concealing one of these effects "
        "('none' = effect-free); the draws of the others are skipped",
    )
    ap.add_argument(
        "--store",
        default=None,
        metavar="DIR",
        help="keep the blinded recordings (and their concealed truth) in DIR",
    )
    ap.add_argument(
        "--reuse",
        action="store_true",
        help="diagnose the recordings an earlier run kept in --store DIR instead "
        "of simulating them again (same seed, rate, duration); cases not "
        "kept there are simulated",
    )
    ap.add_argument(
        "--kept-only",
        action="store_true",
        help="with --reuse: skip the cases not kept in --store DIR",
    )
    ap.add_argument(
        "--distribution",
        choices=("random", "users"),
        default="random",
        help="random: random vehicles and effects at 3-10x the noise (default); users: the "
        "flights and effect sizes users try (draw_user_case), scored right / "
        "indistinguishable / wrong",
    )
    ap.add_argument(
        "--permute",
        action="store_true",
        help="users: diagnose each recording again with the candidate library in reverse "
        "order and count the answers that agree",
    )
    args = ap.parse_args(argv)
    if args.distribution == "users":
        return main_users(args)
    if args.n < 1 or args.workers < 1 or args.rate <= 0 or args.duration <= 5:
        print("blinded_study: --n, --workers >= 1, --rate > 0, --duration > 5 s", file=sys.stderr)
        return 2
    keep = range(args.n)
    if args.only:
        only = {x.strip() for x in args.only.split(",") if x.strip()}
        names = {i: draw_case(args.seed, i)["names"] for i in keep}
        keep = [i for i in keep if ("none" in only and not names[i]) or only & set(names[i])]
    if args.reuse and not args.store:
        print("blinded_study: --reuse needs --store DIR", file=sys.stderr)
        return 2
    if args.store:
        os.makedirs(args.store, exist_ok=True)
    if args.reuse and args.kept_only:
        keep = [
            i
            for i in keep
            if os.path.exists(os.path.join(args.store, f"case_{args.seed}_{i:04d}.truth.json"))
        ]
    jobs = [(args.seed, i, args.rate, args.duration, args.store, args.reuse) for i in keep]
    args.n = len(jobs)
    rows = []
    t0 = time.perf_counter()
    if args.backend == "ray":
        from agents.sweep import run_sweep

        done = run_sweep(run_one, jobs, backend="ray", workers=args.workers, progress=True)
    else:
        pool = Pool(args.workers)
        done = pool.imap_unordered(run_one, jobs)
    for k, row in enumerate(done, 1):
        rows.append(row)
        print(
            f"[{k}/{args.n}] #{row['i']} {row['verdict']} "
            f"truth={'+'.join(row['truth']) or 'none'} found={'+'.join(row['found']) or 'none'}"
            + "".join(f" (indistinguishable: {' or '.join(n)})" for n in row["indistinguishable"])
            + f" snr={[round(x, 1) for x in row['snr']]} "
            f"imp={row['improvement']:.2f} diag={row['t_diag']:.1f}s",
            flush=True,
        )
    if args.backend == "pool":
        pool.close()
    rows.sort(key=lambda r: r["i"])
    s = summarise(rows, args.rate, args.duration)
    s["wall_seconds"] = time.perf_counter() - t0
    print_summary(s, rows)
    if args.out:
        atomic_write_text(
            args.out,
            json.dumps({"summary": s, "rows": rows}, indent=1, default=float) + "\n",
            force=True,
        )
    return 0


def main_users(args) -> int:
    keep = range(args.n)
    if args.only:  # the cases concealing one of these effects ('none': effect-free)
        only = {x.strip() for x in args.only.split(",") if x.strip()}
        names = {i: draw_user_case(args.seed, i)["names"] for i in keep}
        keep = [i for i in keep if ("none" in only and not names[i]) or only & set(names[i])]
    jobs = [(args.seed, i, args.rate, args.permute) for i in keep]
    args.n = len(jobs)
    rows = []
    t0 = time.perf_counter()
    with Pool(args.workers) as pool:
        for k, row in enumerate(pool.imap_unordered(run_user, jobs), 1):
            rows.append(row)
            print(
                f"[{k}/{args.n}] #{row['i']} {row['trajectory']} {row['duration']:.0f}s "
                f"truth={'+'.join(row['truth']) or 'none'}"
                + (f" (rotor {row['truth_rotor']})" if row["truth_rotor"] else "")
                + f" found={'+'.join(row['found']) or 'none'}"
                + "".join(
                    f" (indistinguishable: {' or '.join(n)})" for n in row["indistinguishable"]
                )
                + f" weak rotor named {row['weak_rotor']} cpu={row['cpu_diag']:.1f}s"
                + (
                    ""
                    if "order_independent" not in row
                    else f" order-independent={row['order_independent']}"
                ),
                flush=True,
            )
    rows.sort(key=lambda r: r["i"])
    s = summarise_users(rows)
    s["wall_seconds"] = time.perf_counter() - t0
    print_users(s)
    if args.out:
        atomic_write_text(
            args.out,
            json.dumps({"summary": s, "rows": rows}, indent=1, default=float) + "\n",
            force=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
