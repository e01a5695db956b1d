"""``report.md`` and PNG plots of a diagnosis (matplotlib, Agg backend).

Plots:

* ``residuals.png`` -- held-out residual per channel over time, nominal vs diagnosed; spans
  excluded as not free flight shaded grey, the importer's calibration segment hatched,
  located intervals orange;
* ``regimes.png`` -- binned trends: per disagreeing channel (or, when none disagrees, the
  channels with the largest residual), the median and interquartile range of the residual
  in ``REGIME_BINS`` quantile bins of the regime variable that explains it best, nominal vs
  diagnosed;
* ``prediction.png`` -- held-out open-loop error against the horizon for the nominal model,
  the diagnosed model and the constant-velocity / constant-acceleration baselines, and the
  nominal vs diagnosed error over the flight at the horizon nearest 0.2 s (position for a
  pose log, attitude for an IMU-only log).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quadfault.diagnosis.locate import regime_variables
from quadfault.diagnosis.report_text import markdown
from quadfault.diagnosis.residuals import channel_unit
from quadfault.diagnosis.result import DiagnosisResult
from quadfault.errors import QuadfaultError
from quadfault.fileio import atomic_savefig, atomic_write_text, check_writable

FILES = ("report.md", "residuals.png", "regimes.png", "prediction.png")
REGIME_BINS = 10
COLORS = {
    "nominal": "tab:red",
    "model": "tab:blue",
    "constant_velocity": "tab:gray",
    "constant_acceleration": "tab:olive",
}
LABELS = {
    "nominal": "nominal model",
    "model": "with diagnosed effects",
    "constant_velocity": "constant velocity",
    "constant_acceleration": "constant acceleration",
}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _shade(ax, res):
    s = res.series
    for a, b, _ in s.get("masked", ()):
        ax.axvspan(a, b, color="0.6", alpha=0.35, lw=0)
    for a, b in s.get("calibration", ()):
        ax.axvspan(a, b, facecolor="none", edgecolor="tab:blue", hatch="//", alpha=0.25, lw=0)


def _broken(t, *arrays):
    """``t`` and ``arrays`` with a NaN row wherever consecutive blocks are not adjacent
    (gaps, excluded spans), so plotted lines do not bridge them."""
    dt = np.diff(t)
    cut = np.flatnonzero(dt > 2.0 * np.median(dt)) + 1
    return [np.insert(np.asarray(a, float), cut, np.nan, axis=0) for a in (t,) + arrays]


def _residuals_png(res: DiagnosisResult, path, force):
    plt = _plt()
    s = res.series
    t, base, model = _broken(s["block_t"], s["baseline"], s["model"])
    n = len(res.channels)
    fig, axes = plt.subplots(n, 1, figsize=(10, 1.6 * n + 1.2), sharex=True, squeeze=False)
    for j, (ax, ch) in enumerate(zip(axes[:, 0], res.channels)):
        ax.plot(t, base[:, j], lw=0.6, color=COLORS["nominal"], label=LABELS["nominal"])
        ax.plot(t, model[:, j], lw=0.6, color=COLORS["model"], label=LABELS["model"])
        _shade(ax, res)
        for w in res.where:
            if w.channel == ch:
                ax.axvspan(w.t0, w.t1, color="orange", alpha=0.25, lw=0)
        lo, hi = np.nanpercentile(base[:, j], [0.5, 99.5])  # robust limits: spikes clipped
        pad = 0.25 * max(hi - lo, 1e-9)
        ax.set_ylim(lo - pad, hi + pad)
        ax.set_ylabel(f"{ch}\n[{channel_unit(ch)}]", fontsize=8)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[0, 0].set_title(
        "held-out residuals (block means; 0.5-99.5 percentile range). Grey: "
        "not free flight (excluded); hatched: calibration segment; orange: "
        "located intervals",
        fontsize=8,
    )
    axes[-1, 0].set_xlabel("t [s]")
    fig.tight_layout()
    atomic_savefig(fig, path, force=force, dpi=90)
    plt.close(fig)


def _binned(var, y, edges):
    idx = np.clip(np.searchsorted(edges, var, side="right") - 1, 0, len(edges) - 2)
    out = []
    for b in range(len(edges) - 1):
        sel = y[idx == b]
        if sel.size:
            out.append((0.5 * (edges[b] + edges[b + 1]), *np.percentile(sel, [25, 50, 75])))
    return np.array(out)


def _regimes_png(res: DiagnosisResult, path, force):
    plt = _plt()
    s = res.series
    variables = regime_variables(s["replay"])
    rows = s.get("scored")
    regs = [(r["channel"], r["variable"], r["unit"], r["correlation"]) for r in res.regimes]
    if not regs:  # nothing disagrees: show the largest residuals against thrust level
        z = np.sqrt(np.mean((s["baseline"] / np.asarray(res.scale)) ** 2, axis=0))
        regs = [(res.channels[j], "thrust_level", "T/(m g)", None) for j in np.argsort(-z)[:2]]
    regs = regs[:6]
    fig, axes = plt.subplots(1, len(regs), figsize=(4.2 * len(regs), 3.6), squeeze=False)
    for ax, (ch, name, unit, corr) in zip(axes[0], regs):
        j = list(res.channels).index(ch)
        var = variables[name]
        keep = np.ones(len(var), bool) if rows is None else rows
        edges = np.unique(np.quantile(var[keep], np.linspace(0, 1, REGIME_BINS + 1)))
        if len(edges) < 2:
            edges = np.array([var.min(), var.max() + 1e-9])
        for key, arr in (("nominal", s["baseline"]), ("model", s["model"])):
            b = _binned(var[keep], arr[keep, j], edges)
            if len(b):
                ax.fill_between(b[:, 0], b[:, 1], b[:, 3], color=COLORS[key], alpha=0.2, lw=0)
                ax.plot(b[:, 0], b[:, 2], "o-", ms=3, color=COLORS[key], label=LABELS[key])
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel(f"{name} [{unit}]")
        ax.set_ylabel(f"{ch} residual [{channel_unit(ch)}]")
        ax.set_title(
            f"median and quartiles in {REGIME_BINS} bins"
            + ("" if corr is None else f"; |corr| = {corr:.2f}"),
            fontsize=8,
        )
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    atomic_savefig(fig, path, force=force, dpi=90)
    plt.close(fig)


def _prediction_png(res: DiagnosisResult, path, force):
    plt = _plt()
    pred = res.series.get("prediction") or {}
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    if not pred:
        for ax in axes:
            ax.text(
                0.5,
                0.5,
                "no free-flight stretch long enough for a prediction",
                ha="center",
                va="center",
            )
            ax.set_axis_off()
    else:
        key = "position_rmse_m" if "position_rmse_m" in pred else "attitude_rmse_deg"
        unit = "position error RMS [m]" if key == "position_rmse_m" else "attitude error RMS [deg]"
        h = pred["horizons_s"]
        for label, errs in pred[key].items():
            axes[0].plot(h, errs, "o-", color=COLORS[label], label=LABELS[label])
        axes[0].set_xlabel("prediction horizon [s]")
        axes[0].set_ylabel(unit)
        axes[0].set_yscale("log")
        axes[0].legend(fontsize=8)
        axes[0].grid(alpha=0.3, which="both")
        axes[0].set_title(
            f"held-out open-loop prediction from {pred['n_starts']} recorded states", fontsize=9
        )
        ot = pred["_over_time"]
        for label in ("nominal", "model"):
            axes[1].plot(
                ot["t"], ot[label], ".-", ms=3, lw=0.7, color=COLORS[label], label=LABELS[label]
            )
        _shade(axes[1], res)
        axes[1].set_xlabel("start time t [s]")
        axes[1].set_ylabel(ot["quantity"])
        axes[1].set_title(f"error after {ot['horizon_s']:.2f} s over the flight", fontsize=9)
        axes[1].legend(fontsize=8)
        axes[1].grid(alpha=0.3)
    fig.tight_layout()
    atomic_savefig(fig, path, force=force, dpi=90)
    plt.close(fig)


def write_report(
    res: DiagnosisResult, out_dir, *, source: str = "recording", force: bool = False
) -> Path:
    """Write ``report.md`` and the PNG plots into ``out_dir`` (created if missing)."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise QuadfaultError(f"{out}: exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    check_writable([out / f for f in FILES], force=force)
    _residuals_png(res, out / "residuals.png", force)
    _regimes_png(res, out / "regimes.png", force)
    _prediction_png(res, out / "prediction.png", force)
    atomic_write_text(out / "report.md", markdown(res, source), force=force)
    return out
