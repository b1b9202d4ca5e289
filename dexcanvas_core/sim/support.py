"""Does a captured object rest on the table by itself at its first pose?

Real captures show objects leaning on things that were not captured (DexYCB's scenes hold
several objects; the grasped one may lean on a box). Simulated alone on the table, such an
object falls over before the hand reaches it, and the rollout fails for a reason that is not
the hand's. :func:`rests_stably` tells them apart from the geometry: the object's lowest point
must be on the table top (within :data:`SUPPORT_GAP_M`) and its centre of mass over its support
polygon (the convex hull, seen from above, of its points within :data:`CONTACT_BAND_M` of the
lowest), :data:`COM_MARGIN_M` inside it; a point or line support (a ball, a lying cylinder, a
box on an edge) must keep the centre of mass from sinking when tipped a little. The simulators
(the force pipeline and the robot's re-simulation) hold such an object at its captured pose,
by a weld, until the demonstration starts moving it (:func:`hold_until_frame`), and say so in
their metrics.
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
        elif prim.type == "cylinder":  # a dense ring at each end
            r, h = s[0], s[1]
            a = np.linspace(0, 2 * np.pi, 72, endpoint=False)
            ring = np.stack([r * np.cos(a), r * np.sin(a), np.zeros_like(a)], axis=1)
            up = np.array([0.0, 0.0, h])
            c = np.concatenate([ring + up, ring - up])
        else:  # sphere, capsule: a dense sphere, its halves apart by the capsule's length
            r = s[0]
            h = 0.0 if prim.type == "sphere" else s[1]
            k = np.arange(800) + 0.5
            z = 1.0 - 2.0 * k / 800  # a Fibonacci sphere, about 7° between points
            rho = np.sqrt(1.0 - z * z)
            phi = np.pi * (3.0 - np.sqrt(5.0)) * k
            c = r * np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)
            c[:, 2] += np.where(c[:, 2] >= 0, h, -h)
        pts.append(c @ prim.R.T + np.asarray(prim.pos))
    return np.concatenate(pts)


def _inside(poly_xy: np.ndarray, q: np.ndarray, margin: float) -> bool | None:
    """Whether ``q`` lies ``margin`` inside the convex hull of ``poly_xy``; None when the support
    is a point or a line (a ball, a cylinder on its side, a box on an edge), which the hull
    cannot tell."""
    from scipy.spatial import ConvexHull, QhullError

    if len(poly_xy) < 3:
        return None
    try:
        hull = ConvexHull(poly_xy)
    except QhullError:  # collinear support
        return None
    if hull.volume < 1e-6:  # a sliver (< 1 cm²): a line for all purposes
        return None
    # hull.equations: n·x + d <= 0 inside, with unit normals n
    return bool(np.all(hull.equations[:, :2] @ q + hull.equations[:, 2] <= -margin))


TILT_RAD = np.radians(12.0)
"""Tilt of the balance test of a point or line support (more than the spacing of the points
that sample a curved surface)."""
SINK_FRACTION = 0.25
"""Tipped about a point or line support, the centre of mass may sink by at most this fraction
of what it sinks about a fixed pivot (a box on an edge: all of it; a ball: none)."""


def _balanced(w: np.ndarray, com: np.ndarray, support: np.ndarray, top: float) -> bool:
    """A point or line support: tipped by :data:`TILT_RAD` about the support (both ways, about
    each horizontal axis for a point, about the line for a line) and set back on the table, the
    centre of mass must not sink (a ball or a lying cylinder rolls at the same height: stable;
    a box on an edge falls: not)."""
    c = support.mean(axis=0)
    d = support - c
    if np.abs(d).max() < 1e-4:
        axes = [np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])]
    else:
        u = np.linalg.svd(d, full_matrices=False)[2][0]
        axes = [np.array([u[0], u[1], 0.0]) / np.hypot(u[0], u[1])]
    pivot = np.array([c[0], c[1], top])
    for a in axes:
        for sgn in (1.0, -1.0):
            R = aa_to_matrix(sgn * TILT_RAD * a)
            pts = (w - pivot) @ R.T + pivot
            z_pivot = (R @ (com - pivot) + pivot)[2]
            z = z_pivot + (top - pts[:, 2].min())
            if com[2] - z > SINK_FRACTION * (com[2] - z_pivot) + 1e-9:
                return False
    return True


def rests_stably(geometry, rot_aa: np.ndarray, pos: np.ndarray, table_top_z: float) -> bool:
    """Whether the object posed at ``(rot_aa, pos)`` rests on a table top at ``table_top_z``
    [m] by itself (module docstring)."""
    R = aa_to_matrix(np.asarray(rot_aa, dtype=np.float64))
    w = _surface_points(geometry) @ R.T + np.asarray(pos, dtype=np.float64)
    low = float(w[:, 2].min())
    if low - table_top_z > SUPPORT_GAP_M:
        return False
    support = w[w[:, 2] <= low + CONTACT_BAND_M]
    com = R @ np.asarray(geometry.com, dtype=np.float64) + np.asarray(pos, dtype=np.float64)
    inside = _inside(support[:, :2], com[:2], COM_MARGIN_M)
    if inside is None:
        return _balanced(w, com, support, low)
    return inside


def hold_until_frame(geometry, traj, table_top_z: float) -> int:
    """0 when the trajectory's object rests by itself at its first pose; else the first frame
    at which the demonstration has moved it :data:`MOVE_M` (the object is held before)."""
    o = traj.object
    if rests_stably(geometry, o.rot_aa[0], o.pos[0], table_top_z):
        return 0
    moved = np.flatnonzero(np.linalg.norm(o.pos - o.pos[0], axis=1) > MOVE_M)
    return int(moved[0]) if moved.size else traj.num_frames
