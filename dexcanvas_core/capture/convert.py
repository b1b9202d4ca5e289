"""A :class:`~dexcanvas_core.capture.arrays.Capture` as a DexCanvas :class:`Trajectory`.

* **Hand**: MANO translation ``mano_global_pos = wrist − J0`` of the hand the keypoints are posed
  with, so that ``ManoLayer`` reproduces the wrist; ``mano_joint_pos`` are the MANO21 keypoints of
  the pose by forward kinematics with the subject's bone lengths measured from the capture's own
  keypoints when it has them (else its betas: the exact MANO model when ``$MANO_MODEL_DIR`` holds
  it, else the built-in skeleton). How far the kinematics land from the capture's keypoints is
  reported (``keypoint_fit_mm``); far apart means a convention is wrong (``flat_hand_mean``,
  joint order).
* **Frame rate**: resampled to ``fps`` (default 120 Hz, the DexCanvas rate the physics is tuned
  at) by linear interpolation of positions and slerp of rotations; ``None`` keeps the capture's.
* **Object motion** (``object_move``): the contact window when given, else the frames from the
  first to the last whose object position is more than 1 cm from its first pose's.
* **Table**: a table top at ``table_height`` under the object's first pose. Its extent is the
  default table's, shrunk on each side that the hand dips below the top, so that a real hand
  that went below table height beyond the real table's edge is not held up by a table that was
  not there. Without ``table_height``: a floor out of reach, 1 m below the capture's lowest point
  (there is no table to rest on).
"""

from __future__ import annotations

import hashlib
import math

import numpy as np

from dexcanvas_core.capture.capture import Capture
from dexcanvas_core.capture.world import object_points_world
from dexcanvas_core.mano import ManoLayer, measure_bone_lengths
from dexcanvas_core.rotations import quat_wxyz_to_aa
from dexcanvas_core.table import DEFAULT_TABLE, Table
from dexcanvas_core.trajectory import HandTrack, ObjectMove, ObjectTrack, Trajectory

DEFAULT_FPS = 120.0
"""Frame rate [Hz] imported sequences are resampled to (DexCanvas' capture rate)."""

MOVE_THRESHOLD_M = 0.01
"""An object farther than this [m] from its first position is moving (``object_move``)."""

NO_TABLE_DROP_M = 1.0
"""Without a table, the floor lies this far [m] below the capture's lowest point."""

TABLE_HAND_CLEARANCE_M = 0.01
"""A hand keypoint this far [m] below the table top marks where the real table was not."""

CAP_MACHINE = "imported"


def _fk(cap: Capture) -> tuple[np.ndarray, np.ndarray]:
    """(keypoints (T, 21, 3) posed at the capture's wrist, J0 of the hand used (3,))."""
    if cap.keypoints is not None:  # the subject's own bone lengths (betas are then moot)
        layer, betas = ManoLayer("right", bone_lengths=measure_bone_lengths(cap.keypoints)), None
    else:
        layer, betas = ManoLayer("right"), cap.betas[None]
    out = layer.forward_numpy(betas=betas, global_orient=cap.global_orient, hand_pose=cap.hand_pose)
    kp = out.keypoints  # posed about the rest wrist J0 (which stays put), no translation
    j0 = kp[0, 0].copy()
    return kp - j0 + cap.wrist_pos[:, None], j0


def keypoint_fit_mm(cap: Capture, kp_fk: np.ndarray) -> float | None:
    """Mean distance [mm] between the kinematics' keypoints and the capture's, or None."""
    if cap.keypoints is None:
        return None
    return float(1000.0 * np.linalg.norm(kp_fk - cap.keypoints, axis=-1).mean())


def object_move_range(cap: Capture) -> tuple[int, int] | None:
    """(first, last) frame of the object's motion (module docstring), or None if it never moves."""
    if cap.contact_window is not None:
        return cap.contact_window
    d = np.linalg.norm(cap.object_pos - cap.object_pos[0], axis=1)
    moving = np.flatnonzero(d > MOVE_THRESHOLD_M)
    if moving.size == 0:
        return None
    return int(moving[0]), int(moving[-1])


def capture_table(cap: Capture, keypoints: np.ndarray) -> Table:
    """The table of a capture (module docstring)."""
    lowest = min(float(keypoints[..., 2].min()), float(cap.object_pos[:, 2].min()))
    if cap.table_height is None:
        return Table(
            top_z_m=lowest - NO_TABLE_DROP_M,
            size_x_m=DEFAULT_TABLE.size_x_m,
            size_y_m=DEFAULT_TABLE.size_y_m,
            center_x_m=float(cap.object_pos[0, 0]),
            center_y_m=float(cap.object_pos[0, 1]),
        )
    top = cap.table_height
    cx, cy = float(cap.object_pos[0, 0]), float(cap.object_pos[0, 1])
    hx, hy = 0.5 * DEFAULT_TABLE.size_x_m, 0.5 * DEFAULT_TABLE.size_y_m
    x_lo, x_hi, y_lo, y_hi = cx - hx, cx + hx, cy - hy, cy + hy
    # The object's resting footprint (first and last frame) must stay on the table.
    rest = np.concatenate([object_points_world(cap, 0), object_points_world(cap, -1)])
    keep_x = (float(rest[:, 0].min()) - 0.02, float(rest[:, 0].max()) + 0.02)
    keep_y = (float(rest[:, 1].min()) - 0.02, float(rest[:, 1].max()) + 0.02)
    below = keypoints.reshape(-1, 3)
    below = below[below[:, 2] < top - TABLE_HAND_CLEARANCE_M]
    for p in below:  # shrink the side nearest to each point below the top, never past the object
        if not (x_lo <= p[0] <= x_hi and y_lo <= p[1] <= y_hi):
            continue
        cuts = {
            "x_hi": (p[0] - keep_x[1], p[0] - 1e-3),
            "x_lo": (keep_x[0] - p[0], p[0] + 1e-3),
            "y_hi": (p[1] - keep_y[1], p[1] - 1e-3),
            "y_lo": (keep_y[0] - p[1], p[1] + 1e-3),
        }
        side, (room, edge) = max(cuts.items(), key=lambda kv: kv[1][0])
        if room <= 0:
            continue  # the hand is under the object's footprint: nothing to cut there
        if side == "x_hi":
            x_hi = edge
        elif side == "x_lo":
            x_lo = edge
        elif side == "y_hi":
            y_hi = edge
        else:
            y_lo = edge
    return Table(
        top_z_m=top,
        size_x_m=x_hi - x_lo,
        size_y_m=y_hi - y_lo,
        center_x_m=0.5 * (x_lo + x_hi),
        center_y_m=0.5 * (y_lo + y_hi),
    )


def capture_uuid(cap: Capture) -> str:
    """A stable id: the source and a hash of the hand and object tracks."""
    h = hashlib.sha256()
    for a in (cap.global_orient, cap.hand_pose, cap.wrist_pos, cap.object_pos):
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    h.update(cap.source.encode())
    return f"import-{cap.name}-{h.hexdigest()[:12]}"


def capture_to_trajectory(
    cap: Capture, *, object_id: str | None = None, fps: float | None = DEFAULT_FPS
) -> tuple[Trajectory, dict]:
    """The capture as a Trajectory (module docstring), and a report dict (``keypoint_fit_mm``,
    ``table``, ``fps_in``, ``frames_in``, ``object_move``).

    Args:
        object_id: the object's id in the dataset (default ``cap.object_name``).
        fps: frame rate to resample to [Hz]; ``None`` keeps the capture's.
    """
    kp, j0 = _fk(cap)
    T = cap.num_frames
    oid = object_id or cap.object_name
    move = object_move_range(cap)
    traj = Trajectory(
        uuid=capture_uuid(cap),
        timestamp=np.arange(T, dtype=np.float64) / cap.fps,
        fps=float(cap.fps),
        hands=[
            HandTrack(
                name="right",
                global_pos=cap.wrist_pos - j0,
                global_rot_aa=cap.global_orient,
                hand_pose=np.concatenate([cap.global_orient, cap.hand_pose], axis=1),
                joint_pos=kp,
                betas=cap.betas,
            )
        ],
        objects=[ObjectTrack(oid, cap.object_pos, quat_wxyz_to_aa(cap.object_quat_wxyz))],
        gesture=cap.manipulation_type,
        operator="imported",
        scene=oid,
        cap_machine=CAP_MACHINE,
        is_generated=False,
        object_move=[] if move is None else [ObjectMove(oid, move[0], move[1])],
    )
    if fps is not None and not math.isclose(fps, cap.fps, rel_tol=1e-6):
        traj = traj.resample(fps)
    table = capture_table(cap, traj.hand.joint_pos)  # every frame the hand passes through
    traj.table = table
    report = {
        "name": cap.name,
        "source": cap.source,
        "frames_in": T,
        "fps_in": cap.fps,
        "frames": traj.num_frames,
        "fps": traj.fps,
        "object": oid,
        "mirrored": cap.mirrored,
        "up": [round(float(v), 4) for v in cap.up],
        "keypoint_fit_mm": keypoint_fit_mm(cap, kp),
        "pose_fitted_to_keypoints": cap.pose_fit_mm is not None,
        "table": None if cap.table_height is None else table.to_dict(),
        "object_move": None if move is None else list(move),
        "ignored_keys": list(cap.ignored_keys),
    }
    return traj.validate(), report
