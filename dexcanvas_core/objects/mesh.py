"""Objects given as triangle meshes: loading, checks, convex decomposition, a signed distance.

A mesh object is described by a file (OBJ, STL, PLY, GLB; read with ``trimesh``) whose own frame
is the object frame — the frame a capture tracks — scaled by ``scale`` (metres per mesh unit).
:func:`load_object_mesh` reads and checks it before any work is done: the file must be readable,
closed (a solid with a volume: an open surface has none, so it has no mass distribution and no
inside), and of a size a hand can hold (5 mm to 1 m across; a mesh in millimetres read as metres
is 1000× too large and is refused with the fix, ``scale = 0.001``).

:func:`mesh_collision` turns it into what physics and geometry queries need, cached on disk by
the mesh's content hash (a second run reads the cache, it does not decompose again):

* **Convex parts.** MuJoCo collides a mesh geom through its convex hull, so a convex mesh is used
  as it is, and a non-convex one (a bowl, a clamp, scissors, a mug) is first split into convex
  parts by approximate convex decomposition (``coacd``, Wei et al. 2022).
* **A signed-distance grid** of the union of those parts (the shape physics collides with):
  distances [m] on a regular grid around the object, negative inside, evaluated by trilinear
  interpolation with its analytic gradient as the normal. Distances are exact at the grid nodes
  (the closest of the parts' triangles, found among candidates from a k-d tree of surface
  samples); the sign is "inside some convex part".
"""

from __future__ import annotations

import hashlib
import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull, cKDTree

from dexcanvas_core.builtin import cache_dir
from dexcanvas_core.errors import MissingDependencyError, ValidationError

log = logging.getLogger(__name__)

MESH_SUFFIXES: tuple[str, ...] = (".obj", ".stl", ".ply", ".glb", ".gltf", ".off")
"""File types :func:`load_object_mesh` reads (``trimesh``'s loaders)."""

MIN_EXTENT_M = 0.005
"""Smallest accepted object extent [m] (a mesh in metres read with ``scale = 0.001`` is below)."""

MAX_EXTENT_M = 1.0
"""Largest accepted object extent [m] (a mesh in millimetres read as metres is far above)."""

COACD_THRESHOLD = 0.04
"""``coacd`` concavity threshold: the largest concavity a part may keep, relative to the mesh's
size (smaller: more, tighter parts)."""

MAX_HULL_VERTICES = 64
"""Vertices per convex part kept for physics (``coacd``'s ``max_ch_vertex``)."""

SDF_MAX_NODES = 64
"""Grid nodes along the object's longest axis (with the padding)."""

SDF_MIN_SPACING_M = 0.001
"""Finest grid spacing [m]."""

SDF_PAD_M = 0.03
"""Grid margin around the object [m]; beyond it distances are extrapolated."""

CACHE_VERSION = 3
"""Bumped when the cached decomposition or grid changes meaning."""


@dataclass(frozen=True)
class ObjectMesh:
    """A checked object mesh in the object frame [m].

    Attributes:
        vertices: ``(V, 3)`` vertices [m] (after ``scale``).
        faces: ``(F, 3)`` triangles, outward winding.
        source: the file it was read from.
        digest: sha256 of the file's bytes and the scale (the cache key).
        volume_m3: enclosed volume [m³].
        convex: the mesh is its own convex hull (no decomposition needed).
    """

    vertices: np.ndarray
    faces: np.ndarray
    source: str
    digest: str
    volume_m3: float
    convex: bool

    @property
    def extent_m(self) -> np.ndarray:
        """``(3,)`` axis-aligned size [m] in the object frame."""
        return self.vertices.max(axis=0) - self.vertices.min(axis=0)


def _trimesh():
    try:
        import trimesh
    except ImportError as e:  # pragma: no cover - a declared dependency
        raise MissingDependencyError("trimesh", "mesh objects") from e
    return trimesh


def load_object_mesh(path: str | os.PathLike, scale: float = 1.0) -> ObjectMesh:
    """Read and check an object mesh; ``scale`` converts mesh units to metres.

    Raises:
        ValidationError: the file is missing, unreadable or of an unknown type, the surface is
            open (no volume), the scale is not positive, or the scaled mesh is not 5 mm – 1 m
            across (the message suggests the scale that fixes a unit mistake).
    """
    p = Path(path).expanduser()
    where = f"object mesh {str(p)!r}"
    if not (isinstance(scale, int | float) and math.isfinite(scale) and scale > 0):
        raise ValidationError(f"{where}: scale must be a positive number, got {scale!r}")
    if not p.is_file():
        raise ValidationError(f"{where}: no such file", field="mesh")
    if p.suffix.lower() not in MESH_SUFFIXES:
        raise ValidationError(
            f"{where}: unknown mesh type {p.suffix!r}; use one of {', '.join(MESH_SUFFIXES)}",
            field="mesh",
        )
    trimesh = _trimesh()
    data = p.read_bytes()
    try:
        loaded = trimesh.load(p, force="mesh", process=False)
    except Exception as e:  # trimesh raises many types for a bad file
        raise ValidationError(f"{where}: cannot be read ({type(e).__name__}: {e})") from e
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise ValidationError(f"{where}: holds no triangles", field="mesh")
    # Geometry only: textured files split vertices along UV seams, which would leave a closed
    # surface looking open; a plain mesh merges them by position.
    mesh = trimesh.Trimesh(loaded.vertices, loaded.faces, process=True)
    mesh.apply_scale(float(scale))
    extent = mesh.extents
    if not np.all(np.isfinite(mesh.vertices)):
        raise ValidationError(f"{where}: has non-finite vertices", field="mesh")
    big = float(extent.max())
    if big > MAX_EXTENT_M or big < MIN_EXTENT_M:
        fix = 10.0 ** round(math.log10(0.1 / big)) if big > 0 else None
        hint = (
            f"; if the file is in other units give scale = {fix * scale:g} "
            f"(it would then span {big * fix * 100:.1f} cm)"
            if fix
            else ""
        )
        raise ValidationError(
            f"{where}: spans {big:.4g} m at scale {scale:g}, outside the {MIN_EXTENT_M * 1e3:.0f}"
            f" mm – {MAX_EXTENT_M:g} m of an object a hand holds{hint}",
            field="scale",
        )
    if not mesh.is_watertight:
        trimesh.repair.fill_holes(mesh)
    if not mesh.is_watertight or not mesh.is_volume:
        open_edges = _open_edge_count(mesh)
        raise ValidationError(
            f"{where}: is not a closed surface ({open_edges} open edges), so it has no volume "
            "and no inside; an object needs a solid: close the surface (e.g. Blender's 3D-Print "
            "toolbox, or trimesh.repair) and try again",
            field="mesh",
        )
    if mesh.volume < 0:
        mesh.invert()
    digest = hashlib.sha256(data + f"|scale={float(scale)!r}".encode()).hexdigest()
    return ObjectMesh(
        vertices=np.asarray(mesh.vertices, dtype=np.float64).copy(),
        faces=np.asarray(mesh.faces, dtype=np.int64).copy(),
        source=str(p),
        digest=digest,
        volume_m3=float(mesh.volume),
        convex=bool(mesh.is_convex),
    )


def _open_edge_count(mesh) -> int:
    edges = np.sort(mesh.edges, axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return int((counts == 1).sum())


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


# -- signed distance ------------------------------------------------------------------------------


def _closest_on_triangles(p: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Closest points ``(N, 3)`` on triangles ``tris (N, 3, 3)`` to points ``p (N, 3)``
    (``trimesh.triangles.closest_point``, imported here: 0.5 s of import time that lookups of
    the built-in catalogue never need)."""
    from trimesh.triangles import closest_point

    return closest_point(tris, p)


def _point_triangle_distance(p: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Euclidean distance ``(N,)`` from points ``p (N, 3)`` to triangles ``tris (N, 3, 3)``."""
    return np.linalg.norm(p - _closest_on_triangles(p, tris), axis=1)


def _inside_any(points: np.ndarray, parts: list[ConvexPart]) -> np.ndarray:
    inside = np.zeros(len(points), dtype=bool)
    for part in parts:
        lo, hi = part.vertices.min(axis=0), part.vertices.max(axis=0)
        idx = np.flatnonzero(np.all((points >= lo) & (points <= hi), axis=1) & ~inside)
        n, d = part.planes[:, :3], part.planes[:, 3]
        inside[idx[(points[idx] @ n.T + d).max(axis=1) <= 0.0]] = True
    return inside


def _surface_samples(parts: list[ConvexPart], spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Points on every part's triangles, about ``spacing`` apart, and their triangle ids."""
    pts, ids = [], []
    tri_id = 0
    for part in parts:
        v = part.vertices
        for f in part.faces:
            a, b, c = v[f[0]], v[f[1]], v[f[2]]
            edge = max(np.linalg.norm(b - a), np.linalg.norm(c - a), np.linalg.norm(c - b))
            k = max(1, math.ceil(edge / spacing))
            i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
            keep = (i + j) <= k
            u, w = i[keep] / k, j[keep] / k
            pts.append(a + np.outer(u, b - a) + np.outer(w, c - a))
            ids.append(np.full(len(u), tri_id))
            tri_id += 1
    return np.concatenate(pts), np.concatenate(ids)


@dataclass(frozen=True)
class SdfGrid:
    """Signed distance [m] of a union of convex parts on a regular grid (object frame),
    negative inside, with each node's nearest surface triangle.

    Queries inside the grid are exact up to which triangles are tried: the distance to the
    nearest of the eight surrounding nodes' nearest triangles, the sign from the parts
    (inside one of them), the normal along the closest point's direction. Without the
    triangles (``triangles is None``), the values are interpolated trilinearly.

    Attributes:
        origin: ``(3,)`` position of node ``(0, 0, 0)`` [m].
        spacing: node spacing [m].
        values: ``(nx, ny, nz)`` signed distances at the nodes [m].
        nearest: ``(nx, ny, nz)`` index of each node's nearest triangle, or ``None``.
        triangles: ``(M, 3, 3)`` the parts' outward-wound triangles [m], or ``None``.
        planes: ``(K, 4)`` the parts' face planes stacked (``n·x + d ≤ 0`` inside), or ``None``.
        part_of_plane: ``(K,)`` which part each plane bounds, or ``None``.
    """

    origin: np.ndarray
    spacing: float
    values: np.ndarray
    nearest: np.ndarray | None = None
    triangles: np.ndarray | None = None
    planes: np.ndarray | None = None
    part_of_plane: np.ndarray | None = None

    @classmethod
    def from_parts(cls, parts: list[ConvexPart]) -> SdfGrid:
        """Sample the signed distance of the union of ``parts`` (see the module docstring)."""
        lo = np.min([p.vertices.min(0) for p in parts], axis=0) - SDF_PAD_M
        hi = np.max([p.vertices.max(0) for p in parts], axis=0) + SDF_PAD_M
        h = max(float((hi - lo).max()) / (SDF_MAX_NODES - 1), SDF_MIN_SPACING_M)
        n = np.ceil((hi - lo) / h).astype(int) + 1
        axes = [lo[i] + h * np.arange(n[i]) for i in range(3)]
        nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        tris = np.concatenate([p.vertices[p.faces] for p in parts])  # (M, 3, 3)
        samples, tri_of = _surface_samples(parts, 0.5 * h)
        tree = cKDTree(samples)
        # The nearest sample's distance overestimates the true one by at most about
        # (0.35 h)² / (2 d): below 1 % of h beyond 3 h. Nearer nodes get the exact distance to
        # the triangles of their k nearest samples.
        dist, nn1 = tree.query(nodes, k=1)
        nearest = tri_of[nn1]
        near = np.flatnonzero(dist < 3.0 * h)
        k = min(8, len(samples))
        for s in range(0, len(near), 65536):
            idx = near[s : s + 65536]
            _, nn = tree.query(nodes[idx], k=k)
            cand = tri_of[nn.reshape(len(idx), k)]  # (B, k) triangle ids
            rep = np.repeat(nodes[idx], k, axis=0)
            t = tris[cand.ravel()]
            d = _point_triangle_distance(rep, t).reshape(len(idx), k)
            best = d.argmin(axis=1)
            dist[idx] = d[np.arange(len(idx)), best]
            nearest[idx] = cand[np.arange(len(idx)), best]
        sign = np.where(_inside_any(nodes, parts), -1.0, 1.0)
        planes = np.concatenate([p.planes for p in parts])
        owner = np.concatenate([np.full(len(p.planes), i) for i, p in enumerate(parts)])
        return cls(
            lo,
            h,
            (sign * dist).reshape(tuple(n)),
            nearest.astype(np.int32).reshape(tuple(n)),
            tris,
            planes,
            owner,
        )

    def scaled(self, factor: float) -> SdfGrid:
        """The grid of the shape scaled by ``factor`` about the frame's origin."""
        planes = None
        if self.planes is not None:
            planes = self.planes.copy()
            planes[:, 3] *= factor
        return SdfGrid(
            self.origin * factor,
            self.spacing * factor,
            self.values * factor,
            self.nearest,
            None if self.triangles is None else self.triangles * factor,
            planes,
            self.part_of_plane,
        )

    def _inside(self, p: np.ndarray) -> np.ndarray:
        """``(N,)`` points inside one of the parts (each part's planes tested only on the
        points within its planes' bounding slab along the grid axes, in blocks)."""
        inside = np.zeros(len(p), dtype=bool)
        starts = np.flatnonzero(np.r_[True, np.diff(self.part_of_plane) != 0])
        ends = np.r_[starts[1:], len(self.planes)]
        for a, b in zip(starts, ends, strict=True):
            planes = self.planes[a:b]
            todo = np.flatnonzero(~inside)
            for c in range(0, len(todo), 4096):
                idx = todo[c : c + 4096]
                worst = (p[idx] @ planes[:, :3].T + planes[:, 3]).max(axis=1)
                inside[idx[worst <= 0.0]] = True
        return inside

    def _exact(self, p: np.ndarray, i0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distance and normal from the candidate triangles of the cells ``i0`` (see class)."""
        corners = np.array([(a, b, c) for a in (0, 1) for b in (0, 1) for c in (0, 1)])
        idx = i0[:, None, :] + corners[None]  # (N, 8, 3)
        cand = self.nearest[idx[..., 0], idx[..., 1], idx[..., 2]]  # (N, 8)
        t = self.triangles[cand.ravel()]
        rep = np.repeat(p, 8, axis=0)
        q = _closest_on_triangles(rep, t)
        dist = np.linalg.norm(rep - q, axis=1).reshape(len(p), 8)
        best = dist.argmin(axis=1)
        rows = np.arange(len(p))
        d = dist[rows, best]
        q = q.reshape(len(p), 8, 3)[rows, best]
        tri = t.reshape(len(p), 8, 3, 3)[rows, best]
        inside = self._inside(p)
        g = (p - q) * np.where(inside, -1.0, 1.0)[:, None]
        on = d < 1e-9  # on the surface: the triangle's own normal
        if on.any():
            g[on] = np.cross(tri[on, 1] - tri[on, 0], tri[on, 2] - tri[on, 0])
        return np.where(inside, -d, d), g

    def sdf_and_normal(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance ``(N,)`` [m] and unit gradient ``(N, 3)`` at points ``(N, 3)``.

        Exact (see the class); beyond the grid, from the triangles of the nearest border cell.
        Without triangles: trilinear interpolation and its gradient inside the grid, beyond it
        the value at the nearest grid point plus the distance to it.
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        n = np.asarray(self.values.shape)
        hi = self.origin + self.spacing * (n - 1)
        pc = np.clip(p, self.origin, hi)
        x = (pc - self.origin) / self.spacing
        i0 = np.minimum(np.floor(x).astype(int), n - 2)
        if self.triangles is not None:  # beyond the grid: the border cell's triangles
            d, g = self._exact(p, i0)
            return self._finish(p, p, d, g)
        t = x - i0
        V = self.values
        c = np.empty((len(p), 2, 2, 2))
        for a in (0, 1):
            for b in (0, 1):
                for e in (0, 1):
                    c[:, a, b, e] = V[i0[:, 0] + a, i0[:, 1] + b, i0[:, 2] + e]
        tx, ty, tz = t[:, 0:1, None], t[:, 1], t[:, 2]
        cx = c[:, 0] * (1 - tx) + c[:, 1] * tx  # (N, 2, 2) over (y, z)
        cxy = cx[:, 0] * (1 - ty[:, None]) + cx[:, 1] * ty[:, None]  # (N, 2) over z
        d = cxy[:, 0] * (1 - tz) + cxy[:, 1] * tz
        g = np.empty_like(p)
        dx = c[:, 1] - c[:, 0]  # (N, 2, 2)
        dxy = dx[:, 0] * (1 - ty[:, None]) + dx[:, 1] * ty[:, None]
        g[:, 0] = dxy[:, 0] * (1 - tz) + dxy[:, 1] * tz
        dy = cx[:, 1] - cx[:, 0]  # (N, 2)
        g[:, 1] = dy[:, 0] * (1 - tz) + dy[:, 1] * tz
        g[:, 2] = cxy[:, 1] - cxy[:, 0]
        g /= self.spacing
        return self._finish(p, pc, d, g)

    @staticmethod
    def _finish(p, pc, d, g) -> tuple[np.ndarray, np.ndarray]:
        """Extend beyond the grid (``pc``: the points clamped to it) and normalise ``g``."""
        out = p - pc
        off = np.linalg.norm(out, axis=1)
        far = off > 0
        if far.any():
            d[far] += off[far]
            g[far] = out[far] / off[far, None]
        norm = np.linalg.norm(g, axis=1)
        flat = norm < 1e-9
        g[~flat] /= norm[~flat, None]
        g[flat] = (0.0, 0.0, 1.0)
        return d, g


# -- the cached collision shape -------------------------------------------------------------------


@dataclass(frozen=True)
class MeshCollision:
    """An object mesh's collision shape: its convex parts and their signed-distance grid."""

    parts: tuple[ConvexPart, ...]
    sdf: SdfGrid
    cached: bool = False
    """True when read from the disk cache rather than computed."""


def mesh_cache_dir() -> Path:
    """Where decompositions and grids are cached: ``<cache dir>/objects``."""
    return cache_dir() / "objects"


def mesh_collision(mesh: ObjectMesh) -> MeshCollision:
    """The mesh's convex parts and signed-distance grid, from the disk cache when there."""
    path = mesh_cache_dir() / f"{mesh.digest[:32]}-v{CACHE_VERSION}.npz"
    if path.is_file():
        try:
            with np.load(path) as z:
                parts = tuple(
                    ConvexPart(z[f"v{i}"], z[f"f{i}"], z[f"p{i}"]) for i in range(int(z["n"]))
                )
                sdf = SdfGrid(
                    z["origin"],
                    float(z["spacing"]),
                    z["values"],
                    z["nearest"],
                    z["triangles"],
                    z["planes"],
                    z["part_of_plane"],
                )
            return MeshCollision(parts, sdf, cached=True)
        except (OSError, KeyError, ValueError) as e:
            log.warning("ignoring an unreadable mesh cache entry %s (%s); rebuilding", path, e)
    parts = tuple(convex_parts(mesh))
    sdf = SdfGrid.from_parts(list(parts))
    arrays: dict[str, np.ndarray] = {"n": np.array(len(parts))}
    for i, part in enumerate(parts):
        arrays[f"v{i}"], arrays[f"f{i}"], arrays[f"p{i}"] = part.vertices, part.faces, part.planes
    arrays.update(
        origin=sdf.origin,
        spacing=np.array(sdf.spacing),
        values=sdf.values,
        nearest=sdf.nearest,
        triangles=sdf.triangles,
        planes=sdf.planes,
        part_of_plane=sdf.part_of_plane,
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    os.replace(tmp, path)
    return MeshCollision(parts, sdf)
