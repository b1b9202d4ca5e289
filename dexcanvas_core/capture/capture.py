"""The :class:`Capture`: one captured sequence, normalised (right hand, world z up, metres,
MANO's flat-hand-mean pose convention), what every format's reader becomes
(``dexcanvas_core.capture.arrays.capture_from_arrays``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass
class Capture:
    """One captured sequence, normalised: right hand, world z up, metres, flat-hand-mean poses.

    Attributes:
        name: the sequence's name (its file or directory stem).
        source: where it came from (format and path).
        fps: frame rate [Hz].
        global_orient: (T, 3) wrist orientation, axis-angle [rad].
        hand_pose: (T, 45) finger joints [rad], flat-hand-mean convention.
        wrist_pos: (T, 3) wrist joint J0 [m] (from ``transl``: ``J0(betas) + transl``).
        betas: (10,) MANO shape.
        keypoints: (T, 21, 3) MANO21 keypoints [m], or ``None``.
        object_name: the object's id.
        object_pos: (T, 3) [m].
        object_quat_wxyz: (T, 4).
        mesh_vertices: (V, 3) [m] in the object frame (mirrored with the scene).
        mesh_faces: (F, 3) vertex indices.
        mesh_file: the mesh file the vertices came from, ``None`` when inline.
        object_mass_kg: mass [kg] given with the sequence, or ``None``.
        table_height: table top height [m] (world z), or ``None`` (no table).
        contact_window: (first, last) interaction frame, or ``None``.
        manipulation_type: a manipulation type name or ``"unknown"``.
        mirrored: True when a left hand was mirrored to a right one.
        up: the file's up direction (unit 3-vector in its own frame) that became +z.
        ignored_keys: keys of the file this toolkit does not read.
        pose_fit_mm: when the sequence gave keypoints but no pose, the mean keypoint distance
            [mm] of the pose fitted to them (``dexcanvas_core.capture.fit``); else None.
    """

    name: str
    source: str
    fps: float
    global_orient: np.ndarray
    hand_pose: np.ndarray
    wrist_pos: np.ndarray
    betas: np.ndarray
    keypoints: np.ndarray | None
    object_name: str
    object_pos: np.ndarray
    object_quat_wxyz: np.ndarray
    mesh_vertices: np.ndarray
    mesh_faces: np.ndarray
    mesh_file: Path | None = None
    object_mass_kg: float | None = None
    table_height: float | None = None
    contact_window: tuple[int, int] | None = None
    manipulation_type: str = "unknown"
    mirrored: bool = False
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    ignored_keys: tuple[str, ...] = ()
    pose_fit_mm: float | None = None

    @property
    def num_frames(self) -> int:
        return self.global_orient.shape[0]
