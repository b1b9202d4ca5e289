"""Anatomical joint frames and range-of-motion limits for MANO's 15 finger joints.

MANO stores each finger joint as an axis-angle vector in the template frame (rest orientations
are identity). For limits we read that vector in an anatomical frame per joint, built from the
rest bone leaving the joint (the bone to the next joint or the fingertip):

* ``twist`` — along the bone (distal direction);
* ``flex``  — the axis about which a positive rotation moves the distal bone toward the palm
  (the volar side, template ``-y``): ``flex = normalise(bone × (-y))``; for index…pinky this is
  template ``+z`` (right hand), matching MANO's positive-z flexion;
* ``abd``   — completes the right-handed frame, ``abd = twist × flex`` (rotation in the palm
  plane; its sign is not anatomical "ab-" vs "adduction" for every finger, so limits are
  symmetric except for the thumb's CMC).

``anatomical_angles(pose45)`` returns the components ``(flex, abd, twist)`` [rad] of each
joint's axis-angle vector in that frame (exact for single-axis rotations, a close approximation
for the small combined rotations of the distal joints). ``limit_violation`` returns how far each
component lies outside ``[LOW, HIGH]`` and works on numpy arrays and torch tensors alike, so the
mocap fitter can use it as a soft prior and the demonstration generator as a hard check.

Limits are active ranges of motion of the adult hand, generous on purpose (they bound plausible
human data, not a specific subject):

* finger MCP flexion −20°…90°, abduction ±20° (little finger ±25°), PIP 0…110°, DIP −10…80°:
  Hume et al. 1990, "Functional range of motion of the joints of the hand", J Hand Surg 15A;
  Bain et al. 2015, "The functional range of motion of the finger joints", J Hand Surg Eur 40;
* thumb CMC flexion/extension and abduction ±45°–50°, MCP −15…70°, IP −20…85°:
  Hume et al. 1990; Jenkins et al. 1998, "Thumb joint flexion: what is normal?", J Hand Surg Br;
* axial twist is not an active DoF of the finger joints; MANO fits still show some, so twist is
  bounded at ±15°–20° (thumb CMC ±35°: its opposition includes pronation, Cooney et al. 1981).
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import numpy as np

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import MANO21, MANO_JOINTS
from dexcanvas_core.mano.skeleton import HandSkeleton

ANGLE_NAMES: tuple[str, str, str] = ("flex", "abd", "twist")

_D = np.deg2rad


def _limits_for(joint: str) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    finger, level = joint[:-1], int(joint[-1])
    if finger == "thumb":
        table = {
            1: ((-45, -50, -35), (50, 50, 35)),  # CMC
            2: ((-15, -20, -20), (70, 20, 20)),  # MCP
            3: ((-20, -10, -15), (85, 10, 15)),  # IP
        }
    else:
        abd = 25 if finger == "pinky" else 20
        table = {
            1: ((-20, -abd, -15), (90, abd, 15)),  # MCP
            2: ((0, -10, -15), (110, 10, 15)),  # PIP
            3: ((-10, -10, -15), (80, 10, 15)),  # DIP
        }
    lo, hi = table[level]
    return tuple(_D(lo)), tuple(_D(hi))  # type: ignore[return-value]


FINGER_JOINTS: tuple[str, ...] = MANO_JOINTS[1:]
"""The 15 finger joints in MANO order (rows of the arrays below)."""

LOW = np.array([_limits_for(j)[0] for j in FINGER_JOINTS])
"""(15, 3) lower limits [rad] of (flex, abd, twist) per finger joint (MANO order)."""
HIGH = np.array([_limits_for(j)[1] for j in FINGER_JOINTS])
"""(15, 3) upper limits [rad]."""


@lru_cache(maxsize=2)
def joint_frames(side: str = "right") -> np.ndarray:
    """(15, 3, 3): rows (flex, abd, twist) unit axes of each finger joint, template frame."""
    if side not in ("right", "left"):
        raise ValidationError(f"side must be 'right' or 'left', got {side!r}", field="side")
    # Built on the right hand; the left frames are their mirror images (see below).
    kp = HandSkeleton.default("right").rest_keypoints
    volar = np.array([0.0, -1.0, 0.0])
    frames = np.zeros((15, 3, 3))
    for k, joint in enumerate(FINGER_JOINTS):
        finger, level = joint[:-1], int(joint[-1])
        child = MANO21.index(f"{finger}{level + 1}" if level < 3 else f"{finger}_tip")
        twist = kp[child] - kp[MANO21.index(joint)]
        twist /= np.linalg.norm(twist)
        flex = np.cross(twist, volar)
        flex /= np.linalg.norm(flex)
        abd = np.cross(twist, flex)
        frames[k] = (flex, abd, twist)
    if side == "left":
        # Mirroring x → -x maps a right-hand axis-angle (x, y, z) to (x, -y, -z) for the same
        # anatomical motion; express the frame rows in that convention.
        frames = frames * np.array([1.0, -1.0, -1.0])
    frames.setflags(write=False)
    return frames


def anatomical_angles(pose45: Any, side: str = "right") -> Any:
    """``(..., 15, 3)`` (flex, abd, twist) [rad] from ``(..., 45)`` MANO finger axis-angles.

    Accepts numpy arrays or torch tensors (differentiable); returns the same kind.
    """
    F = joint_frames(side)
    shape = tuple(pose45.shape)
    if shape[-1] != 45:
        raise ValidationError(f"pose must have shape (..., 45), got {shape}", field="hand_pose")
    r = pose45.reshape((*shape[:-1], 15, 3))
    if isinstance(pose45, np.ndarray):
        return np.einsum("jab,...jb->...ja", F, r)
    import torch

    Ft = torch.tensor(F, dtype=pose45.dtype, device=pose45.device)
    return torch.einsum("jab,...jb->...ja", Ft, r)


def limit_violation(pose45: Any, side: str = "right", margin: float = 0.0) -> Any:
    """``(..., 15, 3)`` [rad]: how far each anatomical angle lies outside ``[LOW-margin,
    HIGH+margin]`` (0 inside). numpy in → numpy out; torch in → torch out (differentiable)."""
    ang = anatomical_angles(pose45, side)
    if isinstance(ang, np.ndarray):
        return np.maximum(LOW - margin - ang, 0.0) + np.maximum(ang - HIGH - margin, 0.0)
    import torch

    lo = torch.as_tensor(LOW - margin, dtype=ang.dtype, device=ang.device)
    hi = torch.as_tensor(HIGH + margin, dtype=ang.dtype, device=ang.device)
    return torch.relu(lo - ang) + torch.relu(ang - hi)


def pose_from_anatomical(angles: np.ndarray, side: str = "right") -> np.ndarray:
    """Inverse of :func:`anatomical_angles`: ``(..., 15, 3)`` angles → ``(..., 45)`` axis-angles."""
    a = np.asarray(angles, dtype=np.float64)
    if a.shape[-2:] != (15, 3):
        raise ValidationError(f"angles must have shape (..., 15, 3), got {a.shape}", field="angles")
    r = np.einsum("jab,...ja->...jb", joint_frames(side), a)  # frames are orthonormal: F^T a
    return r.reshape((*a.shape[:-2], 45))
