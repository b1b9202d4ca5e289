"""Compiled Gauss–Newton accumulation of the objectives into the QP (numba).

Each objective adds ``JᵀWJ`` to the QP's ``P`` and ``JᵀWe`` to its ``c``. As NumPy this is four
operations per objective plus its error and Jacobian's slicing (some ten per objective, each
one to two microseconds of overhead on a 30-dof hand); here it is one pass that reads the rows
where they are (the kinematics' all-sites arrays for site targets) and skips the zero entries
of the Jacobians (a finger's rows touch its own joints and the wrist's). Compiled at
import, cached on disk: :mod:`retarget._jit`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from retarget._jit import BOOL, F1, F1CW, F2, F2C, F2CW, F3, F3C, FLOAT, I1, INT, kernel


@njit(cache=True)
def _add_row(row, wi, e, P, c):
    """``P += wi · row rowᵀ``, ``c += wi · e · row`` for one error row (skipping ``row``'s
    zeros: a finger's rows touch its own joints and the wrist's)."""
    wei = wi * e
    for a in range(row.shape[0]):
        x = row[a]
        if x == 0.0:
            continue
        c[a] += x * wei
        xa = x * wi
        for b in range(row.shape[0]):
            P[a, b] += xa * row[b]


@kernel(F2C, F1, F1, F2CW, F1CW)
def weighted_gram(J, w, e, P, c):
    """``P += Jᵀ diag(w) J``, ``c += Jᵀ diag(w) e`` for ``J`` (m, nv)."""
    for i in range(J.shape[0]):
        if w[i] != 0.0:
            _add_row(J[i], w[i], e[i], P, c)


@kernel(F3C, F2, I1, I1, F2, F1, F2CW, F1CW)
def site_gram(J_sites, p_sites, rows_a, rows_b, targets, w, P, c):
    """The keypoint (``rows_b`` empty: ``e = p_a − target``) or vector
    (``e = p_a − p_b − target``) terms of sites ``rows_a`` (and ``rows_b``), rows into the
    kinematics' all-sites arrays ``J_sites`` (nsite, ≥3, nv) and ``p_sites`` (nsite, 3);
    ``targets`` (k, 3), ``w`` (3k,) per error row."""
    pairs = rows_b.shape[0] > 0
    row = np.empty(P.shape[0])
    for k in range(rows_a.shape[0]):
        sa = rows_a[k]
        for r in range(3):
            wi = w[3 * k + r]
            if wi == 0.0:
                continue
            if pairs:
                sb = rows_b[k]
                e = p_sites[sa, r] - p_sites[sb, r] - targets[k, r]
                row[:] = J_sites[sa, r] - J_sites[sb, r]
                _add_row(row, wi, e, P, c)
            else:
                _add_row(J_sites[sa, r], wi, p_sites[sa, r] - targets[k, r], P, c)


@kernel(F2CW, F1CW, F1, F1)
def add_diagonal(P, c, w, r):
    """``P += diag(w)``, ``c += w ⊙ r`` (a row-selection Jacobian's terms)."""
    for a in range(w.shape[0]):
        if w[a] != 0.0:
            P[a, a] += w[a]
            c[a] += w[a] * r[a]


@kernel(F3C, F2, F2, F3, I1, BOOL, FLOAT, F1, FLOAT, BOOL, F1, F2, F2CW, F1CW)
def surface_gram(
    J, points, targets, frames, idx, split, weight, ramp, tangent_weight, use_gap, gap, gdir, P, c
):
    """The surface-contact term of the active fingers ``idx``: per finger ``k`` (finger
    ``f = idx[k]``) the error ``points[k] − targets[f]`` and its point Jacobian ``J[k]``
    (3, nv), in the target's (normal, t₁, t₂) frame ``frames[f]`` when ``split`` (the
    tangential rows weighted ``tangent_weight``), each row weighted ``weight · ramp[f]``.
    With ``use_gap`` (and ``split``) the normal row's error and direction are instead
    ``gap[k]`` and ``gdir[k]`` (its Jacobian ``gdir[k]ᵀ J[k]``): the link's signed distance
    where it hovers off the surface (``SurfaceContactObjective.hover``)."""
    row = np.empty(P.shape[0])
    d = np.empty(3)
    for k in range(idx.shape[0]):
        f = idx[k]
        for r in range(3):
            d[r] = points[k, r] - targets[f, r]
        for r in range(3):
            wi = weight * ramp[f]
            if split and r > 0:
                wi *= tangent_weight
            if wi == 0.0:
                continue
            if split:
                u = gdir[k] if (use_gap and r == 0) else frames[f, r]
                e = gap[k] if (use_gap and r == 0) else u[0] * d[0] + u[1] * d[1] + u[2] * d[2]
                row[:] = u[0] * J[k, 0] + u[1] * J[k, 1] + u[2] * J[k, 2]
                _add_row(row, wi, e, P, c)
            else:
                _add_row(J[k, r], wi, d[r], P, c)


@njit(cache=True)
def _rotation_vector(M, out):
    """``out[:] =`` the rotation vector [rad] (angle in [0, π]) of the rotation matrix ``M``
    (3, 3): its unit quaternion by the largest-diagonal branch (as ``mju_mat2Quat``, robust
    near π), taken with ``w ≥ 0``, then ``2 atan2(|v|, w) v / |v|``."""
    tr = M[0, 0] + M[1, 1] + M[2, 2]
    if tr > 0.0:
        s = 2.0 * np.sqrt(tr + 1.0)
        w, x, y, z = (
            0.25 * s,
            (M[2, 1] - M[1, 2]) / s,
            (M[0, 2] - M[2, 0]) / s,
            (M[1, 0] - M[0, 1]) / s,
        )
    elif M[0, 0] > M[1, 1] and M[0, 0] > M[2, 2]:
        s = 2.0 * np.sqrt(1.0 + M[0, 0] - M[1, 1] - M[2, 2])
        w, x, y, z = (
            (M[2, 1] - M[1, 2]) / s,
            0.25 * s,
            (M[0, 1] + M[1, 0]) / s,
            (M[0, 2] + M[2, 0]) / s,
        )
    elif M[1, 1] > M[2, 2]:
        s = 2.0 * np.sqrt(1.0 + M[1, 1] - M[0, 0] - M[2, 2])
        w, x, y, z = (
            (M[0, 2] - M[2, 0]) / s,
            (M[0, 1] + M[1, 0]) / s,
            0.25 * s,
            (M[1, 2] + M[2, 1]) / s,
        )
    else:
        s = 2.0 * np.sqrt(1.0 + M[2, 2] - M[0, 0] - M[1, 1])
        w, x, y, z = (
            (M[1, 0] - M[0, 1]) / s,
            (M[0, 2] + M[2, 0]) / s,
            (M[1, 2] + M[2, 1]) / s,
            0.25 * s,
        )
    n = np.sqrt(w * w + x * x + y * y + z * z)
    if w < 0.0:  # the short way round
        n = -n
    w, x, y, z = w / n, x / n, y / n, z / n
    v = np.sqrt(x * x + y * y + z * z)
    f = 2.0 if v < 1e-12 else 2.0 * np.arctan2(v, w) / v  # (first order: 2 sin(θ/2) ≈ θ)
    out[0], out[1], out[2] = f * x, f * y, f * z


@njit(cache=True)
def _pose_error(p, R, p_target, R_target, out):
    M = np.empty((3, 3))
    for a in range(3):
        out[a] = p[a] - p_target[a]
        for b in range(3):
            M[a, b] = (
                R[3 * a] * R_target[b, 0]
                + R[3 * a + 1] * R_target[b, 1]
                + R[3 * a + 2] * R_target[b, 2]
            )
    _rotation_vector(M, out[3:])


@kernel(F1, F1, F1, F2, F1CW)
def pose_error(p, R, p_target, R_target, out):
    """``out`` (6,) ``= [p − p*; log(R R*ᵀ)]`` for a position ``p`` (3,) and a rotation ``R``
    (9,), row-major (MuJoCo's ``xmat``), against ``p_target``, ``R_target`` (3, 3)."""
    _pose_error(p, R, p_target, R_target, out)


@kernel(F3C, F2, F2, INT, F1, F2, F1, F2CW, F1CW)
def pose_gram(J_sites, p_sites, R_sites, site, p_target, R_target, w, P, c):
    """The wrist pose term of site ``site``: :func:`pose_error` from the kinematics' all-sites
    positions ``p_sites`` (nsite, 3) and rotations ``R_sites`` (nsite, 9), and the site's
    Jacobian ``J_sites[site]`` (6, nv) as the error's, rows weighted ``w`` (6,)."""
    e = np.empty(6)
    _pose_error(p_sites[site], R_sites[site], p_target, R_target, e)
    for r in range(6):
        if w[r] != 0.0:
            _add_row(J_sites[site, r], w[r], e[r], P, c)
