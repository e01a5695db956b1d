"""Matplotlib rendering of a QuadFaultEnv: the vehicle, its path and eta_hat vs the truth.

``rgb_array`` draws on an off-screen Agg canvas and returns an ``(H, W, 3)`` uint8 frame;
``human`` draws the same figure in a pyplot window and falls back silently to off-screen
drawing when no display is available (headless machines never crash).

The 3-D view uses right-handed east-north-up axes for readability (x = east = p_y,
y = north = p_x, up = -p_z of the internal NED position).
"""

from __future__ import annotations

import numpy as np

from quad_fault_env.observation import SD_MAX

FIGSIZE = (9.0, 4.0)  # [in]
DPI = 80


def _rotor_positions(vehicle) -> np.ndarray:
    """Rotor (x, y) in the body frame [m] from the allocation rows Mx = -y f, My = x f."""
    A = vehicle.allocation
    return np.stack((A[2], -A[1]), axis=-1)


class FlightRenderer:
    """Draws the state of an env; one figure reused for every frame."""

    def __init__(self, vehicle, human: bool = False):
        import matplotlib

        self.rotors = _rotor_positions(vehicle)
        self.human = False
        if human:
            import matplotlib.pyplot as plt

            if matplotlib.get_backend().lower() not in ("agg", "pdf", "svg", "ps", "cairo",
                                                        "template"):
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
        self.ax3d = self.fig.add_axes([0.0, 0.02, 0.5, 0.9], projection="3d")
        self.axbar = self.fig.add_axes([0.6, 0.12, 0.37, 0.76])

    @staticmethod
    def _up(p):
        """NED -> (east, north, up) for plotting."""
        p = np.asarray(p, dtype=float)
        return np.stack((p[..., 1], p[..., 0], -p[..., 2]), axis=-1)

    def draw(self, env) -> np.ndarray:
        ax, bar = self.ax3d, self.axbar
        ax.cla()
        bar.cla()
        state = env.plant.state
        t = env.time
        path = self._up(np.array(env.history))
        ts = np.linspace(0.0, max(env.scenario.duration, 1e-3), 200)
        ref = self._up(env.scenario.trajectory(ts).position)
        ax.plot(path[:, 0], path[:, 1], path[:, 2], color="tab:blue", lw=1.5, label="flown")
        ax.plot(ref[:, 0], ref[:, 1], ref[:, 2], color="0.5", lw=1, ls="--", label="reference")
        # the vehicle: arms from the centre to each rotor, drawn in the world frame
        p = np.asarray(state.p, dtype=float)
        scale = 2.0  # exaggerate the arms so the attitude is visible [-]
        arms = np.concatenate((self.rotors, np.zeros((len(self.rotors), 1))), axis=1) * scale
        tips = self._up(p + arms @ np.asarray(state.R).T)
        c = self._up(p)
        for i, tip in enumerate(tips):
            ax.plot([c[0], tip[0]], [c[1], tip[1]], [c[2], tip[2]], color="k", lw=2)
            ax.text(tip[0], tip[1], tip[2], str(i + 1), fontsize=7)
        lo = np.minimum(ref.min(0), path.min(0)) - 0.5
        hi = np.maximum(ref.max(0), path.max(0)) + 0.5
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(min(lo[2], 0.0), hi[2])
        ax.set_xlabel("east [m]", fontsize=7)
        ax.set_ylabel("north [m]", fontsize=7)
        ax.set_zlabel("up [m]", fontsize=7, labelpad=-2)
        ax.legend(fontsize=6, loc="upper left")
        ax.tick_params(labelsize=6)
        ax.set_title(f"{env.scenario.name}  t = {t:5.2f} s", fontsize=9)
        # eta_hat (with one-sigma bars) vs the true efficiency
        est = env._estimate
        eta_hat = np.asarray(est.eta, dtype=float)
        eta_true = np.asarray(env.scenario.efficiency(t), dtype=float)
        sd = est.sd
        err = None if sd is None else np.minimum(np.asarray(sd, dtype=float), SD_MAX)
        idx = np.arange(len(eta_hat))
        bar.bar(idx - 0.2, eta_true, width=0.4, color="0.6", label="true")
        bar.bar(idx + 0.2, eta_hat, width=0.4, color="tab:orange", yerr=err, capsize=3,
                label=f"estimate ({getattr(env.estimator, 'name', 'custom')})")
        bar.set_xticks(idx, [f"M{i + 1}" for i in idx])
        bar.set_ylim(0.0, 1.3)
        bar.axhline(1.0, color="k", lw=0.5, ls=":")
        bar.set_ylabel("motor efficiency [-]", fontsize=8)
        bar.legend(fontsize=7, loc="lower right")
        bar.set_title(f"estimator status: {est.status}", fontsize=9)
        self.fig.canvas.draw()
        frame = np.asarray(self.fig.canvas.buffer_rgba())[..., :3].copy()
        if self.human:
            import matplotlib.pyplot as plt

            plt.pause(1e-3)
        return frame

    def close(self):
        if self.human:
            import matplotlib.pyplot as plt

            plt.close(self.fig)
        self.fig = None
