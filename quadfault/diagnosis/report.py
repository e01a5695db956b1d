"""``report.md`` and PNG plots of a diagnosis (matplotlib, Agg backend).

Plots: ``residuals.png`` (normalised residual per channel over time, located intervals
shaded, nominal vs diagnosed model), ``regimes.png`` (residual against the regime variable
that explains it best, per disagreeing channel), ``prediction.png`` (open-loop position
error over the horizon, nominal vs diagnosed).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quadfault.diagnosis.locate import regime_variables
from quadfault.diagnosis.residuals import channel_unit
from quadfault.diagnosis.result import DiagnosisResult
from quadfault.fileio import atomic_savefig, atomic_write_text, check_writable

FILES = ("report.md", "residuals.png", "regimes.png", "prediction.png")


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _residuals_png(res: DiagnosisResult, path, force):
    plt = _plt()
    s = res.series
    t, base, model = s["block_t"], s["baseline"], s["model"]
    fig, axes = plt.subplots(len(res.channels), 1, figsize=(10, 11), sharex=True)
    for j, (ax, ch) in enumerate(zip(axes, res.channels)):
        ax.plot(t, base[:, j], lw=0.6, color="tab:red", label="nominal model")
        ax.plot(t, model[:, j], lw=0.6, color="tab:blue", label="with diagnosed effects")
        for w in res.where:
            if w.channel == ch:
                ax.axvspan(w.t0, w.t1, color="orange", alpha=0.25)
        lo, hi = np.percentile(base[:, j], [0.5, 99.5])  # robust limits: spikes clipped
        pad = 0.25 * max(hi - lo, 1e-9)
        ax.set_ylim(lo - pad, hi + pad)
        ax.set_ylabel(f"{ch}\n[{channel_unit(ch)}]", fontsize=8)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[0].set_title("held-out residuals (block means, 0.5-99.5 percentile range); "
                      "shaded: located intervals", fontsize=9)
    axes[-1].set_xlabel("t [s]")
    fig.tight_layout()
    atomic_savefig(fig, path, force=force, dpi=90)
    plt.close(fig)


def _regimes_png(res: DiagnosisResult, path, force):
    plt = _plt()
    s = res.series
    variables = regime_variables(s["replay"])
    regs = list(res.regimes) or []
    n = max(1, len(regs))
    fig, axes = plt.subplots(1, n, figsize=(4.5 * n, 3.8), squeeze=False)
    if not regs:
        axes[0, 0].text(0.5, 0.5, "no channel disagrees beyond noise", ha="center")
        axes[0, 0].set_axis_off()
    for ax, r in zip(axes[0], regs):
        j = list(res.channels).index(r["channel"])
        ax.plot(variables[r["variable"]], s["baseline"][:, j], ".", ms=2, alpha=0.4,
                color="tab:red", label="nominal")
        ax.plot(variables[r["variable"]], s["model"][:, j], ".", ms=2, alpha=0.4,
                color="tab:blue", label="diagnosed")
        ax.set_xlabel(f"{r['variable']} [{r['unit']}]")
        ax.set_ylabel(f"{r['channel']} residual [{channel_unit(r['channel'])}]")
        ax.set_title(f"|corr| = {r['correlation']:.2f}", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, markerscale=4)
    fig.tight_layout()
    atomic_savefig(fig, path, force=force, dpi=90)
    plt.close(fig)


def _prediction_png(res: DiagnosisResult, path, force):
    plt = _plt()
    pred = res.series.get("prediction") or {}
    fig, ax = plt.subplots(figsize=(6, 4))
    if "_curves" in pred:
        for label, color in (("nominal", "tab:red"), ("model", "tab:blue")):
            ax.plot(pred["_curve_t"], pred["_curves"][label], color=color,
                    label="nominal model" if label == "nominal" else "with diagnosed effects")
        ax.set_xlabel("prediction horizon [s]")
        ax.set_ylabel("position error RMS [m]")
        ax.legend()
        ax.grid(alpha=0.3)
        ax.set_title(f"open-loop prediction from {pred['n_starts']} recorded states")
    else:
        ax.text(0.5, 0.5, "no pose: open-loop prediction not available", ha="center")
        ax.set_axis_off()
    fig.tight_layout()
    atomic_savefig(fig, path, force=force, dpi=90)
    plt.close(fig)


def _markdown(res: DiagnosisResult, source: str) -> str:
    L = [f"# Model-mismatch diagnosis of `{source}`", "",
         f"**Verdict: {res.verdict}.** Held-out residual RMS reduced by "
         f"{100 * res.model_improvement:.1f}% with the accepted effects "
         f"({res.seconds:.1f} s).", ""]
    sc = res.scoring or {}
    if sc.get("excluded_s"):
        segs = ", ".join(f"{a:.2f}-{b:.2f} s" for a, b in sc["excluded_s"])
        L += [f"Held-out scores use {sc['scored_blocks']} of {sc['blocks']} blocks: the "
              f"calibration segment {segs} (where the importer fitted constants) is fitted on "
              "but never scored.", ""]
    elif sc.get("note"):
        L += [f"Scoring: {sc['note']}.", ""]
    L += ["## Effects", ""]
    if res.effects:
        L += ["| effect | parameters | 1-sigma | held-out improvement | explanation |",
              "|---|---|---|---|---|"]
        for e in res.effects:
            L.append(f"| {e.name} | {_fmt(e.params)} | {_fmt(e.uncertainty)} | "
                     f"{100 * e.improvement:.1f}% | {e.explanation} |")
    else:
        L.append("None: no candidate improved held-out residuals by a meaningful margin.")
    L += ["", "## Residual RMS per channel (held out)", "",
          "| channel | nominal | diagnosed model | noise scale |", "|---|---|---|---|"]
    for ch, sc in zip(res.channels, res.scale):
        L.append(f"| {ch} [{channel_unit(ch)}] | {res.baseline_rmse[ch]:.4g} | "
                 f"{res.model_rmse[ch]:.4g} | {sc:.3g} |")
    L += ["", "![residuals](residuals.png)", "", "## Where", ""]
    if res.where:
        L += ["| channel | t0 [s] | t1 [s] | note |", "|---|---|---|---|"]
        L += [f"| {w.channel} | {w.t0:.2f} | {w.t1:.2f} | {w.note} |" for w in res.where]
    else:
        L.append("No interval where the nominal model exceeds 4x the smoothed noise.")
    L += ["", "## Regimes", ""]
    for r in res.regimes:
        bins = ", ".join(f"[{a:.3g}, {b:.3g}]: {c:.3g}" for a, b, c in r["bins_lo_hi_rms"])
        others = ", ".join(f"{k} {v:.2f}" for k, v in sorted(r["all"].items(), key=lambda kv: -kv[1]))
        L.append(f"- **{r['channel']}** follows **{r['variable']}** [{r['unit']}] "
                 f"(|corr| {r['correlation']:.2f}; all: {others}). Residual RMS per bin: {bins}.")
    if not res.regimes:
        L.append("No channel disagrees beyond 1.5x its noise scale.")
    L += ["", "![regimes](regimes.png)", "", "## Open-loop prediction", ""]
    p = res.prediction
    if p:
        L.append(f"From {p['n_starts']} recorded states, horizon {p['horizon_s']:.2f} s:")
        L.append("")
        L += ["| error at horizon | nominal | diagnosed |", "|---|---|---|"]
        for key in ("position_rmse_m", "velocity_rmse_m_per_s", "attitude_rmse_deg"):
            L.append(f"| {key} | {p[key]['nominal']:.4g} | {p[key]['model']:.4g} |")
    else:
        L.append("Not available (no pose in the recording).")
    L += ["", "![prediction](prediction.png)", ""]
    if res.untestable:
        L += ["## Untestable", "", "This recording cannot reveal: " + ", ".join(res.untestable)
              + " (they need position, velocity and attitude).", ""]
    return "\n".join(L)


def _fmt(d: dict) -> str:
    def one(v):
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(f"{x:.4g}" for x in v) + "]"
        return f"{v:.4g}" if isinstance(v, float) else str(v)

    return "; ".join(f"{k} = {one(v)}" for k, v in d.items())


def write_report(res: DiagnosisResult, out_dir, *, source: str = "recording",
                 force: bool = False) -> Path:
    """Write ``report.md`` and the PNG plots into ``out_dir`` (created if missing)."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        from quadfault.errors import QuadfaultError

        raise QuadfaultError(f"{out}: exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    check_writable([out / f for f in FILES], force=force)
    _residuals_png(res, out / "residuals.png", force)
    _regimes_png(res, out / "regimes.png", force)
    _prediction_png(res, out / "prediction.png", force)
    atomic_write_text(out / "report.md", _markdown(res, source), force=force)
    return out
