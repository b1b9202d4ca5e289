"""Named hand keypoint orderings and converters between them.

Three orderings are in use:

* ``MANO_JOINTS`` (16): MANO's kinematic joints in MANO's own order — wrist, then index, middle,
  pinky, ring, thumb, three joints each (proximal to distal). This is the order of the 15 × 3
  finger axis-angles in ``mano_hand_pose[:, 3:]``.
* ``MANO21`` (21): the 16 MANO joints followed by the five fingertips thumb, index, middle,
  ring, pinky (the tip order of the common MANO layers). This is the layout of the DexCanvas
  ``mano_joint_pos`` column (16 skeleton joints, then the fingertips).
* ``OPENPOSE21`` (21): wrist, then thumb, index, middle, ring, pinky, four points each from
  the base to the tip — the order of most hand-pose estimators and retargeting code.

``convert_keypoints(x, src, dst)`` reorders the keypoint axis (``-2``) of any array or tensor.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from dexcanvas_core.errors import UnknownNameError, ValidationError

FINGERS: tuple[str, ...] = ("thumb", "index", "middle", "ring", "pinky")
"""Fingers in anatomical order (the order used by per-finger arrays of this toolkit)."""

MANO_FINGER_ORDER: tuple[str, ...] = ("index", "middle", "pinky", "ring", "thumb")
"""Order of the fingers inside MANO's joint list and 45-D pose vector."""

MANO_JOINTS: tuple[str, ...] = (
    "wrist",
    *(f"{f}{i}" for f in MANO_FINGER_ORDER for i in (1, 2, 3)),
)
"""The 16 MANO joints; ``{finger}1..3`` are the MCP, PIP, DIP joints (thumb: CMC, MCP, IP)."""

MANO_PARENTS: tuple[int, ...] = (-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14)
"""Parent index of each of the 16 MANO joints (MANO's ``kintree_table[0]``)."""

MANO21: tuple[str, ...] = (*MANO_JOINTS, *(f"{f}_tip" for f in FINGERS))
"""The 21-keypoint order of DexCanvas ``mano_joint_pos``: 16 MANO joints, then 5 fingertips."""

OPENPOSE21: tuple[str, ...] = (
    "wrist",
    *(name for f in FINGERS for name in (f"{f}1", f"{f}2", f"{f}3", f"{f}_tip")),
)
"""Wrist, then thumb, index, middle, ring, pinky; base to tip (4 keypoints per finger)."""

FINGERTIPS_MANO21: tuple[int, ...] = tuple(MANO21.index(f"{f}_tip") for f in FINGERS)
"""Indices of the thumb…pinky tips in ``MANO21``."""

KeypointOrder = Literal["mano21", "openpose21"]
ORDERS: dict[str, tuple[str, ...]] = {"mano21": MANO21, "openpose21": OPENPOSE21}


def permutation(src: str, dst: str) -> np.ndarray:
    """Index array ``p`` such that ``x_dst = x_src[..., p, :]``."""
    for name in (src, dst):
        if name not in ORDERS:
            raise UnknownNameError("keypoint order", name, ORDERS)
    src_names = ORDERS[src]
    return np.array([src_names.index(n) for n in ORDERS[dst]], dtype=np.int64)


def convert_keypoints(x, src: KeypointOrder, dst: KeypointOrder):
    """Reorder the keypoint axis of ``x``, a numpy array or torch tensor ``(..., 21, D)``."""
    if x.shape[-2:-1] != (21,) and (len(x.shape) < 2 or x.shape[-2] != 21):
        raise ValidationError(
            f"keypoints must have shape (..., 21, D), got {tuple(x.shape)}", field="keypoints"
        )
    p = permutation(src, dst)
    if isinstance(x, np.ndarray):
        return x[..., p, :]
    import torch

    return x[..., torch.as_tensor(p, device=x.device), :]
