"""``quadfault reproduce``: the paper's evaluation, IRLS vs a calibrated EKF (and RLS and a UKF).

Steps (``docs/reproduce.md``):

1. on a calibration flight of the combined scenario with seed ``K + 1000``, choose for every
   IRLS variant (:data:`estimators.paper.pairing.VARIANTS`) its partner among each baseline
   (:data:`estimators.paper.pairing.BASELINES`: the EKF, RLS, the UKF): the same output
   post-processing, and the tuning (``Q_eta``, RLS's forgetting factor) with the smallest
   excess spike among those whose RMSE is at most the IRLS's
   (:func:`estimators.paper.pairing.choose_partner`);
2. fly degradation, abrupt, combined and clipping (sigma_f = 0.07) with seed ``K``, run every
   pair, score them (:mod:`estimators.metrics`) and run the fault detector
   (:mod:`estimators.fdi`) on every estimate stream;
3. the paper's pair on flights of the ``reference`` integration mode (the authors' Euler step
   with its input lag), its EKF calibrated to equal RMSE as in the paper
   (:mod:`estimators.paper.calibration`), for a like-for-like table beside the paper's
   numbers;
4. write ``metrics.json`` (docs/reproduce.md), ``report.md`` and PNG figures
   (:mod:`estimators.paper.report`); print the table.

Scenario jobs run in parallel processes (``--workers``, default 2).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from estimators.paper.pairing import pair_ratios
from estimators.paper.report import STATIC_FIGURES, excess_ratio_text, table, write_report
from estimators.registry import make_estimator
from quadfault.errors import ConfigError
from quadfault.model.sensor_presets import as_sensor_noise
from quadfault.model.sensors import SensorNoise

SCENARIOS = ("degradation", "abrupt", "combined", "clipping")
REFERENCE_SCENARIOS = ("degradation", "abrupt", "combined")
MODES = ("rk4", "reference")
FIGURES = ("estimates_{s}.png", "errors_{s}.png")

#: The reference code's hard-coded results (facts sec. 6): motor-averaged RMSE / std per case
#: and the per-motor max spikes.
PAPER = {
    "rmse": {
        "irls": {"degradation": 0.023358, "abrupt": 0.0237185, "combined": 0.02357875},
        "ekf": {"degradation": 0.02247225, "abrupt": 0.027893, "combined": 0.02250075},
    },
    "std": {
        "irls": {"degradation": 0.0233525, "abrupt": 0.02008725, "combined": 0.0235735},
        "ekf": {"degradation": 0.02246, "abrupt": 0.02005375, "combined": 0.022483},
    },
    "spike": {
        "irls": {
            "abrupt": [0.139575, 0.123851, 0.142402, 0.130006],
            "combined": [0.120609, 0.102525, 0.129096, 0.150433],
        },
        "ekf": {
            "abrupt": [0.286273, 0.263499, 0.292192, 0.274747],
            "combined": [0.176225, 0.155338, 0.259303, 0.220348],
        },
    },
}


@dataclass(frozen=True)
class ReproduceConfig:
    """What ``reproduce`` runs.

    Attributes:
        duration: flight time of each scored scenario [s] (fault windows scale with it).
        seed: seed of the scored flights; the calibration flight uses ``seed + 1000``.
        calibration_scenario, calibration_duration [s]: the calibration flight.
        q_range, points_per_decade, bisection_steps: the Q_eta scan.
        thrust_noise: sigma_f.
        reference_mode: also run the ``reference`` integration mode.
        workers: parallel processes (1 = in this process).
        history_offset: the convergence figure's window ends this long after motor 1's fault
            onset [s].
        improved: also run the IRLS variants beyond the paper (the output median alone, and
            ``IRLSConfig.improved()``: change completion and output median, docs/irls.md) on
            the RK4 flights, each with its EKF partner.
        partner_q_range, partner_points_per_decade, partner_refine: the partners' ``Q_eta``
            scan (EKF, UKF; RLS scans its own ``1 - lambda`` range) and its refinement rounds
            (:func:`estimators.paper.pairing.choose_partner`).
        baselines: the estimators each IRLS variant is paired with (names of
            :data:`estimators.paper.pairing.BASELINES`; the EKF always, the paper's).
        sensor_noise: the sensors of every flight, the calibration flight's too (a
            :class:`~quadfault.model.sensors.SensorNoise` or what ``as_sensor_noise`` takes, a
            preset name such as ``"px4"``; default noise-free, as in the paper).
    """

    duration: float = 80.0
    seed: int = 0
    calibration_scenario: str = "combined"
    calibration_duration: float = 40.0
    q_range: tuple = (1e-4, 10.0)
    points_per_decade: float = 1.0
    bisection_steps: int = 6
    thrust_noise: float = 0.07
    reference_mode: bool = True
    workers: int = 2
    history_offset: float = 0.02
    improved: bool = True
    partner_q_range: tuple = (1e-4, 1e3)
    partner_points_per_decade: float = 3.0
    partner_refine: int = 3
    baselines: tuple = ("ekf", "rls", "ukf")
    sensor_noise: SensorNoise = field(default_factory=SensorNoise)

    def __post_init__(self):
        object.__setattr__(self, "sensor_noise", as_sensor_noise(self.sensor_noise))

    @classmethod
    def quick(cls, **changes) -> ReproduceConfig:
        """~1 minute: 12 s flights (schedule scaled) and a coarser calibration."""
        return replace(
            cls(
                duration=12.0,
                calibration_duration=12.0,
                q_range=(1e-3, 10.0),
                bisection_steps=4,
                partner_q_range=(1e-3, 1e3),
                partner_points_per_decade=2.0,
                partner_refine=2,
            ),
            **changes,
        )

    @property
    def variants(self) -> tuple:
        """The IRLS variants run on the RK4 flights."""
        from estimators.paper.pairing import VARIANTS

        return VARIANTS if self.improved else VARIANTS[:1]

    @property
    def calibration_seed(self) -> int:
        return self.seed + 1000


def sim_config(mode: str, name: str, sensor_noise=None):
    """Simulation settings of a scenario.

    ``reference``: the authors' loop (``SimConfig.reference()``). ``rk4``: our integrator with
    the paper's actuator assumption, no upper thrust limit (only ``f >= 0``), except for
    ``clipping``, whose point is saturation at f_max. With the default f_max (thrust-to-weight
    2), a motor at eta = 0.5 cannot hold hover plus the circle, and the abrupt and combined
    flights lose control during the first fault. ``sensor_noise``: the sensors (None:
    noise-free).
    """
    from quadfault.sim.simulator import SimConfig

    noise = as_sensor_noise(sensor_noise)
    if mode == "reference":
        return SimConfig.reference(sensor_noise=noise)
    return SimConfig(saturate=name == "clipping", sensor_noise=noise)


def _fly(name: str, duration: float, seed: int, mode: str, sigma: float, sensor_noise=None):
    from quadfault.model.scenarios import named_scenario
    from quadfault.sim.simulator import simulate

    return simulate(
        named_scenario(name, duration),
        config=sim_config(mode, name, sensor_noise),
        seed=seed,
        thrust_noise=sigma,
    )


def flight_check(rec) -> dict:
    """Did the flight stay under control? (rotor commands beyond 5x the hover thrust on more
    than 1 % of the rows, or more than 10 m from the start, mean it did not)."""
    f = np.abs(rec.thrust_cmd).max(axis=1)
    wild = float(np.mean(f > 5.0 * rec.vehicle.hover_thrust))
    drift = float(np.max(np.linalg.norm(rec.position - rec.position[0], axis=1)))
    return {
        "max_command": float(f.max()),
        "max_distance": drift,
        "diverged": bool(wild > 0.01 or drift > 10.0),
    }


def _calibration_job(mode: str, cfg: ReproduceConfig) -> dict:
    """The calibration flight of ``mode``. ``rk4``: every variant's IRLS RMSE on it and its EKF
    partner (:func:`estimators.paper.pairing.choose_partner`, one EKF scan shared by all);
    ``reference``: the paper pair's EKF matched to the IRLS's RMSE, as in the paper
    (:func:`estimators.paper.calibration.calibrate_q_eta`)."""
    from estimators.paper.calibration import calibrate_q_eta
    from estimators.paper.pairing import (
        BASELINES,
        VARIANTS,
        choose_partner,
        irls_target,
        shared_scan,
    )

    rec = _fly(
        cfg.calibration_scenario,
        cfg.calibration_duration,
        cfg.calibration_seed,
        mode,
        cfg.thrust_noise,
        cfg.sensor_noise,
    )
    if mode == "reference":
        cal = calibrate_q_eta(
            rec,
            irls_target(rec, VARIANTS[0]),
            q_range=cfg.q_range,
            points_per_decade=cfg.points_per_decade,
            bisection_steps=cfg.bisection_steps,
        )
        return {"reference": cal}
    targets = {v.name: irls_target(rec, v) for v in cfg.variants}
    out = {}
    for b in cfg.baselines:
        scan = shared_scan(rec, b)
        q_range = cfg.partner_q_range if BASELINES[b].option == "q_eta" else None
        for v in cfg.variants:
            out[calibration_key(v.name, b)] = choose_partner(
                rec,
                targets[v.name],
                v.median,
                q_range=q_range,
                points_per_decade=cfg.partner_points_per_decade,
                refine=cfg.partner_refine,
                evaluate=scan(v.median, v.prefilter, v.accelerometer),
                baseline_name=b,
            )
    return out


def calibration_key(variant: str, baseline_name: str) -> str:
    """The key of a partner's calibration: ``rk4`` / ``rk4_<variant>`` for the EKF (as
    before), with ``/<baseline>`` for the others."""
    key = "rk4" if variant == "paper" else f"rk4_{variant}"
    return key if baseline_name == "ekf" else f"{key}/{baseline_name}"


def _scenario_job(
    mode: str, name: str, cfg: ReproduceConfig, tunings: dict, keep_series: bool
) -> dict:
    """Fly one scenario; run and score every variant's pairs (``tunings``: variant name ->
    {baseline: its partner's speed q}; the reference mode runs the paper's EKF pair only)."""
    from estimators.fdi import detect, evaluate
    from estimators.metrics import fault_windows, score
    from estimators.paper.pairing import VARIANTS, run_pairs

    rec = _fly(name, cfg.duration, cfg.seed, mode, cfg.thrust_noise, cfg.sensor_noise)
    out = {
        "mode": mode,
        "name": name,
        "scores": {},
        "extra": {},
        "fdi": {},
        "flight": flight_check(rec),
    }
    series = {}
    for v in (x for x in VARIANTS if x.name in tunings):
        for key, (s, extra) in run_pairs(rec, v, tunings[v.name]).items():
            out["scores"][key] = score(rec, s)
            out["extra"][key] = extra
            out["fdi"][key] = evaluate(detect(s), fault_windows(rec)).to_dict()
            series[key] = s.eta
    if keep_series:
        out["series"] = {"t": rec.t, "truth": rec.eta_true, **series}
        out["windows"] = fault_windows(rec)
    return out


def _warm_up() -> None:
    """Compile the numba kernels once in the parent so forked workers inherit them."""
    rec = _fly("hover", 0.05, 0, "rk4", 0.0)
    for name in ("irls", "ekf", "rls", "ukf"):
        make_estimator(name, rec.vehicle).run(rec)
    _fly("hover", 0.05, 0, "reference", 0.0)


def _map(fn, jobs, workers: int, bar):
    """Run ``fn(*job)`` for every job, in ``workers`` processes; results in job order."""
    if workers <= 1 or len(jobs) <= 1:
        results = []
        for job in jobs:
            results.append(fn(*job))
            bar.update(1)
        return results
    import multiprocessing

    # fork: workers inherit the kernels compiled by _warm_up (spawn where fork is missing)
    method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    ctx = multiprocessing.get_context(method)
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        futures = [pool.submit(fn, *job) for job in jobs]
        results = []
        for fut in futures:
            results.append(fut.result())
            bar.update(1)
    return results


def reproduce(cfg: ReproduceConfig, progress: bool = False) -> dict:
    """Run the evaluation; returns everything ``write_outputs`` needs."""
    from quadfault.progress import progress_bar

    modes = MODES if cfg.reference_mode else ("rk4",)
    start = time.perf_counter()
    _warm_up()
    cal_jobs = [(m, cfg) for m in modes]
    n_jobs = (
        len(cal_jobs) + len(SCENARIOS) + (len(REFERENCE_SCENARIOS) if cfg.reference_mode else 0)
    )
    bar = progress_bar(
        total=n_jobs + 1, desc="reproduce", unit="job", disable=None if progress else True
    )
    try:
        cals = {
            k: c
            for block in _map(_calibration_job, cal_jobs, cfg.workers, bar)
            for k, c in block.items()
        }
        q = {
            v.name: {b: cals[calibration_key(v.name, b)].q_eta for b in cfg.baselines}
            for v in cfg.variants
        }
        jobs = [("rk4", s, cfg, q, True) for s in SCENARIOS]
        if cfg.reference_mode:
            jobs += [
                ("reference", s, cfg, {"paper": {"ekf": cals["reference"].q_eta}}, False)
                for s in REFERENCE_SCENARIOS
            ]
        results = _map(_scenario_job, jobs, cfg.workers, bar)
        history = irls_history(cfg)
        bar.update(1)
    finally:
        bar.close()
    return {
        "config": cfg,
        "calibration": cals,
        "results": results,
        "history": history,
        "seconds": time.perf_counter() - start,
    }


def irls_history(cfg: ReproduceConfig) -> dict:
    """One IRLS window just after motor 1's fault onset, with ``record_history``: the KKT
    histories of every IRLS round (warm-started as usual) and the interior-point iterates of
    the first round started from eta = 0.5 instead (the reference ``run.m``'s ``x0``)."""
    from estimators.base import samples
    from estimators.ipm import solve_box_qp
    from estimators.irls import IRLSConfig, SlidingWindowIRLS
    from estimators.residuals import segment_terms
    from estimators.robust import mad_weights

    rec = _fly(
        "combined", min(cfg.duration, 12.0), cfg.seed, "rk4", cfg.thrust_noise, cfg.sensor_noise
    )
    icfg = IRLSConfig(record_history=True)
    onset = rec.meta["fault_windows"][0][1]
    k_end = int(np.searchsorted(rec.t, onset + cfg.history_offset))
    k0 = k_end - icfg.window + 1
    x_prev = SlidingWindowIRLS(rec.vehicle).run(rec.slice(0, k_end).without_truth()).eta[-1]
    est = SlidingWindowIRLS(rec.vehicle, icfg)
    est.reset(x_prev)
    last = None
    for s in samples(rec.slice(k0, k_end + 1).without_truth()):
        last = est.update(s)
    d = last.diagnostics
    # first round of the same window, from x0 = 0.5, keeping the iterates (x_history)
    sl = slice(k0, k_end + 1)
    f = np.clip(rec.thrust_cmd[sl], 0.0, rec.vehicle.rotor_max_thrust)
    seg = segment_terms(
        rec.vehicle,
        rec.t[sl],
        rec.position[sl],
        rec.velocity[sl],
        rec.rotation[sl],
        rec.omega[sl],
        f,
        icfg.segment_weights,
    )
    e = seg.c + 2.0 * (seg.b @ x_prev) + np.einsum("snm,n,m->s", seg.H, x_prev, x_prev)  # eq. 26
    w, _ = mad_weights(
        e,
        z_soft=icfg.z_soft,
        power=icfg.soft_power,
        z_hard=icfg.z_hard,
        hard_drop=icfg.hard_drop,
        w_min=icfg.w_min,
        mad_eps=icfg.mad_eps,
    )
    JGJ = np.einsum("s,snm->nm", w, seg.H) + icfg.gamma * np.eye(4)
    x0 = np.full(4, 0.5)
    ipm = solve_box_qp(
        JGJ,
        w @ seg.b - icfg.gamma * x_prev,
        icfg.lower,
        icfg.upper,
        x0,
        icfg.ipm,
        record_history=True,
    )
    return {
        "t": float(rec.t[k_end]),
        "truth": rec.eta_true[k_end].tolist(),
        "x_history": np.vstack((x0, ipm.x_history)),
        "x_prev": x_prev.tolist(),
        "dual": d.dual_history,
        "cent": d.cent_history,
        "gap": d.gap_history,
        "residual": d.residual_history,
        "eta": last.eta.tolist(),
    }


# ---------------------------------------------------------------------------------------
# outputs
def metrics_document(run: dict) -> dict:
    """``metrics.json``: the contract's ``scenarios`` block plus config, reference mode, FDI."""
    cfg: ReproduceConfig = run["config"]
    doc = {
        "scenarios": {},
        "reference_mode": {"scenarios": {}},
        "fdi": {},
        "reference_mode_fdi": {},
        "flights": {},
        "reference_mode_flights": {},
    }
    for r in run["results"]:
        ref = r["mode"] == "reference"
        scen = doc["reference_mode"]["scenarios"] if ref else doc["scenarios"]
        fdi = doc["reference_mode_fdi"] if ref else doc["fdi"]
        scen[r["name"]] = {k: {**v.to_contract(), **r["extra"][k]} for k, v in r["scores"].items()}
        fdi[r["name"]] = r["fdi"]
        doc["reference_mode_flights" if ref else "flights"][r["name"]] = r["flight"]
    if not cfg.reference_mode:
        del doc["reference_mode"], doc["reference_mode_fdi"], doc["reference_mode_flights"]
    doc["ratios"] = pair_ratios(doc["scenarios"])
    doc["baseline_ratios"] = {
        b: pair_ratios(doc["scenarios"], baseline_name=b) for b in cfg.baselines
    }
    doc["spike_ratio"] = {
        n: {v: r["spike"] for v, r in per.items() if r["spike"] is not None}
        for n, per in doc["ratios"].items()
    }
    doc["config"] = {
        **asdict(cfg),
        "q_range": list(cfg.q_range),
        "partner_q_range": list(cfg.partner_q_range),
        "integrator": "rk4",
        "baselines": list(cfg.baselines),
        "sensor_noise": cfg.sensor_noise.describe() if cfg.sensor_noise.any else "none",
        "upper_thrust_limit": "only in clipping (the paper has none)",
        "align": "end",
        "ekf_q_eta": run["calibration"]["rk4"].q_eta,
        "ekf_q_eta_improved": (
            run["calibration"]["rk4_improved"].q_eta
            if "rk4_improved" in run["calibration"]
            else None
        ),
        "ekf_q_eta_median": (
            run["calibration"]["rk4_median"].q_eta if "rk4_median" in run["calibration"] else None
        ),
        "calibration": {m: c.to_dict() for m, c in run["calibration"].items()},
        "seconds_total": run["seconds"],
    }
    doc["paper"] = PAPER
    return doc


def planned_files(out: Path) -> list[Path]:
    names = ["metrics.json", "report.md", *STATIC_FIGURES]
    names += [f.format(s=s) for s in SCENARIOS for f in FIGURES]
    return [out / n for n in names]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--out",
        default="quadfault-reproduce",
        help="output folder (default ./quadfault-reproduce; created if missing)",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="12 s flights and a coarser calibration (about a minute)",
    )
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        help="seed of the scored flights (calibration flight: seed + 1000)",
    )
    p.add_argument("--workers", type=int, default=2, help="parallel processes (default 2)")
    p.add_argument(
        "--no-reference-mode",
        action="store_true",
        help="skip the flights of the reference integration mode",
    )
    p.add_argument(
        "--baselines",
        default="ekf,rls,ukf",
        metavar="NAMES",
        help="comma-separated estimators each IRLS variant is paired with, each "
        "tuned on the calibration flight (default ekf,rls,ukf; ekf always)",
    )
    p.add_argument(
        "--no-improved",
        action="store_true",
        help="skip the IRLS variants beyond the paper (output median, "
        "IRLSConfig.improved()) and their EKF partners",
    )
    p.add_argument(
        "--sensor-noise",
        default=None,
        metavar="PRESET|POS,VEL,ATT,GYRO[,ACC]",
        help="the sensors of every flight: a preset measured on real logs (crazyflie, px4, "
        "...: docs/sensors.md) or white noise stds as for simulate (default: none, as in "
        "the paper)",
    )


def run(args) -> int:
    from quadfault.fileio import atomic_write_text, check_writable
    from quadfault.progress import enabled

    if args.workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {args.workers}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {out}: exists and is not a folder")
    if out.exists():
        check_writable(planned_files(out), force=args.force)
    base = ReproduceConfig.quick() if args.quick else ReproduceConfig()
    cfg = replace(
        base,
        seed=args.seed,
        workers=args.workers,
        baselines=baselines_of(getattr(args, "baselines", "ekf,rls,ukf")),
        reference_mode=not args.no_reference_mode,
        improved=not getattr(args, "no_improved", False),
        sensor_noise=as_sensor_noise(getattr(args, "sensor_noise", None), "--sensor-noise"),
    )
    result = reproduce(cfg, progress=not args.quiet and enabled())
    out.mkdir(parents=True, exist_ok=True)
    doc = metrics_document(result)
    atomic_write_text(
        out / "metrics.json", json.dumps(doc, indent=2, default=_json) + "\n", force=args.force
    )
    write_report(out, doc, result, force=args.force)
    print(
        f"quadfault reproduce ({'quick' if args.quick else 'full'}, seed {cfg.seed}, "
        f"integrator rk4, EKF Q_eta = {doc['config']['ekf_q_eta']:.4g}"
        + (f", sensor noise {_noise_text(cfg.sensor_noise)})" if cfg.sensor_noise.any else ")")
    )
    print(table(doc["scenarios"]))
    for b, ratios in doc["baseline_ratios"].items():
        for name, per in ratios.items():
            pairs = [
                f"{v} spike {r['spike']:.2f}x, excess {excess_ratio_text(r, 'x')}, "
                f"RMSE {r['rmse']:.2f}x"
                for v, r in per.items()
                if r["spike"] is not None
            ]
            if pairs:
                print(f"IRLS/{b.upper()} {name}: " + "; ".join(pairs))
    bad = [
        f"{n} ({m})"
        for m, key in (("rk4", "flights"), ("reference", "reference_mode_flights"))
        for n, fl in doc.get(key, {}).items()
        if fl["diverged"]
    ]
    if bad:
        print(
            f"WARNING: flights that lost control (their numbers are meaningless): {', '.join(bad)}"
        )
    if cfg.reference_mode:
        print("\nreference integration mode (the authors' Euler step):")
        print(table(doc["reference_mode"]["scenarios"]))
    print(
        f"\nwrote {out / 'metrics.json'}, {out / 'report.md'} and figures "
        f"({result['seconds']:.0f} s)"
    )
    return 0


def _noise_text(noise) -> str:
    return noise.name or ",".join(f"{x:g}" for x in noise.white)


def baselines_of(text: str) -> tuple:
    """``--baselines`` as names (the EKF first, always; clean error for unknown names)."""
    from estimators.paper.pairing import BASELINES

    names = [x.strip() for x in str(text).split(",") if x.strip()]
    bad = [x for x in names if x not in BASELINES]
    if bad:
        raise ConfigError(
            f"--baselines: unknown {', '.join(map(repr, bad))}; choose from {', '.join(BASELINES)}"
        )
    return ("ekf",) + tuple(dict.fromkeys(x for x in names if x != "ekf"))


def _json(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")
