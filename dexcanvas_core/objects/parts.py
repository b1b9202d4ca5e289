"""A convex part of an object's collision shape (MuJoCo collides a mesh through its convex hull):
its hull triangles and face planes, volume and centroid. A mesh is split into such parts by
:func:`dexcanvas_core.objects.mesh.convex_parts`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull

# -- convex parts ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class ConvexPart:
    """One convex part of an object's collision shape (object frame, [m]).

    Attributes:
        vertices: ``(V, 3)`` hull vertices.
        faces: ``(F, 3)`` hull triangles, outward winding.
        planes: ``(F, 4)`` outward unit normals and offsets, ``n·x + d ≤ 0`` inside.
    """

    vertices: np.ndarray
    faces: np.ndarray
    planes: np.ndarray

    @classmethod
    def from_points(cls, points: np.ndarray) -> ConvexPart:
        """The convex hull of ``points (N, 3)`` [m]."""
        pts = np.asarray(points, dtype=np.float64)
        hull = ConvexHull(pts)
        used = np.unique(hull.simplices)
        remap = np.full(len(pts), -1)
        remap[used] = np.arange(len(used))
        verts = pts[used]
        faces = remap[hull.simplices]
        planes = hull.equations.copy()
        # orient each triangle along its plane's outward normal
        a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
        flip = np.einsum("ij,ij->i", np.cross(b - a, c - a), planes[:, :3]) < 0
        faces[flip] = faces[flip][:, ::-1]
        return cls(verts, faces, planes)

    @property
    def volume_m3(self) -> float:
        v = self.vertices
        a, b, c = v[self.faces[:, 0]], v[self.faces[:, 1]], v[self.faces[:, 2]]
        return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)

    @property
    def centroid(self) -> np.ndarray:
        """``(3,)`` centre of volume [m]."""
        v = self.vertices
        a, b, c = v[self.faces[:, 0]], v[self.faces[:, 1]], v[self.faces[:, 2]]
        vol = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
        return (vol[:, None] * (a + b + c) / 4.0).sum(0) / vol.sum()

    def scaled(self, factor: float) -> ConvexPart:
        p = self.planes.copy()
        p[:, 3] *= factor
        return ConvexPart(self.vertices * factor, self.faces, p)
