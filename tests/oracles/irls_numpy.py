"""The IRLS in readable numpy form: the test oracle of the compiled estimator.

* :func:`segment_models` / :func:`quadratic_terms` -- the affine residual model of every
  segment of a recording at once (paper eqs. 13-26), vectorised;
* :func:`mad_weights` -- the robust weights (eqs. 27-30) with numpy's sort;
* :func:`ipm` -- Algorithm 1 with the full ``3n x 3n`` KKT system of eq. (42) solved by
  ``numpy.linalg.solve`` (the kernel eliminates ``dlambda`` and uses Cholesky);
* :func:`solve_window` -- Algorithm 2 from these pieces;
* :func:`solve_window_scipy` -- the same rounds with each weighted box-constrained least
  squares solved exactly by ``scipy.optimize.minimize`` (an independent cross-check);
* :class:`ChangeCompletion`, :func:`causal_median` -- the options beyond the paper;
* :class:`OnlineIRLS` -- the online rules written plainly over these pieces.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadfault.model.dynamics import E3
from quadfault.model.rotation import cross, vee
from quadfault.model.vehicle import Vehicle

RESIDUAL_ROWS = 10


@dataclass(frozen=True)
class SegmentModels:
    """Affine residual models of consecutive segments: ``r_k(eta) = r0[k] + J[k] @ eta``.

    Attributes:
        r0: residuals at ``eta = 0``, shape (S, 10) [m/s, m, rad/s, 1].
        J: constant Jacobians d r / d eta, shape (S, 10, n).
        dt: segment durations [s], shape (S,).
        thrust: commanded collective thrust of each segment [N], shape (S,).
    """

    r0: np.ndarray
    J: np.ndarray
    dt: np.ndarray
    thrust: np.ndarray

    def __len__(self) -> int:
        return len(self.dt)

    def residuals(self, eta) -> np.ndarray:
        """``(S, 10)`` residuals at efficiency ``eta`` (n,)."""
        return self.r0 + self.J @ np.asarray(eta, dtype=float)

    def window(self, start: int, stop: int) -> SegmentModels:
        sl = slice(start, stop)
        return SegmentModels(self.r0[sl], self.J[sl], self.dt[sl], self.thrust[sl])


#: the arrays of :class:`SegmentModels`
FIELDS = ("r0", "J", "dt", "thrust")


def segment_models(vehicle: Vehicle, t, p, v, R, w, f) -> SegmentModels:
    """Residual models of the segments between consecutive samples (vectorised).

    Args:
        vehicle: the nominal vehicle (mass, inertia, allocation, gravity).
        t: (N,) sample times [s]; p, v: (N, 3) world NED [m], [m/s]; R: (N, 3, 3) body->world;
        w: (N, 3) body rate [rad/s]; f: (N, n) commanded rotor thrusts [N].

    Returns:
        the ``N - 1`` segment models (segment k uses samples k and k+1 and command ``f[k]``).
    """
    t = np.asarray(t, dtype=float)
    p, v, R, w, f = (np.asarray(a, dtype=float) for a in (p, v, R, w, f))
    dt = np.diff(t)
    m, g = vehicle.mass, vehicle.gravity
    A = vehicle.allocation
    Jmat, Jinv = vehicle.inertia, vehicle.inertia_inverse
    S, n = len(dt), f.shape[1]
    Ri, fi, wi = R[:-1], f[:-1], w[:-1]
    dtc = dt[:, None]
    b3 = Ri[:, :, 2]  # R_i e3
    thrust_gain = fi * A[0]  # dT / d eta_j  (S, n)
    r0 = np.empty((S, RESIDUAL_ROWS))
    J = np.empty((S, RESIDUAL_ROWS, n))
    # velocity and position (eqs. 13, 14, 17, 18): a = g e3 - T R e3 / m
    r0[:, 0:3] = v[1:] - v[:-1] - g * E3 * dtc
    r0[:, 3:6] = p[1:] - p[:-1] - v[:-1] * dtc - g * E3 * (0.5 * dtc**2)
    dv = b3[:, :, None] * thrust_gain[:, None, :] / m  # -(d a / d eta)  (S, 3, n)
    J[:, 0:3] = dv * dt[:, None, None]
    J[:, 3:6] = dv * (0.5 * dt**2)[:, None, None]
    # angular rate (eqs. 15, 19): W_hat = W + J^-1 (M - W x J W) dt
    gyro = cross(wi, wi @ Jmat.T) @ Jinv.T
    w_hat0 = wi - gyro * dtc  # predicted rate at eta = 0
    # d W_hat / d eta = dt J^-1 A_M diag(f_i)  (S, 3, n), A_M = moment rows of the allocation
    dw = (Jinv @ A[1:4])[None] * (fi * dtc)[:, None, :]
    r0[:, 6:9] = w[1:] - w_hat0
    J[:, 6:9] = -dw
    # rotation (eqs. 20-22): r_R = 1/2 (3 - tr dR) - dt vee(dR) . W_hat
    dR = np.einsum("sji,sjk->sik", Ri, R[1:])
    u = vee(dR) * dtc
    r0[:, 9] = 0.5 * (3.0 - np.trace(dR, axis1=1, axis2=2)) - np.einsum("si,si->s", u, w_hat0)
    J[:, 9] = -np.einsum("si,sij->sj", u, dw)
    return SegmentModels(r0, J, dt, fi @ A[0])


def quadratic_terms(models: SegmentModels, G_diag) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-segment quadratic form of the weighted energy (eq. 26).

    ``e_k(eta) = r_k^T G r_k = c[k] + 2 b[k] . eta + eta^T H[k] eta`` with
    ``c = r0^T G r0``, ``b = J^T G r0`` and ``H = J^T G J``.

    Returns:
        ``c`` (S,), ``b`` (S, n), ``H`` (S, n, n).
    """
    G = np.asarray(G_diag, dtype=float)
    GJ = models.J * G[None, :, None]
    c = np.einsum("si,i,si->s", models.r0, G, models.r0)
    b = np.einsum("sin,si->sn", GJ, models.r0)
    H = np.einsum("sin,sim->snm", models.J, GJ)
    return c, b, H


def _median(a: np.ndarray) -> float:
    """Median (``np.median`` gives the same value at ~10x the cost on a 9-vector)."""
    s = np.sort(a)
    k = len(s)
    return float(s[k // 2]) if k % 2 else 0.5 * float(s[k // 2 - 1] + s[k // 2])


def mad_weights(
    e,
    *,
    z_soft: float = 2.5,
    power: float = 7.0,
    z_hard: float = 2.5,
    hard_drop: bool = True,
    w_min: float = 0.03,
    mad_eps: float = 1e-9,
    median_normalize: bool = True,
    floor: bool = False,
):
    """Robust weights of segment energies ``e`` (m,).

    Args:
        floor: apply ``w_min`` even when ``hard_drop`` is on (the paper's eq. 29).
        median_normalize: divide by the median weight (the reference code).

    Returns:
        ``(w, z)``: weights (m,) and z-scores (m,).
    """
    e = np.asarray(e, dtype=float)
    med = _median(e)
    mad = 1.4826 * _median(np.abs(e - med))
    if mad < mad_eps:
        return np.ones_like(e), np.zeros_like(e)
    z = np.abs(e - med) / max(mad, mad_eps)
    w = 1.0 / (1.0 + (z / z_soft) ** power)
    if floor or not hard_drop:
        w = np.maximum(w, w_min)
    if hard_drop:
        w[z > z_hard] = 0.0
    if median_normalize:
        medw = _median(w)
        if medw > 0:
            w = w / medw
    return w, z


def ipm(H, q, lo, hi, x0, s, max_iter=80):
    """Algorithm 1 with the full KKT system (eq. 42); ``s`` the settings
    ``(mu, alpha, beta, step_fraction, backtrack_eps, min_step, tol_feas, tol_gap)``.
    Returns ``(x, iterations, converged, iterates)``."""
    mu, alpha, beta, frac, bt_eps, min_step, tol_feas, tol_gap = s
    H, q = np.asarray(H, float), np.asarray(q, float)
    n = len(q)
    Dphi = np.vstack((np.eye(n), -np.eye(n)))

    def phi(x):
        return np.concatenate((x - hi, lo - x))

    def residual(x, lam, inv_t):
        return np.concatenate((H @ x + q + Dphi.T @ lam, -lam * phi(x) - inv_t))

    x = np.array(x0, float)
    lam = -1.0 / phi(x)
    gap = -phi(x) @ lam
    iterates = []
    for it in range(1, max_iter + 1):
        inv_t = max(gap, 1e-12) / (mu * 2 * n)
        r = residual(x, lam, inv_t)
        K = np.block([[H, Dphi.T], [-lam[:, None] * Dphi, -np.diag(phi(x))]])
        dy = np.linalg.solve(K, -r)
        dx, dlam = dy[:n], dy[n:]
        s_max = 1.0
        neg = dlam < 0
        if neg.any():
            s_max = min(s_max, float(np.min(-lam[neg] / dlam[neg])))
        pos, negx = dx > 0, dx < 0
        if pos.any():
            s_max = min(s_max, float(np.min(-(x - hi)[pos] / dx[pos])))
        if negx.any():
            s_max = min(s_max, float(np.min((lo - x)[negx] / dx[negx])))
        step = frac * s_max
        while True:
            r_try = np.linalg.norm(residual(x + step * dx, lam + step * dlam, inv_t))
            if r_try <= (1 - alpha * step) * np.linalg.norm(r) + bt_eps or step < min_step:
                break
            step *= beta
        x, lam = x + step * dx, lam + step * dlam
        gap = -phi(x) @ lam
        iterates.append(x.copy())
        if r_try < tol_feas and gap < tol_gap:
            return x, it, True, np.array(iterates)
    return x, max_iter, False, np.array(iterates)


def _rounds(c, b, H, x_prev, cfg, solve):
    """The IRLS rounds of Algorithm 2 with ``solve(Hq, q, x_start) -> x``; ``(x, weights)``,
    or ``(None, weights)`` when the conditioning guard trips."""
    m, n = b.shape
    scale = 1.0 / m if cfg.scaling == "paper" else 1.0
    paper = cfg.scaling == "paper"
    x_prev = np.asarray(x_prev, float)
    x = np.clip(x_prev, cfg.lower + 1e-6, cfg.upper - 1e-6)
    w = np.ones(m)
    for _ in range(cfg.max_irls):
        e = (c + 2 * b @ x + np.einsum("snm,n,m->s", H, x, x)) * scale
        w, _ = mad_weights(
            e,
            z_soft=cfg.z_soft,
            power=cfg.soft_power,
            z_hard=cfg.z_hard,
            hard_drop=cfg.hard_drop,
            w_min=cfg.w_min,
            mad_eps=cfg.mad_eps,
            median_normalize=not paper,
            floor=paper,
        )
        JGJ = np.tensordot(w, H, 1) * scale
        if not condition_number_1(JGJ) <= cfg.cond_max:
            return None, w
        Hq = JGJ + cfg.gamma * np.eye(n)
        q = (w @ b) * scale - cfg.gamma * x_prev
        x_new = solve(Hq, q, x)
        step = np.max(np.abs(x_new - x))
        x = x_new
        if step < cfg.irls_tol:
            break
    return x, w


def solve_window(c, b, H, x_prev, cfg):
    """Algorithm 2 from the numpy pieces (no guards): ``(x, weights)``."""
    s = (
        cfg.ipm.mu,
        cfg.ipm.alpha,
        cfg.ipm.beta,
        cfg.ipm.step_fraction,
        cfg.ipm.backtrack_eps,
        cfg.ipm.min_step,
        cfg.ipm.tol_feas,
        cfg.ipm.tol_gap,
    )
    return _rounds(
        c,
        b,
        H,
        x_prev,
        cfg,
        lambda Hq, q, x: ipm(Hq, q, cfg.lower, cfg.upper, x, s, cfg.ipm.max_iter)[0],
    )


def solve_window_scipy(c, b, H, x_prev, cfg):
    """Algorithm 2 with each round's box-constrained quadratic solved exactly by scipy."""
    from scipy.optimize import minimize

    def solve(Hq, q, x):
        res = minimize(
            lambda y: 0.5 * y @ Hq @ y + q @ y,
            x,
            jac=lambda y: Hq @ y + q,
            method="L-BFGS-B",
            bounds=[(cfg.lower, cfg.upper)] * len(q),
            options={"ftol": 1e-15, "gtol": 1e-12, "maxiter": 10000},
        )
        return res.x

    return _rounds(c, b, H, x_prev, cfg, solve)


def window_uncertainty(c, b, H, w, x, cfg):
    """The window's one-sigma uncertainty (docs: the information matrix with the final
    weights), by ``numpy.linalg.inv``."""
    m, n = b.shape
    scale = 1.0 / m if cfg.scaling == "paper" else 1.0
    e = (c + 2 * b @ x + np.einsum("snm,n,m->s", H, x, x)) * scale
    s2 = max(float(w @ e), 0.0) / max(10 * int(np.count_nonzero(w > 0)) - n, 1)
    info = np.tensordot(w, H, 1) * scale + cfg.gamma * np.eye(n)
    return np.sqrt(np.maximum(np.diag(np.linalg.inv(info)), 0.0) * s2)


def condition_number_1(A) -> float:
    """``||A||_1 ||A^-1||_1`` (inf when singular)."""
    try:
        return float(np.linalg.norm(A, 1) * np.linalg.norm(np.linalg.inv(A), 1))
    except np.linalg.LinAlgError:
        return math.inf


def causal_median(x, length):
    """Running median over the last ``length`` rows, the first row repeated before them."""
    x = np.asarray(x, float)
    pad = np.concatenate((np.repeat(x[:1], length - 1, axis=0), x))
    return np.array([np.median(pad[k : k + length], axis=0) for k in range(len(x))])


def weak_direction(info: np.ndarray) -> tuple[np.ndarray, float]:
    """``(v, lambda_min)``: unit eigenvector of the smallest eigenvalue of ``info`` (n, n)."""
    vals, vecs = np.linalg.eigh(0.5 * (info + info.T))
    return vecs[:, 0], float(vals[0])


def l1_completion(delta: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``P delta + alpha* v`` with ``alpha* = argmin ||P delta + alpha v||_1``, ``P = I - v v^T``.

    ``sum_i |p_i + alpha v_i| = sum_i |v_i| |alpha + p_i / v_i|`` is minimised by the
    ``|v_i|``-weighted median of ``-p_i / v_i``.
    """
    delta = np.asarray(delta, dtype=float)
    p = delta - (delta @ v) * v
    nz = np.abs(v) > 1e-12
    if not nz.any():
        return p
    r, wts = -p[nz] / v[nz], np.abs(v[nz])
    order = np.argsort(r)
    r, cw = r[order], np.cumsum(wts[order])
    alpha = float(r[np.searchsorted(cw, 0.5 * cw[-1])])
    return p + alpha * v


class ChangeCompletion:
    """State of the change completion over a stream of window estimates (module doc).

    Args:
        threshold: an estimate that differs by more than this on some motor from the one
            ``span`` windows before starts (or extends) a change [1].
        hold: windows during which the completion applies after the last such move.
        gamma: the estimator's smoothness weight (the weak direction must be below it).
        lower, upper: the box of the estimate.
        span: windows over which a move is measured.
    """

    def __init__(
        self, threshold: float, hold: int, gamma: float, lower: float, upper: float, span: int = 9
    ):
        self.threshold, self.hold, self.gamma = threshold, hold, gamma
        self.lower, self.upper, self.span = lower, upper, span
        self.reset(None)

    def reset(self, x0) -> None:
        """Forget any change; the past ``span`` estimates are taken as ``x0``."""
        self.left = 0
        self.anchor = None
        self.v = None
        self.events = 0
        self.history = (
            None if x0 is None else np.repeat(np.asarray(x0, dtype=float)[None], self.span, axis=0)
        )
        self._k = 0

    @property
    def reference(self) -> np.ndarray:
        """The estimate ``span`` windows ago."""
        return self.history[self._k]

    def observe(self, x: np.ndarray) -> None:
        """Record the estimate of a window (every window, solved or held)."""
        self.history[self._k] = x
        self._k = (self._k + 1) % self.span

    def recent(self) -> np.ndarray:
        """The last ``span`` estimates, oldest first."""
        return np.roll(self.history, -self._k, axis=0)

    @property
    def active(self) -> bool:
        """True while a change is being completed."""
        return self.left > 0

    def triggers(self, x_raw: np.ndarray) -> bool:
        """Would the estimate ``x_raw`` start or extend a change?"""
        # max_i |x_i - ref_i| on Python floats: the same numbers, without numpy's
        # per-call overhead on a 4-vector (the online update calls this every window)
        ref = self.history[self._k].tolist()
        return (
            max(abs(a - b) for a, b in zip(np.asarray(x_raw, dtype=float).tolist(), ref))
            > self.threshold
        )

    def step(self, x_raw: np.ndarray, info) -> np.ndarray:
        """The estimate to use (and feed back) for a window whose solver returned ``x_raw``;
        ``info()`` gives the window's information matrix. Records the result."""
        x = x_raw
        if self.triggers(x_raw):
            if self.left == 0:
                v, lam = weak_direction(info())
                self.v = v if lam < self.gamma else None
                self.anchor = self.reference.copy()
                self.events += 1
            self.left = self.hold
        if self.left > 0:
            self.left -= 1
            if self.v is not None:
                change = l1_completion(x_raw - self.anchor, self.v)
                moves = np.sort(np.abs(change))
                if moves[-2] <= 0.5 * moves[-1]:  # a single-motor change; else stand down
                    x = np.clip(self.anchor + change, self.lower, self.upper)
        self.observe(x)
        return x


class OnlineIRLS:
    """The online rules of the estimator written plainly: keep the last ``window`` good
    samples (a bad sample or a time that does not increase restarts), clip the commands,
    solve the window when it is full and excited, keep the previous estimate on a guard;
    with the options, complete changes and report the running median."""

    def __init__(self, vehicle, cfg):
        self.vehicle, self.cfg, self.rows, self.eta = vehicle, cfg, [], np.ones(4)
        self.completion = ChangeCompletion(
            cfg.change_threshold,
            cfg.change_hold,
            cfg.gamma,
            cfg.lower,
            cfg.upper,
            span=cfg.window - 1,
        )
        self.completion.reset(self.eta)
        self.out = []
        self.segments = []  # the window's segment models, prefiltered

    def _add_segment(self, r):
        """The segment between the two samples ``r``, low-passed on both sides with the
        previous segment's filtered model (``cfg.prefilter``; none: as computed)."""
        seg = segment_models(
            self.vehicle,
            [x.t for x in r],
            [x.p for x in r],
            [x.v for x in r],
            [x.R for x in r],
            [x.w for x in r],
            [x.f for x in r],
        )
        a0 = r[0].accel if len(r[0]) > 6 else None
        if self.cfg.accelerometer != "off" and a0 is not None:
            # the thrust rows measured by the accelerometer; the position rows unused
            seg.r0[0, 0:3] = r[0].R @ np.asarray(a0, float) * seg.dt[0]
            seg.r0[0, 3:6] = 0.0
            seg.J[0, 3:6] = 0.0
        tau = self.cfg.prefilter
        if tau > 0 and self.segments:
            a, prev = np.exp(-seg.dt[0] / tau), self.segments[-1]
            seg = SegmentModels(
                a * prev.r0 + (1 - a) * seg.r0, a * prev.J + (1 - a) * seg.J, seg.dt, seg.thrust
            )
        self.segments = (self.segments + [seg])[-(self.cfg.window - 1) :]

    def _report(self, status):
        self.out.append(self.eta.copy())
        return status, causal_median(np.array(self.out), self.cfg.output_median)[
            -1
        ] if self.cfg.output_median > 1 else self.eta.copy()

    def update(self, s):
        cfg, veh = self.cfg, self.vehicle
        arrays = [np.asarray(a, float) for a in s[1:6]]
        ok = (
            [a.shape for a in arrays] == [(3,), (3,), (3, 3), (3,), (4,)]
            and np.isfinite(s.t)
            and all(np.all(np.isfinite(a)) for a in arrays)
        )
        if not ok or (self.rows and not s.t > self.rows[-1].t):
            self.rows, self.segments = [], []
            return self._report("bad_sample")
        self.rows = self.rows + [s._replace(f=np.clip(arrays[4], 0, veh.rotor_max_thrust))]
        self.rows = self.rows[-cfg.window :]
        if len(self.rows) >= 2:
            self._add_segment(self.rows[-2:])
        if len(self.rows) < cfg.window:
            return self._report("warmup")
        segs = self.segments
        models = SegmentModels(*(np.concatenate([getattr(x, k) for x in segs]) for k in FIELDS))
        if models.thrust.mean() < cfg.min_thrust:
            self.completion.observe(self.eta)
            return self._report("no_excitation")
        c, b, H = quadratic_terms(models, cfg.segment_weights)
        x, w = solve_window(c, b, H, self.eta, cfg)
        if x is None:
            self.completion.observe(self.eta)
            return self._report("ill_conditioned")
        if cfg.change_completion:
            scale = 1.0 / len(c) if cfg.scaling == "paper" else 1.0
            x = self.completion.step(x, lambda: np.tensordot(w, H, 1) * scale)
        self.eta = x
        return self._report("ok")
