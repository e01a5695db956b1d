"""Robust segment weights from a MAD z-score (paper eqs. 26-30, Algorithm 2).

For the segment energies ``e_i = r_i^T G_i r_i``::

    m_e = median(e),   MAD = 1.4826 median(|e - m_e|)                     (eq. 27)
    z_i = |e_i - m_e| / max(MAD, eps)            (two-sided)               (eq. 28)
    w_i = 1 / (1 + (z_i / z_soft)^p)                                       (eq. 29)
    w_i = 0 if z_i > z_hard                      (hard rejection)          (eq. 30)

If ``MAD < eps`` every weight is 1 (and every z-score 0). Two variants (see docs/irls.md):

* ``reference`` (the authors' code): hard rejection on, so the floor ``w_min`` is never used;
  the weights are then divided by their median.
* ``paper``: ``w_i = max(w_i, w_min)`` before the hard rejection, no median normalisation.

With ``hard_drop=False`` the floor ``w_min`` applies instead of the rejection (both variants).

:func:`mad_weights_into` is the compiled kernel the IRLS window runs; :func:`mad_weights` calls
it on one vector of energies and returns new arrays.
"""

from __future__ import annotations

import numpy as np

from quadfault.jit import jit

MAD_SCALE = 1.4826  # MAD -> standard deviation for Gaussian data


@jit(inner=True)
def median_into(a, tmp) -> float:
    """Median of ``a`` (the middle value, or the mean of the middle two, as ``np.median``),
    by insertion sort into the scratch ``tmp`` (at least as long as ``a``)."""
    m = a.shape[0]
    for i in range(m):
        v = a[i]
        j = i - 1
        while j >= 0 and tmp[j] > v:
            tmp[j + 1] = tmp[j]
            j -= 1
        tmp[j + 1] = v
    k = m // 2
    if m % 2:
        return tmp[k]
    return 0.5 * (tmp[k - 1] + tmp[k])


@jit(inner=True)
def mad_weights_into(
    e, z_soft, power, z_hard, w_min, mad_eps, hard_drop, median_normalize, floor, w, z, tmp
) -> None:
    """Robust weights of the energies ``e`` (m,) into ``w`` and their z-scores into ``z``
    (eqs. 27-30); ``tmp`` (m,) is scratch. ``floor``: apply ``w_min`` even when ``hard_drop``
    is on (the paper's eq. 29); ``median_normalize``: divide by the median weight (the
    reference code)."""
    m = e.shape[0]
    med = median_into(e, tmp)
    for i in range(m):
        z[i] = abs(e[i] - med)
    mad = MAD_SCALE * median_into(z, tmp)
    if mad < mad_eps:
        for i in range(m):
            w[i] = 1.0
            z[i] = 0.0
        return
    for i in range(m):
        z[i] = z[i] / max(mad, mad_eps)
        wi = 1.0 / (1.0 + (z[i] / z_soft) ** power)
        if floor or not hard_drop:
            wi = max(wi, w_min)
        if hard_drop and z[i] > z_hard:
            wi = 0.0
        w[i] = wi
    if median_normalize:
        medw = median_into(w, tmp)
        if medw > 0:
            for i in range(m):
                w[i] = w[i] / medw


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
    """Robust weights of segment energies ``e`` (m,) (:func:`mad_weights_into`).

    Returns:
        ``(w, z)``: weights (m,) and z-scores (m,).
    """
    e = np.ascontiguousarray(e, dtype=float)
    w, z, tmp = np.empty_like(e), np.empty_like(e), np.empty_like(e)
    mad_weights_into(
        e,
        float(z_soft),
        float(power),
        float(z_hard),
        float(w_min),
        float(mad_eps),
        bool(hard_drop),
        bool(median_normalize),
        bool(floor),
        w,
        z,
        tmp,
    )
    return w, z
