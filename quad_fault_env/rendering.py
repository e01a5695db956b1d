"""Rendering of a QuadFault flight: top view, altitude against time, eta_hat vs the truth.

One frame (:data:`FIGSIZE` at :data:`DPI`: 800 x 320 pixels) has three panels:

* **top view** (east right, north up, metres): the reference path (grey, dashed), the flown
  path (blue) and the vehicle's arms in the world frame, rotor numbers at their tips;
* **altitude** [m] against time [s]: the reference altitude of the whole episode, the flown
  altitude so far, the ground (brown band below ``TerminationLimits.ground_altitude``) and a
  cursor at the current time, so height and sink rate read off a scale;
* **motor efficiency**: the estimate (orange, one-sigma error bars) beside the truth (grey).

A terminated episode is marked on the frame: a red cross where it ended, in both the top
view and the altitude panel, and a red banner with the reason (``CRASH: below the ground``,
``out_of_bounds``, ``excessive_tilt``, ``non_finite``) and the time. The reason comes from the
environment's own rule (:meth:`~quad_fault_env.envs.config.TerminationLimits.reason`).

Speed: the static parts (axes, labels, reference, ground, legend) are drawn once per episode
on an off-screen matplotlib Agg canvas and kept as a background; each frame restores it and
draws only the moving artists over it (blitting). The axes are redrawn only when the vehicle
leaves the current limits. ``python benchmarks/bench_render.py`` prints the time per frame.

``rgb_array`` returns an ``(H, W, 3)`` uint8 frame. ``human`` shows the same figure in a
pyplot window (blitted to the screen) and falls back silently to off-screen drawing when no
display is available (headless machines never crash).

The renderer draws a :class:`FrameState` (what one frame shows); :func:`frame_state` builds one
from a ``QuadFaultEnv``, so any flight (a vector env's row, a recording) can be drawn by
building its ``FrameState``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quad_fault_env.observation import SD_MAX

FIGSIZE = (10.0, 4.0)  # [in]
DPI = 80
MARGIN = 0.5  # [m] around the reference in the top view
REASONS = {
    "crash": "CRASH: below the ground",
    "out_of_bounds": "out of bounds",
    "excessive_tilt": "excessive tilt",
    "non_finite": "non-finite state",
}
ARM_SCALE = 2.0  # the arms are drawn this many times longer, so the attitude is visible [-]


@dataclass(frozen=True)
class FrameState:
    """What one frame shows (NED world frame, SI units).

    Attributes:
        t: time [s].
        path: positions flown so far, one row per control step from the episode's start
            [m] (the last row is the vehicle now).
        path_t: their times [s].
        R: attitude, body (FRD) to world (NED).
        eta_hat: estimated efficiency per motor [-]; eta_sd its one-sigma uncertainty or None.
        eta_true: true efficiency per motor at ``t`` [-].
        status: the estimator's status; estimator: its name.
        reason: why the episode terminated (``info["termination_reason"]``), or None.
        scenario: the scenario (its name, duration and trajectory give the reference).
        ground_altitude: altitude of the ground [m].
    """

    t: float
    path: np.ndarray
    path_t: np.ndarray
    R: np.ndarray
    eta_hat: np.ndarray
    eta_sd: np.ndarray | None
    eta_true: np.ndarray
    status: str
    estimator: str
    reason: str | None
    scenario: object
    ground_altitude: float


def frame_state(env) -> FrameState:
    """The :class:`FrameState` of a ``QuadFaultEnv`` after its latest reset or step."""
    state, sc, t = env.plant.state, env.scenario, env.time
    path = np.asarray(env.history, dtype=float).reshape(-1, 3)
    est = env._estimate
    sd = None if est.sd is None else np.asarray(est.sd, dtype=float)
    reason = env.limits.reason(state.p, state.R, sc.trajectory(t).position)
    return FrameState(
        t,
        path,
        np.arange(len(path)) * env.control_period,
        np.asarray(state.R),
        np.asarray(est.eta, dtype=float),
        sd,
        np.asarray(sc.efficiency(t), dtype=float),
        str(est.status),
        getattr(env.estimator, "name", "custom"),
        reason,
        sc,
        float(env.limits.ground_altitude),
    )


def _rotor_positions(vehicle) -> np.ndarray:
    """Rotor (x, y) in the body frame [m] from the allocation rows Mx = -y f, My = x f."""
    A = vehicle.allocation
    return np.stack((A[2], -A[1]), axis=-1)


def _padded(lo, hi, pad):
    return float(lo) - pad, float(hi) + pad


class FlightRenderer:
    """Draws :class:`FrameState` s of one vehicle; one figure reused for every frame."""

    def __init__(self, vehicle, human: bool = False):
        import matplotlib

        self.rotors = _rotor_positions(vehicle)
        self.human = False
        if human:
            import matplotlib.pyplot as plt

            if matplotlib.get_backend().lower() not in (
                "agg",
                "pdf",
                "svg",
                "ps",
                "cairo",
                "template",
            ):
                try:
                    plt.ion()
                    self.fig = plt.figure(figsize=FIGSIZE, dpi=DPI)
                    self.human = True
                except Exception:  # no display: draw off-screen instead
                    self.human = False
        if not self.human:
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure

            self.fig = Figure(figsize=FIGSIZE, dpi=DPI)
            FigureCanvasAgg(self.fig)
        self._build()
        self._scenario = None
        self._background = None

    # -- layout: static axes and the moving artists --------------------------------------
    def _build(self) -> None:
        fig = self.fig
        self.ax_top = fig.add_axes([0.055, 0.13, 0.26, 0.72])
        self.ax_alt = fig.add_axes([0.39, 0.13, 0.30, 0.72])
        self.ax_eta = fig.add_axes([0.765, 0.13, 0.22, 0.72])
        top, alt, eta = self.ax_top, self.ax_alt, self.ax_eta
        top.set_aspect("equal", adjustable="box")
        top.set_xlabel("east [m]", fontsize=8)
        top.set_ylabel("north [m]", fontsize=8, labelpad=1)
        top.set_title("top view", fontsize=9)
        alt.set_xlabel("t [s]", fontsize=8)
        alt.set_ylabel("altitude [m]", fontsize=8, labelpad=1)
        alt.set_title("altitude", fontsize=9)
        for ax in (top, alt, eta):
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
        (self.ref_top,) = top.plot([], [], color="0.5", lw=1, ls="--", label="reference")
        (self.ref_alt,) = alt.plot([], [], color="0.5", lw=1, ls="--", label="reference")
        a = dict(animated=True)
        (self.path_top,) = top.plot([], [], color="tab:blue", lw=1.3, label="flown", **a)
        (self.path_alt,) = alt.plot([], [], color="tab:blue", lw=1.3, label="flown", **a)
        self.arms = [
            top.plot([], [], color="k", lw=2, solid_capstyle="round", **a)[0] for _ in self.rotors
        ]
        # rotor numbers as marker glyphs (paths: far cheaper to draw than text)
        self.labels = [
            top.plot([], [], marker=f"${i + 1}$", ms=7, color="k", ls="none", **a)[0]
            for i in range(len(self.rotors))
        ]
        self.cursor = alt.axvline(0.0, color="tab:blue", lw=0.8, alpha=0.6, **a)
        (self.end_top,) = top.plot([], [], "x", color="red", ms=12, mew=3, **a)
        (self.end_alt,) = alt.plot([], [], "x", color="red", ms=12, mew=3, **a)
        self.ground = None
        top.legend(fontsize=6, loc="upper right")
        # efficiency bars (moving heights) and one-sigma error bars
        n = len(self.rotors)
        idx = np.arange(n)
        self.bars_true = eta.bar(idx - 0.2, np.ones(n), width=0.4, color="0.6", label="true")
        self.bars_est = eta.bar(
            idx + 0.2, np.ones(n), width=0.4, color="tab:orange", label="estimate"
        )
        from matplotlib.collections import LineCollection

        self.err = LineCollection([], colors="k", linewidths=1, **a)
        eta.add_collection(self.err)
        for b in (*self.bars_true, *self.bars_est):
            b.set_animated(True)
        eta.set_xticks(idx, [f"M{i + 1}" for i in idx])
        eta.set_ylim(0.0, 1.3)
        eta.set_xlim(-0.6, n - 0.4)
        eta.axhline(1.0, color="k", lw=0.5, ls=":")
        eta.set_ylabel("motor efficiency [-]", fontsize=8, labelpad=1)
        eta.legend(fontsize=6, loc="upper center", ncol=2)
        self.eta_title = eta.set_title("", fontsize=9)
        self.name = self.fig.text(0.01, 0.955, "", fontsize=10, va="center", weight="bold")
        self.title = self.fig.text(0.2, 0.955, "", fontsize=10, va="center", **a)
        self.banner = self.fig.text(
            0.99,
            0.955,
            "",
            fontsize=10,
            va="center",
            ha="right",
            color="white",
            weight="bold",
            animated=True,
            bbox=dict(facecolor="red", edgecolor="none", pad=2),
        )
        self._animated = [
            self.path_top,
            self.path_alt,
            *self.arms,
            *self.labels,
            self.cursor,
            *self.bars_true,
            *self.bars_est,
            self.err,
            self.end_top,
            self.end_alt,
            self.title,
            self.banner,
        ]

    def _new_episode(self, s: FrameState) -> None:
        """Static content of an episode: reference, time axis, limits."""
        sc = s.scenario
        duration = max(float(sc.duration), 1e-3)
        ts = np.linspace(0.0, duration, 400)
        ref = np.asarray(sc.trajectory(ts).position, dtype=float)
        self.ref_top.set_data(ref[:, 1], ref[:, 0])
        self.ref_alt.set_data(ts, -ref[:, 2])
        self._ref = ref
        if self.ground is not None:
            self.ground.remove()
        self.ground = self.ax_alt.axhspan(
            s.ground_altitude - 1e3,
            s.ground_altitude,
            color="saddlebrown",
            alpha=0.25,
            lw=0,
            label="ground",
        )
        self.ax_alt.legend(fontsize=6, loc="upper right")
        self._limits = None
        self._duration = duration
        self._scenario = sc
        self.eta_title.set_text(f"estimator: {s.estimator}")
        self.name.set_text(sc.name)

    def _fit_limits(self, s: FrameState) -> bool:
        """Limits that hold the reference, the flight so far and the ground; True when they
        changed (the background must be redrawn)."""
        ref, path = self._ref, s.path
        east = np.concatenate((ref[:, 1], path[:, 1]))
        north = np.concatenate((ref[:, 0], path[:, 0]))
        up = np.concatenate((-ref[:, 2], -path[:, 2], [s.ground_altitude]))
        if self._limits is not None:
            (e0, e1), (n0, n1), (u0, u1) = self._limits
            inside = (
                e0 <= east.min()
                and east.max() <= e1
                and n0 <= north.min()
                and north.max() <= n1
                and u0 <= up.min()
                and up.max() <= u1
            )
            if inside:
                return False
        half = 0.5 * max(np.ptp(east), np.ptp(north), 1.0) * 1.1 + MARGIN  # square view
        ce, cn = 0.5 * (east.min() + east.max()), 0.5 * (north.min() + north.max())
        limits = (
            (ce - half, ce + half),
            (cn - half, cn + half),
            _padded(up.min(), up.max(), max(0.3, 0.15 * np.ptp(up))),
        )
        self._limits = limits
        self.ax_top.set_xlim(*limits[0])
        self.ax_top.set_ylim(*limits[1])
        self.ax_alt.set_xlim(0.0, self._duration)
        self.ax_alt.set_ylim(*limits[2])
        return True

    # -- drawing -------------------------------------------------------------------------
    def draw(self, env) -> np.ndarray:
        """Draw the state of a ``QuadFaultEnv``; returns the frame."""
        return self.draw_state(frame_state(env))

    def draw_state(self, s: FrameState) -> np.ndarray:
        """Draw one :class:`FrameState`; returns the ``(H, W, 3)`` uint8 frame."""
        if s.scenario is not self._scenario:
            self._new_episode(s)
            self._background = None
        if self._fit_limits(s) or self._background is None:
            self.fig.canvas.draw()  # the static parts; animated artists are left out
            self._background = self.fig.canvas.copy_from_bbox(self.fig.bbox)
        self._update(s)
        canvas = self.fig.canvas
        canvas.restore_region(self._background)
        for artist in self._animated:
            self.fig.draw_artist(artist)
        if self.human:
            canvas.blit(self.fig.bbox)
            canvas.flush_events()
        return np.asarray(canvas.buffer_rgba())[..., :3].copy()

    def _update(self, s: FrameState) -> None:
        path, p = s.path, s.path[-1]
        self.path_top.set_data(path[:, 1], path[:, 0])
        self.path_alt.set_data(s.path_t, -path[:, 2])
        self.cursor.set_xdata([s.t, s.t])
        arms = np.concatenate((self.rotors, np.zeros((len(self.rotors), 1))), axis=1)
        tips = p + (arms * ARM_SCALE) @ np.asarray(s.R).T
        for arm, label, tip in zip(self.arms, self.labels, tips):
            arm.set_data([p[1], tip[1]], [p[0], tip[0]])
            label.set_data([tip[1]], [tip[0]])
        for bar, v in zip(self.bars_true, s.eta_true):
            bar.set_height(v)
        for bar, v in zip(self.bars_est, s.eta_hat):
            bar.set_height(v)
        if s.eta_sd is None:
            self.err.set_segments([])
        else:
            sd = np.minimum(s.eta_sd, SD_MAX)
            x = np.arange(len(s.eta_hat)) + 0.2
            self.err.set_segments(
                [((xi, v - e), (xi, v + e)) for xi, v, e in zip(x, s.eta_hat, sd)]
            )
        self.title.set_text(f"t = {s.t:6.2f} s   estimator status: {s.status}")
        if s.reason is None:
            self.end_top.set_data([], [])
            self.end_alt.set_data([], [])
            self.banner.set_visible(False)
        else:
            self.end_top.set_data([p[1]], [p[0]])
            self.end_alt.set_data([s.t], [-p[2]])
            self.banner.set_text(f"{REASONS.get(s.reason, s.reason)} at t = {s.t:.2f} s")
            self.banner.set_visible(True)

    def close(self):
        if self.human:
            import matplotlib.pyplot as plt

            plt.close(self.fig)
        self.fig = None
