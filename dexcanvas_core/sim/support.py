"""Does a captured object rest on the table by itself at its first pose?

Real captures show objects leaning on things that were not captured (DexYCB's scenes hold
several objects; the grasped one may lean on a box). Simulated alone on the table, such an
object falls over before the hand reaches it, and the rollout fails for a reason that is not
the hand's. :func:`rests_stably` tells them apart from the geometry: the object's lowest point
must be on the table top (within :data:`SUPPORT_GAP_M`) and its centre of mass over its support
polygon (the convex hull, seen from above, of its points within :data:`CONTACT_BAND_M` of the
lowest), :data:`COM_MARGIN_M` inside it. The simulators (the force pipeline and the robot's
re-simulation) hold such an object at its captured pose, by a weld, until the demonstration
starts moving it (:func:`hold_until_frame`), and say so in their metrics.
"""

from __future__ import annotations

import numpy as np

from dexcanvas_core.rotations import aa_to_matrix

SUPPORT_GAP_M = 0.005
"""An object whose lowest point is higher than this above the table top [m] rests on
something else."""
CONTACT_BAND_M = 0.003
"""Points this close [m] to the lowest one make the support polygon."""
COM_MARGIN_M = 0.002
"""The centre of mass must lie this far [m] inside the support polygon."""
MOVE_M = 0.002
"""The demonstration starts moving the object when it is this far [m] from its first pose."""


def _surface_points(geometry) -> np.ndarray:
    """``(N, 3)`` points of the object's surface in its frame (mesh vertices; a primitive
    composition's convex parts or sampled primitives)."""
    if geometry.visual is not None:
        return np.asarray(geometry.visual[0], dtype=np.float64)
    pts = []
    for prim in geometry.primitives:
        if prim.type == "mesh":
            pts.append(prim.part.vertices)
            continue
        s = np.asarray(prim.size, dtype=np.float64)
        if prim.type == "box":
            c = np.array(np.meshgrid(*[[-1.0, 1.0]] * 3)).reshape(3, -1).T * s[:3]
        else:  # sphere, cylinder, capsule: a ring of points at each end, and the poles
            r = s[0]
            h = 0.0 if prim.type == "sphere" else s[1]
            a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
            ring = np.stack([r * np.cos(a), r * np.sin(a), np.zeros_like(a)], axis=1)
            up = np.array([0.0, 0.0, h])
            ends = [ring + up, ring - up]
            if prim.type != "cylinder":
                ends += [np.array([[0, 0, h + r], [0, 0, -h - r]])]
            c = np.concatenate(ends)
        pts.append(c @ prim.R.T + np.asarray(prim.pos))
    return np.concatenate(pts)


def _inside(poly_xy: np.ndarray, q: np.ndarray, margin: float) -> bool:
    """Whether ``q`` lies ``margin`` inside the convex hull of ``poly_xy``."""
    from scipy.spatial import ConvexHull, QhullError

    if len(poly_xy) < 3:
        return False
    try:
        hull = ConvexHull(poly_xy)
    except QhullError:  # collinear support: a line or a point
        return False
    # hull.equations: n·x + d <= 0 inside, with unit normals n
    return bool(np.all(hull.equations[:, :2] @ q + hull.equations[:, 2] <= -margin))


def rests_stably(geometry, rot_aa: np.ndarray, pos: np.ndarray, table_top_z: float) -> bool:
    """Whether the object posed at ``(rot_aa, pos)`` rests on a table top at ``table_top_z``
    [m] by itself (module docstring)."""
    R = aa_to_matrix(np.asarray(rot_aa, dtype=np.float64))
    w = _surface_points(geometry) @ R.T + np.asarray(pos, dtype=np.float64)
    low = float(w[:, 2].min())
    if low - table_top_z > SUPPORT_GAP_M:
        return False
    support = w[w[:, 2] <= low + CONTACT_BAND_M, :2]
    com = R @ np.asarray(geometry.com, dtype=np.float64) + np.asarray(pos, dtype=np.float64)
    return _inside(support, com[:2], COM_MARGIN_M)


def hold_until_frame(geometry, traj, table_top_z: float) -> int:
    """0 when the trajectory's object rests by itself at its first pose; else the first frame
    at which the demonstration has moved it :data:`MOVE_M` (the object is held before)."""
    o = traj.object
    if rests_stably(geometry, o.rot_aa[0], o.pos[0], table_top_z):
        return 0
    moved = np.flatnonzero(np.linalg.norm(o.pos - o.pos[0], axis=1) > MOVE_M)
    return int(moved[0]) if moved.size else traj.num_frames
