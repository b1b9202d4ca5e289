"""Retargeting bare 21-keypoint sequences (hand-pose estimators, teleoperation gloves).

No MANO parameters, no object: only keypoints ``(T, 21, 3)`` [m] in ``mano21`` or
``openpose21`` order. The wrist orientation is recovered from the palm: the wrist and the index,
middle and pinky MCP keypoints move rigidly with MANO's wrist frame (they are children of the
wrist joint only), so ``R_world_mano`` is the rotation that maps the rest skeleton's palm
triangle onto the observed one (Kabsch on the four points, exact for MANO-consistent input).
"""

from __future__ import annotations

import numpy as np

from dexcanvas_core.keypoints import MANO21, convert_keypoints
from dexcanvas_core.rotations import matrix_to_aa
from dexcanvas_core.trajectory import HandTrack, Trajectory
from retarget.errors import RetargetError

_PALM = [MANO21.index(k) for k in ("wrist", "index1", "middle1", "pinky1", "ring1")]


def _kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Rotations ``R`` (T, 3, 3) with ``dst - mean ≈ R (src - mean)`` per frame."""
    s = src - src.mean(axis=-2, keepdims=True)
    d = dst - dst.mean(axis=-2, keepdims=True)
    H = np.einsum("...ki,...kj->...ij", s, d)
    U, _, Vt = np.linalg.svd(H)
    D = np.ones(U.shape[:-1])
    D[..., -1] = np.sign(np.linalg.det(np.einsum("...ij,...jk->...ik", U, Vt)))
    return np.einsum("...ji,...j,...kj->...ik", Vt, D, U)


def keypoints_to_trajectory(
    keypoints: np.ndarray,
    fps: float,
    order: str = "mano21",
    side: str = "right",
    uuid: str = "keypoints",
) -> Trajectory:
    """A hand-only ``Trajectory`` from a keypoint sequence, ready for ``Retargeter.retarget``.

    Args:
        keypoints: ``(T, 21, 3)`` world positions [m].
        fps: frame rate [Hz].
        order: ``"mano21"`` or ``"openpose21"``.
    """
    from dexcanvas_core.mano import HandSkeleton

    kp = np.asarray(keypoints, dtype=np.float64)
    if kp.ndim != 3 or kp.shape[1:] != (21, 3):
        raise RetargetError(f"keypoints must have shape (T, 21, 3), got {kp.shape}")
    if not np.all(np.isfinite(kp)):
        bad = int(np.argwhere(~np.isfinite(kp))[0, 0])
        raise RetargetError(f"keypoints contain NaN or inf (first at frame {bad}); fill gaps first")
    if not (np.isfinite(fps) and fps > 0):
        raise RetargetError(f"fps must be positive, got {fps}")
    if order != "mano21":
        kp = convert_keypoints(kp, order, "mano21")
    rest = HandSkeleton.default(side).rest_keypoints
    R = _kabsch(np.broadcast_to(rest[_PALM], (kp.shape[0], len(_PALM), 3)), kp[:, _PALM])
    T = kp.shape[0]
    # wrist = J0 + transl (MANO semantics): keep the translation consistent with the skeleton.
    transl = kp[:, 0] - rest[0]
    hand = HandTrack(
        name=side,
        global_pos=transl,
        global_rot_aa=matrix_to_aa(R),
        hand_pose=np.concatenate([matrix_to_aa(R), np.zeros((T, 45))], axis=1),
        joint_pos=kp,
    )
    return Trajectory(
        uuid=uuid, timestamp=np.arange(T) / fps, fps=float(fps), hands=[hand], objects=[]
    )


def retarget_keypoints(hand, keypoints: np.ndarray, fps: float, order: str = "mano21", config=None):
    """Retarget a bare keypoint sequence onto ``hand`` (no object): a ``RobotTrajectory``."""
    from retarget.retargeter import Retargeter

    traj = keypoints_to_trajectory(keypoints, fps, order)
    return Retargeter(hand, None, config).retarget(traj)
