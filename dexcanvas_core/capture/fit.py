"""A MANO hand pose fitted to 21 keypoints, for captures that give keypoints but no usable pose
(e.g. DexYCB's PCA poses without the licensed MANO model that expands them).

The subject's skeleton is built from the keypoints' own bone lengths
(:func:`~dexcanvas_core.mano.measure_bone_lengths`), so a MANO-consistent sequence is fitted
exactly; the keypoints are the markers of the mocap fitter (:class:`~dexcanvas_core.mocap.fit.
HandFitter`: batched Levenberg–Marquardt with analytic Jacobians and anatomical joint priors),
each carried by its own joint (the fingertips by the distal joint). The wrist orientation starts
from the palm's rigid fit (Kabsch on the wrist and the four MCP keypoints), the fingers from the
flat hand.
"""

from __future__ import annotations

import numpy as np

from dexcanvas_core.keypoints import MANO21
from dexcanvas_core.mano import HandSkeleton, measure_bone_lengths
from dexcanvas_core.mano.skeleton import TIP_PARENTS
from dexcanvas_core.rotations import matrix_to_aa

_PALM = [MANO21.index(k) for k in ("wrist", "index1", "middle1", "pinky1", "ring1")]


def _kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """``(T, 3, 3)`` rotations best mapping ``src (K, 3)`` onto each ``dst (T, K, 3)``."""
    s = src - src.mean(axis=0)
    d = dst - dst.mean(axis=1, keepdims=True)
    H = np.einsum("ki,tkj->tij", s, d)
    U, _, Vt = np.linalg.svd(H)
    D = np.ones((len(dst), 3))
    D[:, -1] = np.sign(np.linalg.det(np.einsum("tij,tjk->tik", U, Vt)))
    return np.einsum("tji,tj,tkj->tik", Vt, D, U)


def fit_pose_to_keypoints(keypoints: np.ndarray, iterations: int = 30) -> dict:
    """Fit MANO's pose to MANO21 keypoints ``(T, 21, 3)`` [m] of a right hand.

    Returns:
        ``{"global_orient" (T, 3), "hand_pose" (T, 45), "wrist_pos" (T, 3), "residual_mm"
        (T,) mean keypoint distance after the fit, "skeleton"}``.
    """
    # lazy: the mocap package (scipy.signal, scipy.stats) adds ~1.5 s to `dexcanvas --help`
    from dexcanvas_core.mocap.fit import HandFitter
    from dexcanvas_core.mocap.model import HandMarkerModel

    kp = np.asarray(keypoints, dtype=np.float64)
    skel = HandSkeleton.from_bone_lengths(measure_bone_lengths(kp))
    rest = skel.rest_keypoints
    parents = np.array([*range(16), *TIP_PARENTS])
    offsets = rest - rest[parents]  # zero for the 16 joints, the tip bone for the tips
    model = HandMarkerModel(rest, offsets, parents)
    R0 = _kabsch(rest[_PALM], kp[:, _PALM])
    x0 = np.zeros((len(kp), 51))
    x0[:, :3] = matrix_to_aa(R0)
    x0[:, 3:6] = kp[:, 0] - rest[0]
    fitter = HandFitter(model, "right")
    x, stats = fitter.solve(kp, np.ones(kp.shape[:2]), x0, max_iterations=iterations)
    x = np.asarray(x, dtype=np.float64)
    return {
        "global_orient": x[:, :3],
        "hand_pose": x[:, 6:],
        "wrist_pos": rest[0] + x[:, 3:6],
        "residual_mm": 1000.0 * np.asarray(stats.residual_m, dtype=np.float64).mean(axis=-1),
        "skeleton": skel,
    }
