"""Figures comparing agents through a fault (matplotlib, Agg backend)."""

from __future__ import annotations

import math

import numpy as np

from quadfault.fileio import atomic_savefig


def _figure(nrows: int, row_height: float = 2.6):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(nrows, 1, figsize=(8, row_height * nrows), sharex=True)
    return plt, fig, np.atleast_1d(axes)


def plot_through_fault(
    flights, path, *, force: bool = False, before: float = 1.0, after: float = 5.0
):
    """Position error, tilt error and eta_hat of the faulted motor for each flight around
    the first fault onset of their (common) scenario; the whole flight without a fault."""
    if not flights:
        return None
    onsets = _onsets(flights)
    t0, t1 = -math.inf, math.inf
    motor = 0
    if onsets:
        tf, motor = onsets[0]
        t0, t1 = tf - before, tf + after
    plt, fig, (ax_e, ax_tilt, ax_eta) = _figure(3)
    for f in flights:
        sel = (f.t >= t0) & (f.t <= t1)
        label = f.controller + (" (crashed)" if f.metrics.crashed else "")
        ax_e.plot(f.t[sel], f.pos_error[sel], label=label)
        ax_tilt.plot(f.t[sel], f.tilt_error[sel], label=label)
        ax_eta.plot(f.t[sel], f.eta_hat[sel, motor], label=label)
    ref = flights[0]
    sel = (ref.t >= t0) & (ref.t <= t1)
    ax_eta.plot(ref.t[sel], ref.eta_true[sel, motor], "k--", label="true (scoring only)")
    for ax in (ax_e, ax_tilt, ax_eta):
        if onsets:
            ax.axvline(onsets[0][0], color="grey", lw=0.8)
        ax.grid(alpha=0.3)
    ax_e.set_ylabel("|p - p_ref| [m]")
    ax_tilt.set_ylabel("tilt error [deg]")
    ax_eta.set_ylabel(f"eta_hat motor {motor + 1}")
    ax_eta.set_xlabel("t [s]")
    ax_e.legend(fontsize=7, loc="upper right")
    ax_e.set_title(f"{ref.scenario}, seed {ref.seed}: through the first fault")
    fig.tight_layout()
    out = atomic_savefig(fig, path, force=force, dpi=110)
    plt.close(fig)
    return out


def _onsets(flights):
    """(onset [s], motor index) of the first fault, from the true-efficiency trace (scoring)."""
    f = flights[0]
    if f.eta_true.size == 0:
        return []
    drop = np.diff(f.eta_true, axis=0) < -0.05
    idx = np.argwhere(drop)
    if idx.size == 0:
        return []
    k, motor = idx[0]
    return [(float(f.t[k + 1]), int(motor))]


def plot_learning_curve(
    timesteps,
    returns,
    path,
    *,
    baseline: float | None = None,
    label: str = "policy",
    title: str = "learning curve",
    force: bool = False,
):
    """Evaluation return against environment steps.

    ``returns``: ``(n_seeds, n_evaluations)`` mean evaluation returns, one row per training
    seed, all evaluated at ``timesteps``. Draws their mean and, with several seeds, the band
    between the lowest and the highest seed; ``baseline`` (the geometric controller's mean
    return on the same episodes) as a dashed horizontal line."""
    returns = np.atleast_2d(np.asarray(returns, float))
    ts = np.asarray(timesteps)
    plt, fig, (ax,) = _figure(1, 4.0)
    n = returns.shape[0]
    line_label = label if n == 1 else f"{label}: mean of {n} seeds (band: lowest to highest)"
    (line,) = ax.plot(ts, returns.mean(axis=0), marker="o", label=line_label)
    if n > 1:
        ax.fill_between(
            ts, returns.min(axis=0), returns.max(axis=0), color=line.get_color(), alpha=0.25, lw=0
        )
    if baseline is not None:
        ax.axhline(
            baseline, color="k", ls="--", lw=1.2, label="geometric controller (same episodes)"
        )
    ax.ticklabel_format(axis="y", useOffset=False)
    ax.set_xlabel("environment steps")
    ax.set_ylabel("mean evaluation return")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    out = atomic_savefig(fig, path, force=force, dpi=110)
    plt.close(fig)
    return out
