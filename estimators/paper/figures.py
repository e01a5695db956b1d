"""Figures of ``quadfault reproduce``, after the paper's (matplotlib, Agg backend).

Every function takes plain arrays / dicts and a target path, and writes one PNG atomically
(``quadfault.fileio.atomic_savefig``).
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np

from quadfault.fileio import atomic_savefig

COLORS = {
    "irls": "tab:blue",
    "ekf": "tab:orange",
    "truth": "tab:red",
    "irls_median": "tab:cyan",
    "ekf_median": "tab:pink",
    "irls_improved": "tab:green",
    "ekf_improved": "tab:brown",
}
#: one label per series: the two median-filtered EKFs are different partners (each with the
#: Q_eta chosen for its IRLS variant)
LABELS = {
    "irls": "IRLS (proposed)",
    "ekf": "EKF (partner of IRLS)",
    "irls_median": "IRLS + median 21",
    "ekf_median": "EKF + median 21 (partner of IRLS + median)",
    "irls_improved": "IRLS improved (ours)",
    "ekf_improved": "EKF + median 21 (partner of IRLS improved)",
}
ORDER = ("irls", "ekf", "irls_median", "ekf_median", "irls_improved", "ekf_improved")


DPI = 120


def _present(d: dict) -> list[str]:
    return [k for k in ORDER if k in d]


def _save(fig, path, force):
    fig.tight_layout()
    atomic_savefig(fig, path, force=force, dpi=DPI)
    plt.close(fig)


def _save_with_legend_below(fig, ax, path, force):
    """Save with ``ax``'s legend under the axes, where it hides no bar."""
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(
        handles, labels, loc="lower center", ncol=min(len(labels), 3), fontsize=8, frameon=False
    )
    rows = -(-len(labels) // 3)
    fig.tight_layout(rect=(0, 0.045 * rows + 0.02, 1, 1))
    atomic_savefig(fig, path, force=force, dpi=DPI)
    plt.close(fig)


def _shade(ax, windows, motor=None):
    for m, t0, t1 in windows:
        if motor is None or m == motor:
            ax.axvspan(t0, t1 if np.isfinite(t1) else ax.get_xlim()[1], color="0.9", zorder=0)


def plot_estimates(path, series: dict, windows, title: str, force: bool = False):
    """Estimates vs truth per motor; EKF left, IRLS right (the paper's Figs. 3-5)."""
    t = series["t"]
    fig, axes = plt.subplots(4, 2, figsize=(11, 8), sharex=True, sharey=True)
    for col, est in enumerate(("ekf", "irls")):
        for m in range(4):
            ax = axes[m, col]
            _shade(ax, windows, m + 1)
            ax.plot(t, series[est][:, m], color=COLORS[est], lw=0.8, label="estimated")
            ax.plot(t, series["truth"][:, m], color=COLORS["truth"], lw=1.0, label="true")
            ax.set_ylim(0.2, 1.2)
            ax.grid(alpha=0.3)
            if col == 0:
                ax.set_ylabel(f"$\\eta_{m + 1}$")
        axes[0, col].set_title(f"{LABELS[est]}: {title}")
        axes[3, col].set_xlabel("time [s]")
    axes[0, 0].legend(loc="lower left", ncol=2, fontsize=8)
    _save(fig, path, force)


def plot_errors(path, series: dict, windows, title: str, force: bool = False):
    """Signed error eta_true - eta_hat per motor, both estimators overlaid."""
    t = series["t"]
    fig, axes = plt.subplots(4, 1, figsize=(10, 8), sharex=True, sharey=True)
    for m in range(4):
        ax = axes[m]
        _shade(ax, windows)
        for est in [k for k in ("ekf", "irls", "ekf_improved", "irls_improved") if k in series]:
            ax.plot(
                t,
                series["truth"][:, m] - series[est][:, m],
                color=COLORS[est],
                lw=0.7,
                label=LABELS[est],
                alpha=0.85,
            )
        ax.set_ylabel(f"$e_{m + 1}$")
        ax.grid(alpha=0.3)
    axes[0].set_title(f"estimation error, {title} (grey: fault windows)")
    axes[0].legend(loc="upper right", fontsize=8, ncol=2)
    axes[-1].set_xlabel("time [s]")
    _save(fig, path, force)


def plot_rmse_std(path, scenarios: dict, force: bool = False):
    """Motor-averaged RMSE and std per scenario (the paper's Fig. 6)."""
    names = list(scenarios)
    x = np.arange(len(names))
    ests = _present(scenarios[names[0]]) if names else []
    width = 0.76 / max(len(ests), 1)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.6))
    for ax, key, label in ((axes[0], "rmse", "RMSE"), (axes[1], "std", "std. dev.")):
        for i, est in enumerate(ests):
            vals = [np.mean(scenarios[n][est][key]) for n in names]
            ax.bar(
                x + (i - (len(ests) - 1) / 2) * width,
                vals,
                width,
                color=COLORS[est],
                label=LABELS[est],
            )
        ax.set_xticks(x, names)
        ax.set_ylabel(label)
        ax.grid(axis="y", alpha=0.3)
    _save_with_legend_below(fig, axes[0], path, force)


def plot_spikes(path, scenarios: dict, force: bool = False):
    """Per-motor max spike in the other motors' fault windows (the paper's Fig. 7)."""
    names = [n for n in scenarios if scenarios[n]["irls"]["spike"] is not None]
    fig, axes = plt.subplots(
        1, max(len(names), 1), figsize=(4.2 * max(len(names), 1), 4.6), squeeze=False
    )
    x = np.arange(4)
    for ax, name in zip(axes[0], names):
        ests = _present(scenarios[name])
        width = 0.76 / len(ests)
        for i, est in enumerate(ests):
            vals = [np.nan if v is None else v for v in scenarios[name][est]["spike"]]
            ax.bar(
                x + (i - (len(ests) - 1) / 2) * width,
                vals,
                width,
                color=COLORS[est],
                label=LABELS[est],
            )
        ax.set_xticks(x, [f"M{m + 1}" for m in x])
        ax.set_title(name)
        ax.set_ylabel("max |error| in others' windows")
        ax.grid(axis="y", alpha=0.3)
    _save_with_legend_below(fig, axes[0][0], path, force)


def plot_calibration(path, calibrations: dict, force: bool = False):
    """EKF RMSE vs Q_eta (the U-curve), the IRLS target and the chosen Q_eta."""
    fig, ax = plt.subplots(figsize=(6.5, 4))
    for mode, cal in calibrations.items():
        (line,) = ax.loglog(cal["curve_q"], cal["curve_rmse"], "o-", ms=3, label=f"EKF ({mode})")
        ax.axhline(
            cal["target_rmse"],
            color=line.get_color(),
            ls="--",
            lw=0.8,
            label=f"IRLS target ({mode})",
        )
        ax.plot([cal["q_eta"]], [cal["rmse"]], "*", ms=12, color=line.get_color())
    ax.set_xlabel("$Q_\\eta$ per 1 ms step")
    ax.set_ylabel("RMSE (motor average)")
    ax.set_title("EKF calibration on the calibration flight")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    _save(fig, path, force)


def plot_convergence(path, history: dict, force: bool = False):
    """Efficiency iterates of one interior-point loop started from eta = 0.5."""
    xs = np.asarray(history["x_history"])
    fig, ax = plt.subplots(figsize=(6.5, 4))
    for m in range(xs.shape[1]):
        (line,) = ax.plot(np.arange(len(xs)), xs[:, m], "o-", ms=3, label=f"$\\eta_{m + 1}$")
        ax.axhline(history["truth"][m], color=line.get_color(), ls=":", lw=0.8)
    ax.set_xlabel("interior-point iteration")
    ax.set_ylabel("efficiency")
    ax.set_title(f"IRLS window ending at t = {history['t']:.3f} s (dotted: truth)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    _save(fig, path, force)


def plot_kkt(path, history: dict, force: bool = False):
    """KKT residual norms and surrogate gap per interior-point iteration, every IRLS round."""
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.8))
    for ax, key, label in (
        (axes[0], "dual", "$\\|r_{dual}\\|$"),
        (axes[1], "cent", "$\\|r_{cent}\\|$"),
        (axes[2], "gap", "surrogate gap"),
    ):
        for r, h in enumerate(history[key] or ()):
            h = np.maximum(np.asarray(h, dtype=float), 1e-16)
            ax.semilogy(np.arange(1, len(h) + 1), h, "o-", ms=3, label=f"IRLS round {r + 1}")
        ax.axhline(1e-6, color="0.5", ls="--", lw=0.8)
        ax.set_xlabel("interior-point iteration")
        ax.set_title(label)
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=8)
    _save(fig, path, force)
