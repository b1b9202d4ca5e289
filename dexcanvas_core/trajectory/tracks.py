"""Per-frame tracks of a trajectory: a hand's MANO kinematics (:class:`HandTrack`), an object's
pose (:class:`ObjectTrack`), an object's active segments (:class:`ObjectMove`), and the
``urdf_dof`` layouts of the public hand."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.trajectory.arrays import f32

URDF_DOF_NAMES_26: tuple[str, ...] = (
    "ARTx", "ARTy", "ARTz", "ARRx", "ARRy", "ARRz",
    "thumb_cmc_abd", "thumb_cmc_flex", "thumb_mcp", "thumb_ip",
    *(f"{f}_{j}" for f in ("index", "middle", "ring", "pinky")
      for j in ("mcp_abd", "mcp_flex", "pip", "dip")),
)  # fmt: skip
"""``urdf_dof`` order of the 26-DoF hand: wrist xyz [m] + intrinsic XYZ Euler [rad], 20 fingers."""

URDF_DOF_NAMES_28: tuple[str, ...] = (
    *URDF_DOF_NAMES_26[:6],
    "thumb_cmc_abd", "thumb_cmc_flex", "thumb_cmc_twist", "thumb_mcp_flex", "thumb_mcp_abd",
    "thumb_ip",
    *URDF_DOF_NAMES_26[10:],
)  # fmt: skip
"""``urdf_dof`` order of the newer 28-DoF hand (thumb CMC twist and MCP abduction added)."""


@dataclass
class HandTrack:
    """One hand's kinematics over ``T`` frames (world frame, metres, axis-angle)."""

    name: str
    """``'right'`` or ``'left'`` (the public data's ``hand_name``)."""
    global_pos: np.ndarray
    """``mano_global_pos`` (T, 3) [m]: MANO translation."""
    global_rot_aa: np.ndarray
    """``mano_global_rot_aa`` (T, 3) [rad]: MANO global orientation."""
    hand_pose: np.ndarray
    """``mano_hand_pose`` (T, 48) [rad]: 3 global + 15 joints × 3, MANO joint order."""
    joint_pos: np.ndarray | None = None
    """``mano_joint_pos`` (T, 21, 3) [m]: keypoints in ``keypoints.MANO21`` order."""
    urdf_dof: np.ndarray | None = None
    """(T, 26) or (T, 28): 6 wrist (xyz [m], XYZ Euler [rad]) + anatomical finger joints [rad]."""
    urdf_dof_target: np.ndarray | None = None
    """Same layout as ``urdf_dof``: the actuated hand's targets, when present."""
    betas: np.ndarray = field(default_factory=lambda: np.zeros(10, np.float32))
    """MANO shape (10,) from ``trajectory_metadata.mano_hand_shapes``."""

    def __post_init__(self) -> None:
        self.global_pos = f32(self.global_pos, (None, 3), f"hands[{self.name}].mano_global_pos")
        T = self.global_pos.shape[0]
        self.global_rot_aa = f32(
            self.global_rot_aa, (T, 3), f"hands[{self.name}].mano_global_rot_aa"
        )
        self.hand_pose = f32(self.hand_pose, (T, 48), f"hands[{self.name}].mano_hand_pose")
        if self.joint_pos is not None:
            self.joint_pos = f32(self.joint_pos, (T, 21, 3), f"hands[{self.name}].mano_joint_pos")
        for attr in ("urdf_dof", "urdf_dof_target"):
            v = getattr(self, attr)
            if v is not None:
                a = f32(v, (T, None), f"hands[{self.name}].{attr}")
                if a.shape[1] not in (26, 28):
                    raise ValidationError(
                        f"hands[{self.name}].{attr} must have 26 or 28 columns, got {a.shape[1]}",
                        field=attr,
                    )
                setattr(self, attr, a)
        self.betas = f32(self.betas, (10,), f"hands[{self.name}].betas")

    @property
    def num_frames(self) -> int:
        return self.global_pos.shape[0]

    @property
    def finger_pose(self) -> np.ndarray:
        """(T, 45) [rad]: the 15 finger joints' axis-angles (``hand_pose[:, 3:]``)."""
        return self.hand_pose[:, 3:]


@dataclass
class ObjectTrack:
    """One object's pose over ``T`` frames (world frame)."""

    name: str
    pos: np.ndarray
    """(T, 3) [m]: position of the object frame's origin."""
    rot_aa: np.ndarray
    """(T, 3) [rad]: orientation, axis-angle."""

    def __post_init__(self) -> None:
        self.pos = f32(self.pos, (None, 3), f"objects[{self.name}].pos")
        self.rot_aa = f32(self.rot_aa, (self.pos.shape[0], 3), f"objects[{self.name}].rot_aa")

    @property
    def num_frames(self) -> int:
        return self.pos.shape[0]


@dataclass
class ObjectMove:
    """A segment of frames during which an object moves (``trajectory_info.object_move``)."""

    object_name: str
    start_frame: int
    end_frame: int
    """Last frame of the segment, inclusive."""
