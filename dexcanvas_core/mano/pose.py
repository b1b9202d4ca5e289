"""MANO pose layouts and conventions: the mean finger pose (``hands_mean``) of the right model,
mirroring a pose between the hands, and splitting DexCanvas' 48-D ``mano_hand_pose``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from dexcanvas_core.errors import ValidationError

# MANO_RIGHT.pkl ``hands_mean`` [rad] (mean finger pose of the MANO training scans), as reproduced
# in public code, e.g. ykk648/AI_power's FrankMocap hand regressor and several DexYCB / FrankMocap
# tools. The left model's mean is its mirror image: (x, y, z) → (x, -y, -z) per joint. Used only by
# the skeleton path with ``flat_hand_mean=False`` (the exact path reads the model's own).
_MANO_HANDS_MEAN_RIGHT = np.array(
    [
        0.11167872, -0.04289217, 0.41644184, 0.10881133, 0.06598568, 0.75622001,
        -0.09639297, 0.09091566, 0.18845929, -0.11809504, -0.05094385, 0.5295845,
        -0.14369841, -0.0552417, 0.70485714, -0.01918292, 0.09233685, 0.33791352,
        -0.45703298, 0.19628395, 0.62545753, -0.21465238, 0.06599829, 0.50689421,
        -0.36972436, 0.06034463, 0.07949023, -0.14186969, 0.08585263, 0.63552826,
        -0.30334159, 0.05788098, 0.63138921, -0.17612089, 0.13209308, 0.37335458,
        0.85096428, -0.27692274, 0.09154807, -0.49983944, -0.02655647, -0.05288088,
        0.53555915, -0.04596104, 0.27735802,
    ]
)  # fmt: skip


MANO_HANDS_MEAN_RIGHT = _MANO_HANDS_MEAN_RIGHT
"""(45,) [rad] MANO's mean finger pose of the right hand (``hands_mean``), joint order of
``hand_pose``; the left hand's is its mirror (:func:`mirror_axis_angle`)."""
_MANO_HANDS_MEAN_RIGHT.setflags(write=False)


def mirror_axis_angle(axis_angle: Any) -> Any:
    """Mirror axis-angles across the x = 0 plane: ``(x, y, z) → (x, -y, -z)`` per 3-vector.

    Turns a right-hand MANO pose into the left-hand pose that mirrors it (and back). Works on any
    ``(..., 3k)`` numpy array or torch tensor.
    """
    if axis_angle.shape[-1] % 3:
        raise ValidationError(
            f"axis_angle last dimension must be a multiple of 3, got {tuple(axis_angle.shape)}",
            field="axis_angle",
        )
    sign_np = np.tile([1.0, -1.0, -1.0], axis_angle.shape[-1] // 3)
    if isinstance(axis_angle, torch.Tensor):
        return axis_angle * torch.as_tensor(
            sign_np, dtype=axis_angle.dtype, device=axis_angle.device
        )
    return np.asarray(axis_angle) * sign_np


def split_full_pose(pose48: Any) -> tuple[Any, Any]:
    """Split a DexCanvas ``mano_hand_pose`` ``(B, 48)`` into ``(global_orient (B, 3), hand_pose
    (B, 45))`` (numpy arrays or torch tensors). ``ManoLayer.forward`` also accepts the 48-D layout
    directly as ``hand_pose`` when ``global_orient`` is not given."""
    if pose48.shape[-1] != 48:
        raise ValidationError(
            f"full pose must have shape (..., 48), got {tuple(pose48.shape)}", field="hand_pose"
        )
    return pose48[..., :3], pose48[..., 3:]
