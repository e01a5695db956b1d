"""Fair pairs of ``quadfault reproduce``: the EKF partner's Q_eta rule, identical
post-processing, and ``cli`` arguments that reproduce each series through
``quadfault estimate``."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from estimators.paper.pairing import VARIANTS, Variant, choose_partner, pair_ratios, run_pair
from estimators.paper.reproduce import sim_config
from estimators.series_io import read_estimate_csv
from quadfault.errors import ConfigError
from quadfault.io.recording import write_recording
from quadfault.model.scenarios import named_scenario
from quadfault.sim.simulator import simulate


def _curve(q):
    """U-shaped RMSE (minimum 0.02 at q = 1e-2) and an excess spike with its minimum at
    q = 1 (a hump elsewhere)."""
    x = math.log10(q)
    return 0.02 + 0.01 * (x + 2.0) ** 2, 0.05 + 0.02 * x**2


def test_partner_is_the_least_excess_spike_within_the_rmse_target():
    res = choose_partner(None, 0.065, evaluate=_curve, q_range=(1e-5, 1e2), refine=4)
    assert res.matched and res.q_eta == pytest.approx(1.0, rel=0.05)
    # a tighter target cuts the feasible interval below q = 1: its upper edge wins
    res = choose_partner(None, 0.035, evaluate=_curve, q_range=(1e-5, 1e2), refine=6)
    edge = 10 ** (-2 + math.sqrt(1.5))
    assert res.matched and res.rmse <= 0.035 and res.q_eta == pytest.approx(edge, rel=0.1)
    assert all(
        r > 0.035 or e >= res.excess_spike - 1e-12 for r, e in zip(res.curve_rmse, res.curve_excess)
    )


def test_partner_keeps_to_the_fast_branch():
    """A slow filter (left of the RMSE minimum) with a lower excess spike is not chosen."""

    def curve(q):
        r, e = _curve(q)
        return r, (0.0 if q < 1e-2 else e)

    res = choose_partner(None, 0.065, evaluate=curve, q_range=(1e-5, 1e2), refine=4)
    assert res.matched and res.q_eta == pytest.approx(1.0, rel=0.05)
    assert min(res.curve_excess) == 0.0 and res.excess_spike > 0.0


def test_partner_falls_back_to_the_most_accurate_q_eta():
    res = choose_partner(None, 0.01, evaluate=_curve, q_range=(1e-5, 1e2))
    assert not res.matched and res.q_eta == pytest.approx(1e-2, rel=0.2)
    assert "most accurate" in res.message
    with pytest.raises(ConfigError, match="target"):
        choose_partner(None, -1.0, evaluate=_curve)
    with pytest.raises(ConfigError, match="q_range"):
        choose_partner(None, 0.03, evaluate=_curve, q_range=(1.0, 0.1))


def test_variants_share_post_processing_and_keys():
    keys = {(v.irls_key, v.ekf_key) for v in VARIANTS}
    assert ("irls", "ekf") in keys and ("irls_improved", "ekf_improved") in keys
    for v in VARIANTS:
        assert v.ekf_args(1.0)["median"] == (v.median if v.median > 1 else None)


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    rec = simulate(
        named_scenario("abrupt", 3.0), config=sim_config("rk4", "abrupt"), seed=5, thrust_noise=0.07
    )
    path = tmp_path_factory.mktemp("pair") / "abrupt.csv"
    write_recording(rec, path)
    return rec, path


@pytest.mark.slow
def test_each_entry_cli_reproduces_its_series(flight, tmp_path):
    rec, path = flight
    variant = Variant("improved", improved=True, median=21)
    pair = run_pair(rec, variant, 0.3)
    assert set(pair) == {"irls_improved", "ekf_improved"}
    for key, (series, extra) in pair.items():
        assert extra["postprocess"] == "median:21" and extra["partner"] in pair
        assert extra["partner"] != key
        out = tmp_path / f"{key}.csv"
        r = subprocess.run(
            [
                sys.executable,
                "-m",
                "quadfault.cli",
                "estimate",
                str(path),
                *extra["cli"],
                "--out",
                str(out),
                "--quiet",
            ],
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert r.returncode == 0, r.stderr
        np.testing.assert_array_equal(read_estimate_csv(out)["eta"], series.eta)
        assert json.loads(out.with_suffix(".json").read_text())["postprocess"] == "median:21"
    assert pair["ekf_improved"][1]["q_eta"] == 0.3
    assert pair["ekf_improved"][1]["cli"] == [
        "--estimator",
        "ekf",
        "--q-eta",
        "0.3",
        "--accelerometer",
        "auto",
        "--median",
        "21",
    ]  # the improved IRLS reads the accelerometer, so does its partner


def test_pair_ratios():
    per = {
        "irls": {"rmse": [0.02] * 4, "spike": [0.1] * 4, "excess_spike": [0.02] * 4},
        "ekf": {"rmse": [0.025] * 4, "spike": [0.2] * 4, "excess_spike": [0.08] * 4},
    }
    r = pair_ratios(
        {
            "abrupt": per,
            "degradation": {k: {**v, "spike": None, "excess_spike": None} for k, v in per.items()},
        }
    )
    assert r["abrupt"]["paper"] == pytest.approx(
        {"spike": 0.5, "excess_spike": 0.25, "excess_spike_difference": -0.06, "rmse": 0.8}
    )
    assert r["degradation"]["paper"]["spike"] is None
    assert r["degradation"]["paper"]["excess_spike_difference"] is None


def test_excess_ratio_over_an_ekf_excess_within_noise_is_not_a_number(tmp_path):
    """An EKF whose excess spike is within its noise gives no ratio (the report says n/a, not
    50x) but the difference IRLS - EKF."""
    from estimators.paper.pairing import MIN_EXCESS
    from estimators.paper.report import _ratio_lines, excess_ratio_text

    per = {
        "irls": {"rmse": [0.02] * 4, "spike": [0.1] * 4, "excess_spike": [0.02] * 4},
        "ekf": {"rmse": [0.025] * 4, "spike": [0.2] * 4, "excess_spike": [MIN_EXCESS / 25] * 4},
    }
    r = pair_ratios({"combined": per})["combined"]["paper"]
    assert r["excess_spike"] is None
    assert r["excess_spike_difference"] == pytest.approx(0.02 - MIN_EXCESS / 25)
    assert excess_ratio_text(r, "x") == "n/a"
    assert excess_ratio_text({"excess_spike": None, "excess_spike_difference": None}) == "-"
    assert (
        excess_ratio_text({"excess_spike": 0.25, "excess_spike_difference": -0.06}, "x") == "0.25x"
    )
    row = [
        line
        for line in _ratio_lines({"combined": {"paper": r}})
        if line.startswith("| combined | paper |")
    ]
    assert row == ["| combined | paper | 0.50 | n/a | 0.020 | 0.80 |"]


@pytest.mark.parametrize("plot", ["plot_rmse_std", "plot_spikes"])
def test_bar_figures_label_every_series_once_and_hide_no_bar(plot, monkeypatch, tmp_path):
    """The bar figures of ``quadfault reproduce``: one legend entry per series, all labels
    different (each EKF partner named by its IRLS variant), the legend clear of every axes."""
    from estimators.paper import figures

    keys = ("irls", "ekf", "irls_median", "ekf_median", "irls_improved", "ekf_improved")
    entry = {"rmse": [0.02] * 4, "std": [0.02] * 4, "spike": [0.1, 0.2, 0.15, 0.12]}
    scenarios = {n: {k: dict(entry) for k in keys} for n in ("abrupt", "combined")}
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    saved = []
    monkeypatch.setattr(figures, "atomic_savefig", lambda fig, path, **kw: saved.append(fig))
    getattr(figures, plot)(tmp_path / "f.png", scenarios)
    (fig,) = saved
    (legend,) = fig.legends
    labels = [t.get_text() for t in legend.get_texts()]
    assert len(labels) == len(keys) == len(set(labels))
    renderer = FigureCanvasAgg(fig).get_renderer()
    box = legend.get_window_extent(renderer)
    assert not any(box.overlaps(ax.get_window_extent(renderer)) for ax in fig.axes)


def test_every_baseline_has_a_keyed_partner_with_the_same_post_processing():
    from estimators.paper.pairing import BASELINES

    assert list(BASELINES)[0] == "ekf" and {"rls", "ukf"} <= set(BASELINES)
    for v in VARIANTS:
        for b in BASELINES:
            args = v.partner_args(b, 0.01)
            assert args["median"] == (v.median if v.median > 1 else None)
            assert v.key(b) == (b if v.name == "paper" else f"{b}_{v.name}")
    assert VARIANTS[0].partner_args("rls", 0.01)["forgetting"] == pytest.approx(0.99)


def test_a_partner_that_regresses_the_residual_gets_the_irls_variants_prefilter():
    """The residual prefilter is pre-processing: RLS (the same regression) runs with the IRLS
    variant's (none for the paper's settings and the median alone, the improved one's 10 ms);
    the EKF and the UKF have no regression and no prefilter option."""
    from estimators.irls_config import IRLSConfig
    from estimators.paper.pairing import BASELINES

    by_name = {v.name: v for v in VARIANTS}
    assert by_name["paper"].prefilter == 0.0 and by_name["median"].prefilter == 0.0
    assert by_name["improved"].prefilter == IRLSConfig.improved().prefilter > 0.0
    for v in VARIANTS:
        assert v.partner_args("rls", 0.01)["prefilter"] == v.prefilter
        for b in ("ekf", "ukf"):
            assert "prefilter" not in v.partner_args(b, 0.01)
    assert BASELINES["rls"].options(0.01, 0.02) == {"forgetting": 0.99, "prefilter": 0.02}
    assert BASELINES["rls"].options(0.01) == {"forgetting": 0.99}
    with pytest.raises(ConfigError, match="baseline"):
        VARIANTS[0].partner_args("kalman", 0.1)


def test_every_partner_reads_the_accelerometer_where_its_irls_does():
    """The improved IRLS takes its thrust rows from the accelerometer (``auto``): its EKF, RLS
    and UKF partners measure it too; the paper's settings and the median alone read none."""
    from estimators.irls_config import IRLSConfig
    from estimators.paper.pairing import BASELINES

    by_name = {v.name: v for v in VARIANTS}
    assert by_name["improved"].accelerometer == IRLSConfig.improved().accelerometer == "auto"
    for b in BASELINES:
        assert by_name["improved"].partner_args(b, 0.01)["accelerometer"] == "auto"
        for v in ("paper", "median"):
            assert by_name[v].accelerometer == "off"
            assert "accelerometer" not in by_name[v].partner_args(b, 0.01)
    assert BASELINES["ekf"].options(0.1, None, "auto") == {"q_eta": 0.1, "accelerometer": "auto"}


@pytest.mark.slow
def test_partners_are_tuned_on_the_calibration_flight_never_on_the_scored_ones(monkeypatch):
    """Every tuning search (choose_partner) sees the calibration flight only, and on the
    scored flights each partner runs once per scenario with the tuning chosen there."""
    from estimators.paper import pairing
    from estimators.paper.reproduce import ReproduceConfig, calibration_key, reproduce

    searched, runs = [], []
    choose, estimate = pairing.choose_partner, pairing.estimate_series

    def spy_choose(rec, *args, **kw):
        searched.append((rec.meta["seed"], kw["baseline_name"]))
        return choose(rec, *args, **kw)

    def spy_estimate(rec, name, **kw):
        runs.append((rec.meta["seed"], name, kw))
        return estimate(rec, name, **kw)

    monkeypatch.setattr(pairing, "choose_partner", spy_choose)
    monkeypatch.setattr(pairing, "estimate_series", spy_estimate)
    cfg = ReproduceConfig.quick(
        duration=1.0,
        calibration_duration=1.5,
        workers=1,
        reference_mode=False,
        improved=False,
        seed=3,
        partner_points_per_decade=1.0,
        partner_refine=1,
    )
    run = reproduce(cfg)
    assert sorted(searched) == sorted((cfg.calibration_seed, b) for b in ("ekf", "rls", "ukf"))
    tuning_runs = {(s, n) for s, n, _ in runs if n != "irls"}
    assert (cfg.calibration_seed, "rls") in tuning_runs
    scored = [(n, kw) for s, n, kw in runs if s == cfg.seed]
    assert scored and all(s in (cfg.seed, cfg.calibration_seed) for s, _, _ in runs)
    for b in ("ekf", "rls", "ukf"):
        chosen = run["calibration"][calibration_key("paper", b)]
        mine = [kw for n, kw in scored if n == b]
        assert len(mine) == 4  # once per scored scenario, never a scan
        same = {"prefilter": 0.0} if b == "rls" else {}  # the paper IRLS's: none
        assert all(kw == {**chosen.option, **same, "median": None} for kw in mine)
    # the RLS's scan on the calibration flight runs with the paper IRLS's prefilter too
    scans = [kw for s, n, kw in runs if s == cfg.calibration_seed and n == "rls"]
    assert scans and all(kw["prefilter"] == 0.0 for kw in scans)
