"""An object's collision shape as convex parts (MuJoCo collides a mesh through its convex hull):
a convex mesh is its own hull, a non-convex one is split by approximate convex decomposition
(``coacd``, Wei et al. 2022), each part decimated to ``MAX_HULL_VERTICES`` vertices.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import ConvexHull

from dexcanvas_core.errors import MissingDependencyError, ValidationError

if TYPE_CHECKING:
    from dexcanvas_core.objects.mesh import ObjectMesh


COACD_THRESHOLD = 0.04
"""``coacd`` concavity threshold: the largest concavity a part may keep, relative to the mesh's
size (smaller: more, tighter parts)."""

MAX_HULL_VERTICES = 64
"""Vertices per convex part kept for physics (``coacd``'s ``max_ch_vertex``)."""


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


def convex_parts(mesh: ObjectMesh) -> list[ConvexPart]:
    """The mesh's collision shape as convex parts: its hull if convex, else ``coacd``'s parts."""
    if mesh.convex:
        return [ConvexPart.from_points(mesh.vertices)]
    try:
        import coacd
    except ImportError as e:  # pragma: no cover - a declared dependency
        raise MissingDependencyError("coacd", "non-convex mesh objects") from e
    coacd.set_log_level("error")
    parts = coacd.run_coacd(
        coacd.Mesh(mesh.vertices, mesh.faces),
        threshold=COACD_THRESHOLD,
        decimate=True,  # each part at most MAX_HULL_VERTICES vertices
        max_ch_vertex=MAX_HULL_VERTICES,
        seed=0,
    )
    out = []
    for verts, _faces in parts:
        verts = np.asarray(verts, dtype=np.float64)
        if len(verts) >= 4 and np.linalg.matrix_rank(verts - verts.mean(0), tol=1e-7) == 3:
            out.append(ConvexPart.from_points(verts))
    if not out:
        raise ValidationError(f"object mesh {mesh.source!r}: convex decomposition found no solid")
    return out
