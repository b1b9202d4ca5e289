"""The capture's world: its up direction turned to +z, a left hand mirrored to a right one, and
the check that the object rests on the table the capture names.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from typing import Any

import numpy as np

from dexcanvas_core.capture.capture import Capture
from dexcanvas_core.errors import ValidationError
from dexcanvas_core.mano.pose import mirror_axis_angle
from dexcanvas_core.rotations import (
    aa_to_matrix,
    matrix_to_aa,
    matrix_to_quat_wxyz,
    quat_wxyz_to_matrix,
)

log = logging.getLogger(__name__)

_AXES = {"x": 0, "y": 1, "z": 2}


def up_vector(up: Any, where: str = "up_axis") -> np.ndarray:
    """The unit up vector of ``up``: an axis name (``'z'``, ``'y'``, ``'-y'``, …) or a 3-vector.

    Raises:
        ValidationError: anything else.
    """
    if isinstance(up, bytes):
        up = up.decode()
    if isinstance(up, np.ndarray) and up.shape == ():
        up = up.item()
    if isinstance(up, str):
        s = up.strip().lower()
        sign = -1.0 if s.startswith("-") else 1.0
        axis = s.lstrip("+-")
        if axis not in _AXES:
            raise ValidationError(
                f"{where}: up_axis {up!r} is not an axis; give 'z' (default), 'y', '-y', 'x', … "
                "or a 3-vector pointing against gravity",
                field="up_axis",
            )
        v = np.zeros(3)
        v[_AXES[axis]] = sign
        return v
    try:
        v = np.asarray(up, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        v = np.zeros(0)
    n = float(np.linalg.norm(v)) if v.shape == (3,) else 0.0
    if v.shape != (3,) or not math.isfinite(n) or n < 1e-6:
        raise ValidationError(
            f"{where}: up_axis must be 'z', 'y', … or a non-zero 3-vector, got {up!r}",
            field="up_axis",
        )
    return v / n


def rotation_to_z_up(up: np.ndarray) -> np.ndarray:
    """(3, 3) rotation taking the unit vector ``up`` to +z (the smallest such rotation; for
    ``up = -z``, half a turn about x)."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(up, z)
    s, c = float(np.linalg.norm(axis)), float(np.dot(up, z))
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    return aa_to_matrix(axis / s * math.atan2(s, c))


def mirror_capture(cap: Capture) -> Capture:
    """The scene mirrored across the world's x = 0 plane: a left hand becomes the right hand that
    mirrors it (axis-angles ``(x, y, z) → (x, -y, -z)``), the object's poses and mesh are
    mirrored too (faces flipped to keep outward normals)."""
    M = np.diag([-1.0, 1.0, 1.0])

    def pts(a):
        return None if a is None else a * np.array([-1.0, 1.0, 1.0])

    R = quat_wxyz_to_matrix(cap.object_quat_wxyz)
    return dataclasses.replace(
        cap,
        global_orient=mirror_axis_angle(cap.global_orient),
        hand_pose=mirror_axis_angle(cap.hand_pose),
        wrist_pos=pts(cap.wrist_pos),
        keypoints=pts(cap.keypoints),
        object_pos=pts(cap.object_pos),
        object_quat_wxyz=matrix_to_quat_wxyz(M @ R @ M),
        mesh_vertices=pts(cap.mesh_vertices),
        mesh_faces=cap.mesh_faces[:, ::-1].copy(),
        up=M @ cap.up,
        mirrored=True,
    )


def to_z_up(cap: Capture, where: str) -> Capture:
    """Rotate the scene so that ``cap.up`` becomes +z, and check the table against it."""
    Q = rotation_to_z_up(cap.up)
    if not np.allclose(Q, np.eye(3)):

        def pts(a):
            return None if a is None else a @ Q.T

        R = aa_to_matrix(cap.global_orient)
        Ro = quat_wxyz_to_matrix(cap.object_quat_wxyz)
        cap = dataclasses.replace(
            cap,
            global_orient=matrix_to_aa(Q @ R),
            wrist_pos=pts(cap.wrist_pos),
            keypoints=pts(cap.keypoints),
            object_pos=pts(cap.object_pos),
            object_quat_wxyz=matrix_to_quat_wxyz(Q @ Ro),
        )
    if cap.table_height is not None:
        check_table_height(cap, where)
    return cap


def object_points_world(cap: Capture, frame: int) -> np.ndarray:
    """(V, 3) the mesh's vertices in the world at ``frame``."""
    R = quat_wxyz_to_matrix(cap.object_quat_wxyz[frame])
    return cap.mesh_vertices @ R.T + cap.object_pos[frame]


TABLE_REST_TOLERANCE_M = 0.03
"""The object's lowest point at the first frame may lie this far [m] from ``table_height``."""


def check_table_height(cap: Capture, where: str) -> None:
    """The object rests on the table at the first frame: its lowest point should sit at
    ``table_height`` (within :data:`TABLE_REST_TOLERANCE_M`).

    An object sunk into the table, or off it where another up axis would put it on it, means the
    up axis or the table height is wrong: an error naming the axes that fit. An object above the
    table with no axis fitting better starts on something else (another object): a warning.
    """
    pts = object_points_world(cap, 0)
    gap = float(pts[:, 2].min() - cap.table_height)
    if abs(gap) <= TABLE_REST_TOLERANCE_M:
        return
    # Which axis of the file would have put the object on the table?
    Q = rotation_to_z_up(cap.up)
    file_pts = pts @ Q  # back in the file's frame (pts = file @ Q.T)
    fits = []
    for axis in ("x", "y", "z", "-x", "-y", "-z"):
        u = up_vector(axis)
        if abs(float((file_pts @ u).min()) - cap.table_height) <= TABLE_REST_TOLERANCE_M:
            fits.append(axis)
    if gap > 0 and not fits:
        log.warning(
            "%s: at frame 0 the object's lowest point is %.3f m above the table: it starts on "
            "something else",
            where,
            gap,
        )
        return
    hint = (
        f"; with up_axis {' or '.join(repr(a) for a in fits)} it would rest on it"
        if fits
        else "; no axis makes it rest there: check table_height (metres, along the up axis)"
    )
    raise ValidationError(
        f"{where}: at frame 0 the object's lowest point is {gap:+.3f} m from table_height="
        f"{cap.table_height:g} along the up axis {np.round(cap.up, 3).tolist()}: the object "
        f"should rest on the table (is up_axis right?){hint}",
        field="up_axis",
    )
