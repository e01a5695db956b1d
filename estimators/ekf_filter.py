"""The EKF's step: one predict and one update, compiled (the model of :mod:`estimators.ekf`).

State ``x = [p (3); v (3); Omega (3); vec(R) (9, column-major); eta (n)]`` and covariance
``P``. :func:`predict_update_into` is the filter, one line per equation, each a small stage
compiled into it (:func:`quadfault.jit.jit`, inlined) that works in a named
:data:`WORKSPACE`::

    x_pred = f(x, u)                  predict_state          (eqs. 1-4, 12)
    F = d f / d x                     transition_blocks
    P_pred = F P F^T + Q              predict_covariance
    y = z - h(x_pred), H = d h / d x  innovation
    S = H P_pred H^T + R              innovation_covariance  (R added in the factorisation)
    K = P_pred H^T S^-1               whitened_gain
    x = x_pred + K y                  update_state
    P = P_pred - K S K^T              update_covariance
    R -> SO(3), eta clamped           project_and_clamp

The stages use the structure of the ``18 + n``-state filter instead of dense products:

* the transition Jacobian ``F`` is never formed: it is the identity plus a few blocks (p and
  v rows: dt, the thrust direction ``R e3`` and a rank-one eta coupling; Omega rows:
  ``I + dt G`` and ``dt B``; vec(R) rows: ``E^T kron I3`` and the rank-3 product
  ``dR/dphi [dphi/dOmega, dphi/deta]``; eta rows: the identity, a random walk), so
  ``F P F^T`` is two passes of :func:`_jacobian_times` over those blocks (a
  :class:`Transition`), the second on the lower triangle only (mirrored), reading the
  first's result by columns;
* the measurement Jacobian is ``[I_9 0]`` plus a 3 x 9 attitude block, so ``H P`` and
  ``H P H^T`` read rows of ``P``;
* the gain is used in the square-root form: ``S = L L^T``, ``W = L^-1 H P``, so
  ``K = W^T L^-1``, ``x += W^T L^-1 y``, ``P -= W^T W``: no explicit gain, symmetric by
  construction (equal to the Joseph form for this optimal gain up to rounding). An ``S``
  that is not positive definite takes the general solver (:func:`_update_general`).

The online rules around it (first sample, bad samples, idle rotors, command clipping) are
:func:`estimators.ekf.ekf_step`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from estimators.linalg import cholesky_into, gauss_jordan_into, symmetric_eigen_into
from estimators.state import Layout, fields
from quadfault.jit import jit
from quadfault.model.dynamics import (
    angular_acceleration3,
    rotor_wrench,
    translational_acceleration3,
)
from quadfault.model.rotation import expm3, mat3, matvec3  # the core's kernels

#: the filter's state vector: position, velocity, rate, vec(R) column by column (R e1, R e2,
#: R e3), then the n efficiencies
X = fields(
    "EKFStates", ("p", 3), ("v", 3), ("w", 3), ("Re1", 3), ("Re2", 3), ("Re3", 3), ("eta", 0)
)
#: rows of the measurement: position, velocity, rate (each reads its state: ``H = I`` there),
#: the attitude's rotation error, then the accelerometer's body-z specific force (used only
#: on an update that measures it: the first :data:`Y`\ ``.a`` rows otherwise)
Y = fields("EKFMeasurementRows", ("p", 3), ("v", 3), ("w", 3), ("R", 3), ("a", 1))
N_VEC_R = X.eta - X.Re1  # the entries of vec(R)
assert (X.p, X.v, X.w) == (Y.p, Y.v, Y.w) and X.Re1 == Y.R  # rows that read their state
#: the workspace's scratch arrays by name, in the order of the stages that write them (the
#: fields of :class:`Scratch`); stored by shape, a few arrays in all, so that the filter's
#: state and the workspace pass between compiled functions as a few arrays
#: (:data:`WORKSPACE`)
#:
#: * ``predict_state``: the attitude before and after the predict (``R``, ``Rn``), the
#:   predicted state ``xp``;
#: * ``transition_blocks``: the efficiency columns of F (thrust ``dT``, rate ``(dt B)^T``
#:   ``BwT``, attitude ``(dt^2 B / 2)^T`` ``BrT``), ``G`` and its numerator
#:   ``Gn = [J w]x - [w]x J``, the rate block ``Fw = I + dt G`` and its attitude image
#:   ``Mw``, the right Jacobian ``Jr``, the attitude's derivative
#:   ``dR = d vec(R_pred) / d phi``;
#: * ``predict_covariance``: ``FP = F P``, the predicted covariance
#:   ``Pp``; the scratch of :func:`_jacobian_times` (``ze = dT^T P[eta]``,
#:   ``Z = [Mw, Br] P[(Omega, eta)]``);
#: * ``innovation``: the rotation error ``dRz = Rn^T R_meas``, the innovation ``y``, the
#:   attitude rows ``HR`` of ``H``;
#: * ``innovation_covariance``, ``whitened_gain``, ``update_*``: ``HP = H P`` (then
#:   ``W = L^-1 H P``), ``WT = W^T``, ``S = H P H^T`` (lower triangle) and its Cholesky
#:   factor ``L``;
#: * ``project_and_clamp``: the updated attitude ``Ru`` and the projection's scratch
#:   ``svdA``, ``svdD``, ``svdV``.
BLOCKS = fields(
    "EKFBlocks", "R", "Rn", "Gn", "G", "Fw", "Mw", "Jr", "dRz", "Ru", "svdA", "svdD", "svdV"
)  # 3 x 3 each
MATS = fields("EKFMatrices", "FP", "Pp")  # ns x ns each
VECS = fields("EKFVectors", "xp", "ze")  # ns each
SQUARES = fields("EKFSquares", "S", "L")  # Y.size x Y.size each
EFFICIENCY = fields("EKFEfficiencyColumns", "BwT", "BrT")  # n x 3 each
#: the workspace of one filter as stored (dimensions: rotors ``n``, states
#: ``ns = X.size + n``): the arrays of one shape together, named by the fields above
WORKSPACE = Layout(
    "EKFWorkspace",
    mats=(MATS.size, "ns", "ns"),
    blocks=(BLOCKS.size, 3, 3),
    vecs=(VECS.size, "ns"),
    squares=(SQUARES.size, Y.size, Y.size),
    efficiency=(EFFICIENCY.size, "n", 3),
    dT=("n",),
    dR=(N_VEC_R, 3),
    Z=(3, "ns"),
    y=(Y.size,),
    HR=(Y.a - Y.R, N_VEC_R),
    HP=(Y.size, "ns"),
    WT=("ns", Y.size),
)
Workspace = WORKSPACE.pieces


class Scratch(NamedTuple):
    """The workspace's arrays by name (views of a :data:`WORKSPACE`, :func:`scratch`)."""

    R: np.ndarray
    Rn: np.ndarray
    xp: np.ndarray
    dT: np.ndarray
    BwT: np.ndarray
    BrT: np.ndarray
    Gn: np.ndarray
    G: np.ndarray
    Fw: np.ndarray
    Mw: np.ndarray
    Jr: np.ndarray
    dR: np.ndarray
    FP: np.ndarray
    Pp: np.ndarray
    ze: np.ndarray
    Z: np.ndarray
    dRz: np.ndarray
    y: np.ndarray
    HR: np.ndarray
    HP: np.ndarray
    WT: np.ndarray
    S: np.ndarray
    L: np.ndarray
    Ru: np.ndarray
    svdA: np.ndarray
    svdD: np.ndarray
    svdV: np.ndarray


@jit(inline="always")
def scratch(work) -> Scratch:
    """The arrays of the workspace ``work`` (:class:`Workspace`) by name."""
    b, m, v, q, e = work.blocks, work.mats, work.vecs, work.squares, work.efficiency
    return Scratch(
        R=b[BLOCKS.R],
        Rn=b[BLOCKS.Rn],
        xp=v[VECS.xp],
        dT=work.dT,
        BwT=e[EFFICIENCY.BwT],
        BrT=e[EFFICIENCY.BrT],
        Gn=b[BLOCKS.Gn],
        G=b[BLOCKS.G],
        Fw=b[BLOCKS.Fw],
        Mw=b[BLOCKS.Mw],
        Jr=b[BLOCKS.Jr],
        dR=work.dR,
        FP=m[MATS.FP],
        Pp=m[MATS.Pp],
        ze=v[VECS.ze],
        Z=work.Z,
        dRz=b[BLOCKS.dRz],
        y=work.y,
        HR=work.HR,
        HP=work.HP,
        WT=work.WT,
        S=q[SQUARES.S],
        L=q[SQUARES.L],
        Ru=b[BLOCKS.Ru],
        svdA=b[BLOCKS.svdA],
        svdD=b[BLOCKS.svdD],
        svdV=b[BLOCKS.svdV],
    )


class Measurement(NamedTuple):
    """What the update measures: position ``p`` [m], velocity ``v`` [m/s] (world), body rate
    ``w`` [rad/s] (3,) each, attitude ``R`` (3, 3) body -> world; with ``rows`` =
    ``Y.size`` also the accelerometer's body-z specific force ``a`` [m/s^2], whose model is
    linear in the efficiencies, ``a = ha . eta`` (``ha`` (n,): ``-A[0, j] f_j / m`` for the
    command ``f`` of the sample, the thrust the accelerometer feels); ``rows`` = ``Y.a``: no
    accelerometer (``a``, ``ha`` unused). :func:`predict_update_accel_into` measures the
    ``Y.size`` rows, :func:`predict_update_into` the first ``Y.a`` (the caller picks the
    kernel by ``rows``)."""

    p: np.ndarray
    v: np.ndarray
    w: np.ndarray
    R: np.ndarray
    a: float = 0.0
    ha: np.ndarray = np.zeros(0)
    rows: int = Y.a


class Model(NamedTuple):
    """The filter's model: the nominal rigid body ``rigid`` (the tuple of
    :func:`quadfault.model.dynamics.rigid_body`: mass, gravity, J, J^-1), the inertia ``J`` and its
    inverse ``Jinv`` as (3, 3) arrays (the Jacobian's blocks), the allocation ``A`` (4, n),
    the process-noise variance rates ``qc`` (ns,) [1/s], the measurement-noise variances
    ``r`` (:data:`Y`), and the efficiency clamp ``[lo, hi]``."""

    rigid: tuple
    J: np.ndarray
    Jinv: np.ndarray
    A: np.ndarray
    qc: np.ndarray
    r: np.ndarray
    lo: float
    hi: float


def workspace(n: int) -> Workspace:
    """A workspace of :func:`predict_update_into` for ``n`` rotors (arrays of zeros)."""
    shapes = WORKSPACE.shapes(n=n, ns=X.size + n)
    return Workspace(*(np.zeros(s) for s in shapes))


@jit
def _right_jacobian_into(phi0, phi1, phi2, Jr):
    """Right Jacobian of SO(3) (``ekf.right_jacobian_so3``): ``I - a K + b K^2``."""
    th2 = phi0 * phi0 + phi1 * phi1 + phi2 * phi2
    if th2 < 1e-8:
        a = 0.5 - th2 / 24.0
        b = 1.0 / 6.0 - th2 / 120.0
    else:
        th = math.sqrt(th2)
        a = (1.0 - math.cos(th)) / th2
        b = (th - math.sin(th)) / (th2 * th)
    K = ((0.0, -phi2, phi1), (phi2, 0.0, -phi0), (-phi1, phi0, 0.0))
    for i in range(3):
        for j in range(3):
            kk = 0.0
            for k in range(3):
                kk += K[i][k] * K[k][j]
            Jr[i, j] = (1.0 if i == j else 0.0) - a * K[i][j] + b * kk


@jit
def _det3(M):
    return (
        M[0, 0] * (M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1])
        - M[0, 1] * (M[1, 0] * M[2, 2] - M[1, 2] * M[2, 0])
        + M[0, 2] * (M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0])
    )


@jit
def _project_so3_into(M, A, D, V):
    """Closest rotation (polar factor) of ``M`` in place, as
    ``quadfault.model.rotation.orthonormalize``: Newton iterations ``M <- (M + M^-T) / 2`` when ``M``
    is near SO(3) (the EKF's case), else from the eigen-decomposition of ``M^T M`` (the SVD
    of ``M``). ``A``, ``D``, ``V`` are 3 x 3 scratch."""
    err = 0.0
    for i in range(3):
        for j in range(3):
            s = 0.0
            for k in range(3):
                s += M[k, i] * M[k, j]
            A[i, j] = s
            err = max(err, abs(s - (1.0 if i == j else 0.0)))
    if err < 1e-3 and _det3(M) > 0:
        C = A
        for _ in range(3):
            for i in range(3):  # C = cofactor matrix^T = adj(M); inv(M) = C / det
                for j in range(3):
                    i1, i2, j1, j2 = (i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3
                    C[j, i] = M[i1, j1] * M[i2, j2] - M[i1, j2] * M[i2, j1]
            det = M[0, 0] * C[0, 0] + M[0, 1] * C[1, 0] + M[0, 2] * C[2, 0]
            for i in range(3):
                for j in range(3):
                    M[i, j] = 0.5 * (M[i, j] + C[j, i] / det)
        return
    # M = U S V^T: V and S^2 from M^T M; the two largest singular directions give
    # u_k = M v_k / s_k, the third completes a right-handed pair; R = U V^T
    symmetric_eigen_into(A, D, V)
    lo = 0
    for k in range(1, 3):
        if D[k, k] < D[lo, lo]:
            lo = k
    a, b = (lo + 1) % 3, (lo + 2) % 3
    for k in (a, b):
        sk = math.sqrt(max(D[k, k], 1e-300))
        for i in range(3):
            A[i, k] = (M[i, 0] * V[0, k] + M[i, 1] * V[1, k] + M[i, 2] * V[2, k]) / sk
    for i in range(3):  # u_lo = u_a x u_b, with V's orientation: det(U V^T) = +1
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        A[i, lo] = A[i1, a] * A[i2, b] - A[i2, a] * A[i1, b]
    if _det3(V) < 0:
        for i in range(3):
            A[i, lo] = -A[i, lo]
    for i in range(3):
        for j in range(3):
            M[i, j] = A[i, 0] * V[j, 0] + A[i, 1] * V[j, 1] + A[i, 2] * V[j, 2]


class Transition(NamedTuple):
    """The blocks of the transition Jacobian ``F`` of one predict over ``dt`` [s]
    (``ekf.predict``), which :func:`_jacobian_times` applies without forming ``F``. p row i:
    ``e_i + dt e_{v,i} + cp e_{R e3, i} + up_i dT^T``; v row i:
    ``e_{v,i} + cv e_{R e3, i} + uv_i dT^T``; Omega rows: ``[Fw, dt B]`` on (Omega, eta);
    vec(R) row ``3 jb + k``: ``E[:, jb]`` (``E`` a row-major 9-tuple) on the k-th entries of
    R's columns plus ``dR [Mw, Br]`` on (Omega, eta); eta rows: the identity. ``BwT``,
    ``BrT``: ``(dt B)^T``, ``(dt^2 B / 2)^T`` (n, 3); ``dT`` (n,) the thrust's derivative."""

    dt: float
    cp: float
    cv: float
    up: tuple
    uv: tuple
    dT: np.ndarray
    Fw: np.ndarray
    BwT: np.ndarray
    E: tuple
    dR: np.ndarray
    Mw: np.ndarray
    BrT: np.ndarray


@jit(inline="always")
def _entry(A, r, k, transposed):
    """``A[r, k]``, or ``A[k, r]`` when ``transposed``."""
    return A[k, r] if transposed else A[r, k]


@jit(inline="always")
def _jacobian_times(Pin, out, lower, F, ze, Z):
    """``out = F Pin`` over the blocks of the transition Jacobian (:class:`Transition`); when
    ``lower``, ``out = F Pin^T`` on ``out[i, :i + 1]`` only (``Pin`` read by columns: its
    transpose is never copied). ``ze``, ``Z`` are scratch."""
    dt, cp, cv, up, uv, dT = F.dt, F.cp, F.cv, F.up, F.uv, F.dT
    Fw, BwT, E, dR, Mw, BrT = F.Fw, F.BwT, F.E, F.dR, F.Mw, F.BrT
    ns = Pin.shape[0]
    nr = ns - X.eta
    n6 = X.w if lower else ns  # columns the p / v rows need
    n18 = X.eta if lower else ns
    w, e = X.w, X.eta
    for k in range(n6):  # ze = dT^T Pin[eta]  (the rank-one eta coupling)
        acc = 0.0
        for j in range(nr):
            acc += dT[j] * _entry(Pin, e + j, k, lower)
        ze[k] = acc
    for i in range(3):  # p and v rows (R e3: the thrust direction)
        lp = X.p + i + 1 if lower else ns
        for k in range(lp):
            out[X.p + i, k] = (
                _entry(Pin, X.p + i, k, lower)
                + dt * _entry(Pin, X.v + i, k, lower)
                + cp * _entry(Pin, X.Re3 + i, k, lower)
                + up[i] * ze[k]
            )
        lv = X.v + i + 1 if lower else ns
        for k in range(lv):
            out[X.v + i, k] = (
                _entry(Pin, X.v + i, k, lower)
                + cv * _entry(Pin, X.Re3 + i, k, lower)
                + uv[i] * ze[k]
            )
    for i in range(3):  # Omega rows
        lw = w + i + 1 if lower else ns
        for k in range(lw):
            out[w + i, k] = (
                Fw[i, 0] * _entry(Pin, w, k, lower)
                + Fw[i, 1] * _entry(Pin, w + 1, k, lower)
                + Fw[i, 2] * _entry(Pin, w + 2, k, lower)
            )
        for j in range(nr):
            b = BwT[j, i]
            for k in range(lw):
                out[w + i, k] += b * _entry(Pin, e + j, k, lower)
    for a in range(3):  # Z = [Mw, Br] Pin[(Omega, eta)]
        for k in range(n18):
            Z[a, k] = (
                Mw[a, 0] * _entry(Pin, w, k, lower)
                + Mw[a, 1] * _entry(Pin, w + 1, k, lower)
                + Mw[a, 2] * _entry(Pin, w + 2, k, lower)
            )
        for j in range(nr):
            b = BrT[j, a]
            for k in range(n18):
                Z[a, k] += b * _entry(Pin, e + j, k, lower)
    for jb in range(3):  # vec(R) rows: vec(R E) = (E^T kron I3) vec(R), plus dR Z
        e0, e1, e2 = E[jb], E[3 + jb], E[6 + jb]  # column jb of the row-major 9-tuple
        for kk in range(3):
            row = 3 * jb + kk
            d0, d1, d2 = dR[row, 0], dR[row, 1], dR[row, 2]
            lr = X.Re1 + row + 1 if lower else ns
            for k in range(lr):
                out[X.Re1 + row, k] = (
                    e0 * _entry(Pin, X.Re1 + kk, k, lower)
                    + e1 * _entry(Pin, X.Re2 + kk, k, lower)
                    + e2 * _entry(Pin, X.Re3 + kk, k, lower)
                    + d0 * Z[0, k]
                    + d1 * Z[1, k]
                    + d2 * Z[2, k]
                )
    for i in range(e, ns):  # eta rows: random walk
        le = i + 1 if lower else ns
        for k in range(le):
            out[i, k] = _entry(Pin, i, k, lower)


@jit(inline="always")
def predict_state(x, f, dt, model, R, Rn, xp):
    """The state's predict over ``dt`` [s] with the rotor commands ``f`` [N] held: the rigid
    body of :mod:`quadfault.model.dynamics` (the thrust allocation ``[T; M] = A diag(eta) f``,
    eq. 12; the accelerations, eqs. 2 and 4) discretised as the paper's EKF does (eqs. 1-4)::

        p+ = p + v dt + a dt^2 / 2,   v+ = v + a dt,   Omega+ = Omega + Omega' dt,
        R+ = R exp([phi]x),  phi = Omega dt + Omega' dt^2 / 2,   eta+ = eta

    into ``xp`` (``R``, ``Rn``: the attitude before and after). Returns what
    the transition Jacobian needs: the thrust ``T``, the rate ``w``, ``J w``, ``phi`` and
    ``E = exp([phi]x)`` (row-major 9-tuple)."""
    rigid = model.rigid
    for j in range(3):
        for i in range(3):
            R[i, j] = x[X.Re1 + 3 * j + i]
    T, mo = rotor_wrench(model.A, f, x[X.eta :])  # [T; M] = A diag(eta) f
    w = (x[X.w], x[X.w + 1], x[X.w + 2])
    jw = matvec3(rigid[2], w)
    wdot = angular_acceleration3(w, mo, rigid)  # eq. 4
    acc = translational_acceleration3(mat3(R), T, rigid)  # eq. 2
    phi = (
        w[0] * dt + 0.5 * wdot[0] * dt * dt,
        w[1] * dt + 0.5 * wdot[1] * dt * dt,
        w[2] * dt + 0.5 * wdot[2] * dt * dt,
    )
    E = expm3(phi)  # row-major 9-tuple
    for i in range(3):
        for j in range(3):
            Rn[i, j] = R[i, 0] * E[j] + R[i, 1] * E[3 + j] + R[i, 2] * E[6 + j]
    for i in range(3):
        xp[X.p + i] = x[X.p + i] + x[X.v + i] * dt + 0.5 * acc[i] * dt * dt
        xp[X.v + i] = x[X.v + i] + acc[i] * dt
        xp[X.w + i] = x[X.w + i] + wdot[i] * dt
    for j in range(3):
        for i in range(3):
            xp[X.Re1 + 3 * j + i] = Rn[i, j]
    for j in range(x.shape[0] - X.eta):
        xp[X.eta + j] = x[X.eta + j]
    return T, w, jw, phi, E


@jit(inline="always")
def transition_blocks(f, dt, model, T, w, jw, phi, E, R, Rn, dT, BwT, BrT, Gn, G, Fw, Mw, Jr, dR):
    """The blocks of the transition Jacobian ``F = d x_pred / d x`` of :func:`predict_state`
    (its arguments ``T``, ``w``, ``jw``, ``phi``, ``E``), as a :class:`Transition` over arrays
    of ``work``; ``F`` itself is never formed. The efficiency columns: ``dT = d T / d eta``
    and ``B = J^-1 A_M diag(f) = d Omega' / d eta``; the rate block
    ``G = J^-1 ([J w]x - [w]x J) = d Omega' / d Omega``; the attitude:
    ``dR[:, i] = vec(R_pred [Jr[:, i]]x) = d vec(R_pred) / d phi_i``."""
    A, J, Jinv, m = model.A, model.J, model.Jinv, model.rigid[0]
    for j in range(f.shape[0]):  # dT = d T / d eta, B = d Omega' / d eta
        dT[j] = A[0, j] * f[j]
        for i in range(3):
            b = (
                Jinv[i, 0] * (A[1, j] * f[j])
                + Jinv[i, 1] * (A[2, j] * f[j])
                + Jinv[i, 2] * (A[3, j] * f[j])
            )
            BwT[j, i] = dt * b
            BrT[j, i] = 0.5 * dt * dt * b
    w0, w1, w2 = w
    hjw = ((0.0, -jw[2], jw[1]), (jw[2], 0.0, -jw[0]), (-jw[1], jw[0], 0.0))
    hw = ((0.0, -w2, w1), (w2, 0.0, -w0), (-w1, w0, 0.0))
    for k in range(3):  # G = J^-1 ([J w]x - [w]x J) = d Omega' / d Omega
        for j in range(3):
            Gn[k, j] = hjw[k][j] - (hw[k][0] * J[0, j] + hw[k][1] * J[1, j] + hw[k][2] * J[2, j])
    for i in range(3):
        for j in range(3):
            G[i, j] = Jinv[i, 0] * Gn[0, j] + Jinv[i, 1] * Gn[1, j] + Jinv[i, 2] * Gn[2, j]
            Fw[i, j] = (1.0 if i == j else 0.0) + dt * G[i, j]
            Mw[i, j] = (dt if i == j else 0.0) + 0.5 * dt * dt * G[i, j]  # d phi / d Omega
    _right_jacobian_into(phi[0], phi[1], phi[2], Jr)
    for i in range(3):  # dR[:, i] = vec(Rn [Jr[:, i]]x) = d vec(R_pred) / d phi_i
        h = ((0.0, -Jr[2, i], Jr[1, i]), (Jr[2, i], 0.0, -Jr[0, i]), (-Jr[1, i], Jr[0, i], 0.0))
        for cc in range(3):
            for rr in range(3):
                dR[3 * cc + rr, i] = (
                    Rn[rr, 0] * h[0][cc] + Rn[rr, 1] * h[1][cc] + Rn[rr, 2] * h[2][cc]
                )
    cp, cv = -(T / m) * 0.5 * dt * dt, -(T / m) * dt  # d (p, v) / d (R e3)
    up = (
        -R[0, 2] * (0.5 * dt * dt / m),
        -R[1, 2] * (0.5 * dt * dt / m),
        -R[2, 2] * (0.5 * dt * dt / m),
    )  # d (p, v) / d eta = up / uv (x) dT
    uv = (-R[0, 2] * (dt / m), -R[1, 2] * (dt / m), -R[2, 2] * (dt / m))
    return Transition(dt, cp, cv, up, uv, dT, Fw, BwT, E, dR, Mw, BrT)


@jit(inline="always")
def predict_covariance(P, F, qc, dt, FP, Pp, ze, Z):
    """``P_pred = F P F^T + Q`` into ``Pp``, with ``Q = diag(qc) dt``: ``F P`` over the
    blocks of ``F`` (:func:`_jacobian_times`), then ``F (F P)^T`` on the lower triangle
    only (reading ``F P`` by columns), mirrored (exactly symmetric). ``FP``, ``ze``, ``Z``:
    scratch."""
    ns = P.shape[0]
    _jacobian_times(P, FP, False, F, ze, Z)
    _jacobian_times(FP, Pp, True, F, ze, Z)  # F (F P)^T
    for i in range(ns):
        for k in range(i):
            Pp[k, i] = Pp[i, k]
        Pp[i, i] += qc[i] * dt


@jit(inline="always")
def innovation(z, xp, Rn, dRz, y, HR, nm):
    """The innovation ``y = z - h(x_pred)`` into ``y`` and the attitude rows of
    ``H = [I_9 0; 0 HR 0]`` into ``HR`` (``xp``, ``Rn``: the predicted state and attitude;
    ``dRz``: scratch). Position, velocity and rate read their states;
    the attitude's is the rotation error ``log(R_pred^T R_meas)``, whose Jacobian ``HR`` is
    that of ``vee(skew(R_pred^T R_meas))`` (equal to first order; it does not depend on the
    estimate)."""
    zR = z.R
    for i in range(3):
        y[Y.p + i] = z.p[i] - xp[X.p + i]
        y[Y.v + i] = z.v[i] - xp[X.v + i]
        y[Y.w + i] = z.w[i] - xp[X.w + i]
    for i in range(3):  # dRz = Rn^T zR, y[Y.R:] = log(dRz)
        for j in range(3):
            dRz[i, j] = Rn[0, i] * zR[0, j] + Rn[1, i] * zR[1, j] + Rn[2, i] * zR[2, j]
    s0 = 0.5 * (dRz[2, 1] - dRz[1, 2])
    s1 = 0.5 * (dRz[0, 2] - dRz[2, 0])
    s2 = 0.5 * (dRz[1, 0] - dRz[0, 1])
    sn = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    cs = 0.5 * (dRz[0, 0] + dRz[1, 1] + dRz[2, 2] - 1.0)
    scale = 1.0 if sn < 1e-12 else math.atan2(sn, cs) / sn
    y[Y.R], y[Y.R + 1], y[Y.R + 2] = s0 * scale, s1 * scale, s2 * scale
    if nm > Y.a:  # the accelerometer: a = ha . eta
        acc = z.a
        for j in range(z.ha.shape[0]):
            acc -= z.ha[j] * xp[X.eta + j]
        y[Y.a] = acc
    for k in range(3):
        for i in range(N_VEC_R):
            HR[k, i] = 0.0
    for k, ia, ib in ((0, 2, 1), (1, 0, 2), (2, 1, 0)):
        for i in range(3):
            HR[k, 3 * ia + i] -= 0.5 * zR[i, ib]
            HR[k, 3 * ib + i] += 0.5 * zR[i, ia]


@jit(inline="always")
def innovation_covariance(ha, Pp, HR, HP, S, nm):
    """``H P_pred`` into ``HP`` and the lower triangle of ``S = H P_pred H^T`` into
    ``S`` (``R = diag(r)`` is added where ``S`` is factored, :func:`whitened_gain`), on
    the ``nm`` rows measured. ``H = [I_9 0; 0 HR 0; 0 ha^T]``: ``H P`` reads rows of
    ``P``, the attitude rows go through ``HR``, the accelerometer's through ``ha`` on the
    efficiencies."""
    ns = Pp.shape[0]
    nd = Y.R  # the rows that read their state (H = I there)
    for i in range(nd):
        for k in range(ns):
            HP[i, k] = Pp[i, k]
    for i in range(Y.a - nd):
        for k in range(ns):
            HP[nd + i, k] = 0.0
        for j in range(N_VEC_R):
            h = HR[i, j]
            if h != 0.0:
                for k in range(ns):
                    HP[nd + i, k] += h * Pp[X.Re1 + j, k]
    if nm > Y.a:
        for k in range(ns):
            acc = 0.0
            for j in range(ha.shape[0]):
                acc += ha[j] * Pp[X.eta + j, k]
            HP[Y.a, k] = acc
    for i in range(nm):
        for k in range(min(i + 1, nd)):
            S[i, k] = HP[i, k]
        for k in range(nd, min(i + 1, Y.a)):
            acc = 0.0
            for j in range(N_VEC_R):
                acc += HP[i, X.Re1 + j] * HR[k - nd, j]
            S[i, k] = acc
        if i == Y.a:
            acc = 0.0
            for j in range(ha.shape[0]):
                acc += HP[i, X.eta + j] * ha[j]
            S[i, i] = acc


@jit(inline="always")
def whitened_gain(r, S, L, HP, y, nm) -> bool:
    """The gain ``K = P_pred H^T S^-1`` in its square-root form, with ``S + diag(r) = L L^T``
    (:func:`estimators.linalg.cholesky_into`, ``r`` its shift): ``K = W^T L^-1`` with
    ``W = L^-1 H P_pred`` (``HP`` becomes ``W``, forward substitution on whole rows)
    and the whitened innovation ``L^-1 y`` (in ``y``). False, with nothing changed but
    ``L``, when ``S`` is not positive definite (a corrupted covariance). ``nm``: the
    rows measured."""
    ns = HP.shape[1]
    if not cholesky_into(S, r, L, nm):
        return False
    for i in range(nm):  # W = L^-1 H P
        for k in range(i):
            lik = L[i, k]
            for c in range(ns):
                HP[i, c] -= lik * HP[k, c]
        d = L[i, i]
        for c in range(ns):
            HP[i, c] = HP[i, c] / d
    for i in range(nm):  # y <- L^-1 y
        acc = y[i]
        for k in range(i):
            acc -= L[i, k] * y[k]
        y[i] = acc / L[i, i]
    return True


@jit(inline="always")
def update_state(x, xp, W, WT, y, nm):
    """``x = x_pred + K y = x_pred + W^T (L^-1 y)`` (:func:`whitened_gain`, ``nm`` rows);
    ``WT`` becomes ``W^T``."""
    for i in range(x.shape[0]):
        acc = 0.0
        for c in range(nm):
            WT[i, c] = W[c, i]
            acc += W[c, i] * y[c]
        x[i] = xp[i] + acc


@jit(inline="always")
def update_covariance(P, Pp, WT, nm):
    """``P = (I - K H) P_pred = P_pred - K S K^T = P_pred - W^T W`` (after
    :func:`update_state`): the optimal gain's covariance, equal to the Joseph form
    ``(I - K H) P (I - K H)^T + K R K^T`` for this gain up to rounding; symmetric by
    construction (lower triangle computed, mirrored) and positive semi-definite up to
    rounding."""
    for i in range(P.shape[0]):
        for k in range(i + 1):
            acc = 0.0
            for c in range(nm):
                acc += WT[i, c] * WT[k, c]
            P[i, k] = Pp[i, k] - acc
            P[k, i] = P[i, k]


@jit(inline="always")
def project_and_clamp(x, lo, hi, Ru, svdA, svdD, svdV):
    """The updated attitude projected back onto SO(3) (:func:`_project_so3_into`, in ``Ru``;
    ``svd*``: scratch) and the efficiencies clamped to ``[lo, hi]``, in ``x``."""
    for j in range(3):
        for i in range(3):
            Ru[i, j] = x[X.Re1 + 3 * j + i]
    _project_so3_into(Ru, svdA, svdD, svdV)
    for j in range(3):
        for i in range(3):
            x[X.Re1 + 3 * j + i] = Ru[i, j]
    for j in range(x.shape[0] - X.eta):
        x[X.eta + j] = min(max(x[X.eta + j], lo), hi)


@jit
def predict_update_into(x, P, f, dt, z, model, work):
    """One predict over ``dt`` [s] with the rotor commands ``f`` [N] held and one update with
    the measurement ``z`` (:class:`Measurement`) without its accelerometer row (the paper's
    filter); ``x`` and ``P`` are overwritten. ``model``: :class:`Model` (the nominal rigid
    body, allocation, noise, clamp); ``work``: :class:`Workspace`."""
    _predict_update(x, P, f, dt, z, model, work, Y.a)


@jit
def predict_update_accel_into(x, P, f, dt, z, model, work):
    """:func:`predict_update_into` with the accelerometer's row measured too."""
    _predict_update(x, P, f, dt, z, model, work, Y.size)


@jit(inline="always")
def _predict_update(x, P, f, dt, z, model, work, nm):
    """The filter on ``nm`` rows of ``z`` (known when compiled: each kernel above holds one
    update). Each stage is one line of the EKF's equations; each takes the workspace's
    arrays it reads and writes by name (:class:`Scratch`)."""
    s = scratch(work)
    T, w, jw, phi, E = predict_state(x, f, dt, model, s.R, s.Rn, s.xp)  # x_pred = f(x, u)
    F = transition_blocks(  # F = d f / d x
        f,
        dt,
        model,
        T,
        w,
        jw,
        phi,
        E,
        s.R,
        s.Rn,
        s.dT,
        s.BwT,
        s.BrT,
        s.Gn,
        s.G,
        s.Fw,
        s.Mw,
        s.Jr,
        s.dR,
    )
    predict_covariance(P, F, model.qc, dt, s.FP, s.Pp, s.ze, s.Z)  # F P F^T + Q
    innovation(z, s.xp, s.Rn, s.dRz, s.y, s.HR, nm)  # y = z - h(x_pred), H = d h / d x
    innovation_covariance(z.ha, s.Pp, s.HR, s.HP, s.S, nm)  # S = H P_pred H^T (+ R)
    if whitened_gain(model.r, s.S, s.L, s.HP, s.y, nm):  # K = P_pred H^T S^-1 = W^T L^-1
        update_state(x, s.xp, s.HP, s.WT, s.y, nm)  # x = x_pred + K y
        update_covariance(P, s.Pp, s.WT, nm)  # P = P_pred - K S K^T
    else:  # S not positive definite: the general solver
        _update_general_from(x, P, model.r, s, nm)
    project_and_clamp(x, model.lo, model.hi, s.Ru, s.svdA, s.svdD, s.svdV)


@jit
def _update_general_from(x, P, r, s, nm):
    """:func:`_update_general` on the workspace's arrays (``s``: :class:`Scratch`), with
    ``diag(r)`` added to ``S``."""
    S, ns = s.S, x.shape[0]
    for i in range(nm):
        S[i, i] += r[i]
    KT = s.WT.ravel()[: nm * ns].reshape((nm, ns))
    _update_general(x, P, s.xp, s.Pp, s.y[:nm], s.HP[:nm], S[:nm, :nm], KT)


@jit
def _update_general(x, P, xp, Pp, y, HP, S, KT):
    """Fallback of :func:`whitened_gain` for an ``S`` that is not positive definite: ``K^T`` by
    Gauss-Jordan elimination into ``KT`` (12, ns), ``x = xp + K y``,
    ``P = sym(Pp - K H Pp)``; nothing changes if ``S`` is singular."""
    ns, m = Pp.shape[0], S.shape[0]
    for i in range(m):
        for k in range(i + 1, m):
            S[i, k] = S[k, i]
        for k in range(ns):
            KT[i, k] = HP[i, k]
    if not gauss_jordan_into(S, KT):
        for i in range(ns):
            x[i] = xp[i]
            for k in range(ns):
                P[i, k] = Pp[i, k]
        return
    for i in range(ns):
        acc = 0.0
        for c in range(m):
            acc += KT[c, i] * y[c]
        x[i] = xp[i] + acc
    for i in range(ns):
        for k in range(i + 1):
            a = Pp[i, k] + Pp[k, i]
            for c in range(m):
                a -= KT[c, i] * HP[c, k] + KT[c, k] * HP[c, i]
            P[i, k] = 0.5 * a
            P[k, i] = P[i, k]
