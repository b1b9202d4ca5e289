"""Compiled per-frame passes of the retargeter itself (numba; see :mod:`retarget._jit`)."""

from __future__ import annotations

import numpy as np

from retarget._jit import B2, BOOL, F1, F2, F2W, FLOAT, INT, kernel


@kernel(F2, F2, B2, INT, F1, F1)
def predicted_start(Q_last, wq, active, t, lower, upper):
    """Frame ``t``'s predicted starting point (``Retargeter._warm_start``): the last solution
    ``Q_last[1]`` with the wrist joints (the first 6: position, then Euler angles wrapped to
    (−π, π]) moved as the human's ``wq[0] → wq[1]`` and, when no finger's contact flag in
    ``active`` (T, F) changed over frames ``t − 2 … t``, the other joints at their last
    velocity ``Q_last[1] − Q_last[0]``; clipped to ``[lower, upper]``. One pass instead of
    some fifteen array operations."""
    q = Q_last[1]
    n = q.shape[0]
    q0 = q.copy()
    for i in range(6):
        dw = wq[1, i] - wq[0, i]
        if i >= 3:
            dw = (dw + np.pi) % (2 * np.pi) - np.pi
        q0[i] += dw
    same = True
    for f in range(active.shape[1]):
        if active[t, f] != active[t - 1, f] or active[t - 1, f] != active[t - 2, f]:
            same = False
            break
    if same:
        for i in range(6, n):
            q0[i] += q[i] - Q_last[0, i]
    for i in range(n):
        q0[i] = min(max(q0[i], lower[i]), upper[i])
    return q0


@kernel(F2W)
def symmetrize(P):
    """``P ← ½ (P + Pᵀ)`` in place (the same values as the NumPy expression, without its two
    temporaries)."""
    n = P.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            s = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = s
            P[j, i] = s


@kernel(F2, F1, F2, F1, F1, F1, BOOL, FLOAT)
def daqp_arrays(G, h, A, b, lb, ub, box, big):
    """DAQP's constraint arrays in one pass: ``(M, upper, lower, sense)`` with the box
    ``lb ≤ Δq ≤ ub`` as its first ``nv`` simple bounds when ``box`` (clipped to ``±big``,
    DAQP's "no bound"), then ``G Δq ≤ h``, then ``A Δq = b`` (sense 5: active and immutable);
    ``M`` the C-contiguous stack of ``G`` and ``A``."""
    nv = G.shape[1]
    mi, me = G.shape[0], A.shape[0]
    ms = nv if box else 0
    n = ms + mi + me
    M = np.empty((mi + me, nv))
    upper = np.empty(n)
    lower = np.empty(n)
    sense = np.zeros(n, np.int32)
    for i in range(ms):
        upper[i] = min(ub[i], big)
        lower[i] = max(lb[i], -big)
    for r in range(mi):
        M[r] = G[r]
        upper[ms + r] = h[r]
        lower[ms + r] = -big
    for r in range(me):
        M[mi + r] = A[r]
        upper[ms + mi + r] = b[r]
        lower[ms + mi + r] = b[r]
        sense[ms + mi + r] = 5
    return M, upper, lower, sense
