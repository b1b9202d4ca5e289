"""A trajectory written as a ``mano-npz`` capture (the format ``dexcanvas import`` reads).

Used to hand a demonstration to other tools in a plain format, and to build captures with a
known answer (tests, the real-motion benchmark's generated motions).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from dexcanvas_core.keypoints import convert_keypoints
from dexcanvas_core.rotations import aa_to_matrix, aa_to_quat_wxyz
from dexcanvas_core.safe_io import atomic_path
from dexcanvas_core.table import table_of
from dexcanvas_core.trajectory import Trajectory


def geometry_mesh(geometry) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices (V, 3) [m], faces (F, 3))`` of an object geometry in its object frame: a mesh
    object's surface, or the union of a primitive composition's primitives (one closed surface,
    ``trimesh.boolean.union`` with the ``manifold3d`` engine)."""
    import trimesh

    if geometry.visual is not None:
        v, f = geometry.visual
        return np.asarray(v, np.float64), np.asarray(f, np.int64)
    parts = []
    for p in geometry.primitives:
        s = p.size
        if p.type == "box":
            m = trimesh.creation.box(extents=2 * np.asarray(s[:3]))
        elif p.type == "sphere":
            m = trimesh.creation.icosphere(subdivisions=3, radius=s[0])
        elif p.type == "cylinder":
            m = trimesh.creation.cylinder(radius=s[0], height=2 * s[1], sections=48)
        elif p.type == "capsule":
            m = trimesh.creation.capsule(radius=s[0], height=2 * s[1], count=(24, 24))
        else:  # a convex part of a mesh object
            m = trimesh.convex.convex_hull(p.part.vertices)
        T = np.eye(4)
        T[:3, :3] = aa_to_matrix(np.asarray(p.rot_aa, float))
        T[:3, 3] = p.pos
        if p.type != "mesh":
            m.apply_transform(T)
        parts.append(m)
    mesh = parts[0] if len(parts) == 1 else trimesh.boolean.union(parts, engine="manifold")
    return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)


def trajectory_to_arrays(
    traj: Trajectory,
    mesh: tuple[np.ndarray, np.ndarray],
    *,
    mass_kg: float | None = None,
    keypoints: bool = True,
) -> dict[str, np.ndarray]:
    """The ``mano-npz`` keys of a single-hand, single-object right-hand trajectory (z up, its
    table's top as ``table_height``, its object motion as ``contact_window``)."""
    h, o = traj.hand, traj.object
    if h.joint_pos is None:
        raise ValueError("the trajectory has no mano_joint_pos (keypoints)")
    out = {
        "fps": np.float64(traj.fps),
        "global_orient": h.global_rot_aa.astype(np.float64),
        "hand_pose": h.hand_pose[:, 3:].astype(np.float64),
        "flat_hand_mean": np.bool_(True),
        "wrist_pos": h.joint_pos[:, 0].astype(np.float64),
        "betas": h.betas.astype(np.float64),
        "object_name": np.str_(traj.scene or o.name),
        "object_pos": o.pos.astype(np.float64),
        "object_quat_wxyz": aa_to_quat_wxyz(o.rot_aa.astype(np.float64)),
        "object_vertices": mesh[0],
        "object_faces": mesh[1],
        "up_axis": np.str_("z"),
        "table_height": np.float64(table_of(traj).top_z_m),
        "manipulation_type": np.str_(traj.gesture or "unknown"),
    }
    if keypoints:
        out["keypoints"] = convert_keypoints(h.joint_pos.astype(np.float64), "mano21", "openpose21")
    if mass_kg is not None:
        out["object_mass_kg"] = np.float64(mass_kg)
    if traj.object_move:
        m = traj.object_move[0]
        out["contact_window"] = np.array([m.start_frame, m.end_frame], np.int64)
    return out


def write_mano_npz(path: str | os.PathLike, arrays: dict[str, np.ndarray]) -> Path:
    """Write ``arrays`` as an ``.npz`` (no pickles), atomically."""
    p = Path(path).expanduser()
    with atomic_path(p) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
    return p
