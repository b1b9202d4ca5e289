"""Rigid registration of marker sets: weighted Kabsch, outlier rejection, label-swap repair.

``kabsch(P, Q, w)`` returns the rotation ``R`` and translation ``t`` minimising
``Σ_k w_k |R p_k + t − q_k|²`` (Kabsch 1976; Umeyama 1991 without scale), batched over frames,
with the reflection fix ``diag(1, 1, det(V Uᵀ))``.

``register_object`` estimates an object's 6-DoF pose per frame from its ≥ 3 visible markers:

1. fit all visible markers;
2. **label-swap repair**: if the worst residual exceeds the outlier threshold, every
   relabelling of the visible markers is tried — permutations among themselves and moves onto
   labels missing in the frame (a marker that took the label of a hidden neighbour), 24 for
   four markers; one that brings every residual under the threshold and lowers the RMS below a
   third of the original is taken, and the frame is reported as swapped. The layout's distinct
   inter-marker distances are what make the right labelling the only one that fits;
3. **outlier rejection**: otherwise, while more than three markers remain and a residual
   exceeds ``outlier_m``, the marker whose removal leaves the best fit (and which lies more than
   ``outlier_m`` from it) is dropped and the pose refit.

Frames with fewer than three visible markers get no pose (NaN) and are reported; the pipeline
interpolates short runs of them and flags long ones.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.rotations import matrix_to_aa


def kabsch(
    P: np.ndarray, Q: np.ndarray, w: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least-squares rigid transform ``Q ≈ R P + t``, batched.

    Args:
        P: ``(N, 3)`` or ``(B, N, 3)`` model points.
        Q: ``(B, N, 3)`` observed points (NaN rows are ignored).
        w: ``(B, N)`` non-negative weights (default 1; 0 ignores a point).

    Returns:
        ``R (B, 3, 3)``, ``t (B, 3)``; frames with fewer than 3 usable points give NaN.
    """
    Q = np.asarray(Q, dtype=np.float64)
    if Q.ndim == 2:
        Q = Q[None]
    B, N, _ = Q.shape
    P = np.broadcast_to(np.asarray(P, dtype=np.float64), (B, N, 3))
    W = np.ones((B, N)) if w is None else np.array(w, dtype=np.float64, copy=True)
    ok = np.isfinite(Q).all(-1) & np.isfinite(P).all(-1) & (W > 0)
    W = np.where(ok, W, 0.0)
    Qz = np.where(ok[..., None], Q, 0.0)
    Pz = np.where(ok[..., None], P, 0.0)
    wsum = W.sum(1, keepdims=True)
    safe = np.maximum(wsum, 1e-300)
    p_bar = (W[..., None] * Pz).sum(1) / safe
    q_bar = (W[..., None] * Qz).sum(1) / safe
    Pc = (Pz - p_bar[:, None]) * ok[..., None]
    Qc = (Qz - q_bar[:, None]) * ok[..., None]
    Hm = np.einsum("bn,bni,bnj->bij", W, Pc, Qc)
    U, _, Vt = np.linalg.svd(Hm)
    d = np.sign(np.linalg.det(np.einsum("bji,bkj->bik", Vt, U)))
    d = np.where(d == 0, 1.0, d)
    D = np.zeros((B, 3, 3))
    D[:, 0, 0] = 1.0
    D[:, 1, 1] = 1.0
    D[:, 2, 2] = d
    R = np.einsum("bji,bjk,blk->bil", Vt, D, U)
    t = q_bar - np.einsum("bij,bj->bi", R, p_bar)
    bad = ok.sum(1) < 3
    R[bad] = np.nan
    t[bad] = np.nan
    return R, t


@dataclass
class ObjectRegistration:
    """Per-frame object poses from markers (world frame)."""

    R: np.ndarray
    """(T, 3, 3) rotation object → world; NaN where no pose."""
    t: np.ndarray
    """(T, 3) [m] object origin in the world; NaN where no pose."""
    visible: np.ndarray
    """(T,) int: markers visible in the raw data."""
    used: np.ndarray
    """(T, K) bool: markers used in the final fit."""
    residual_m: np.ndarray
    """(T,) [m] RMS residual of the used markers (NaN where no pose)."""
    swapped: np.ndarray
    """(T,) bool: a label permutation was repaired."""
    permutation: np.ndarray
    """(T, K) int: column ``i`` of ``corrected`` is raw column ``permutation[i]`` (-1: none)."""
    corrected: np.ndarray
    """(T, K, 3) [m] the markers after label repair (outliers still in; see ``used``)."""
    outliers: np.ndarray
    """(T,) int: markers rejected as outliers."""

    @property
    def rot_aa(self) -> np.ndarray:
        """(T, 3) axis-angle [rad] (NaN where no pose)."""
        out = np.full((self.R.shape[0], 3), np.nan)
        ok = np.isfinite(self.R).all(axis=(1, 2))
        if ok.any():
            out[ok] = matrix_to_aa(self.R[ok])
        return out

    @property
    def valid(self) -> np.ndarray:
        return np.isfinite(self.t).all(1)


def _residuals(P: np.ndarray, Q: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(B, N) distances |R p + t − q| [m] (NaN where q is NaN)."""
    pred = np.einsum("bij,bnj->bni", R, np.broadcast_to(P, Q.shape)) + t[:, None]
    return np.linalg.norm(pred - Q, axis=-1)


def register_object(
    model_points: np.ndarray,
    observed: np.ndarray,
    *,
    outlier_m: float = 0.005,
    repair_swaps: bool = True,
) -> ObjectRegistration:
    """Object pose per frame from labelled markers (see the module docstring).

    Args:
        model_points: ``(K, 3)`` [m] marker positions in the object frame (``layout``).
        observed: ``(T, K, 3)`` [m] markers in the world frame, NaN where missing.
        outlier_m: residual [m] above which a marker is an outlier (or a swap is suspected).
        repair_swaps: try label permutations on frames whose residual is too high.
    """
    P = np.asarray(model_points, dtype=np.float64)
    Q = np.asarray(observed, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or Q.ndim != 3 or Q.shape[1:] != P.shape:
        raise ValidationError(
            f"register_object: model points {P.shape} and observations {Q.shape} disagree "
            "(expected (K, 3) and (T, K, 3))"
        )
    T, K, _ = Q.shape
    vis = np.isfinite(Q).all(-1)
    n_vis = vis.sum(1)
    perm = np.tile(np.arange(K), (T, 1))
    swapped = np.zeros(T, bool)
    outliers = np.zeros(T, np.int64)
    used = vis.copy()
    R, t = kabsch(P, Q)
    res = _residuals(P, Q, R, t)
    worst = np.nanmax(np.where(vis, res, -np.inf), axis=1) if K else np.zeros(T)
    suspect = np.flatnonzero((n_vis >= 3) & (worst > outlier_m))
    Qc = Q.copy()
    for f in suspect:
        q = Q[f]
        v = vis[f]
        r0 = res[f]
        rms0 = float(np.sqrt(np.nanmean(np.where(v, r0, np.nan) ** 2)))
        best = None
        if repair_swaps:
            # every relabelling of the visible markers, also onto labels missing in the frame
            idx = np.flatnonzero(v)
            for labels in itertools.permutations(range(K), idx.size):
                if labels == tuple(idx):
                    continue
                order = np.full(K, -1)
                order[list(labels)] = idx
                qp = np.where(order[:, None] >= 0, q[np.maximum(order, 0)], np.nan)
                Rp, tp = kabsch(P, qp[None])
                rp = _residuals(P, qp[None], Rp, tp)[0][list(labels)]
                if np.all(rp < outlier_m):
                    rms = float(np.sqrt(np.mean(rp**2)))
                    if rms < rms0 / 3 and (best is None or rms < best[0]):
                        best = (rms, order, qp)
        if best is not None:
            perm[f] = best[1]
            Qc[f] = best[2]
            used[f] = best[1] >= 0
            swapped[f] = True
            continue
        # outlier rejection, one marker at a time: the marker whose removal leaves the best fit
        keep = v.copy()
        while keep.sum() > 3:
            qk = np.where(keep[:, None], q, np.nan)
            Rf, tf = kabsch(P, qk[None])
            r = _residuals(P, qk[None], Rf, tf)[0]
            if np.nanmax(np.where(keep, r, -np.inf)) <= outlier_m:
                break
            best_j, best_rms = -1, np.inf
            for j in np.flatnonzero(keep):
                k2 = keep.copy()
                k2[j] = False
                q2 = np.where(k2[:, None], q, np.nan)
                R2, t2 = kabsch(P, q2[None])
                r2 = _residuals(P, q[None], R2, t2)[0]
                rms = float(np.sqrt(np.mean(r2[k2] ** 2)))
                if rms < best_rms and r2[j] > outlier_m:
                    best_j, best_rms = j, rms
            if best_j < 0:
                break
            keep[best_j] = False
            outliers[f] += 1
        used[f] = keep
    Qu = np.where(used[..., None], Qc, np.nan)
    R, t = kabsch(P, Qu)
    res = _residuals(P, Qu, R, t)
    n_used = used.sum(1)
    sq = np.where(used, res, 0.0) ** 2
    rms = np.where(n_used >= 3, np.sqrt(sq.sum(1) / np.maximum(n_used, 1)), np.nan)
    return ObjectRegistration(
        R=R,
        t=t,
        visible=n_vis,
        used=used,
        residual_m=rms,
        swapped=swapped,
        permutation=perm,
        corrected=Qc,
        outliers=outliers,
    )
