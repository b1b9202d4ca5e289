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
  parts by approximate convex decomposition (``coacd``, Wei et al. 2022), each part decimated
  to ``MAX_HULL_VERTICES`` vertices (:func:`convex_parts`).
* **A signed-distance grid** of the union of those parts (the shape physics collides with):
  distances [m] on a regular grid around the object, negative inside, with each node's nearest
  triangle: a query takes the nearest of its cell's candidate triangles (exact up to which
  triangles are tried), the sign "inside some convex part", the normal along the closest point.

A part is a :class:`.parts.ConvexPart`, the distance is in :mod:`.sdf`.
"""

from __future__ import annotations

import hashlib
import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dexcanvas_core.cache import OBJECTS_DIR, cache_dir
from dexcanvas_core.errors import MissingDependencyError, ValidationError
from dexcanvas_core.objects.parts import ConvexPart
from dexcanvas_core.objects.sdf import SdfGrid
from dexcanvas_core.safe_io import atomic_path

log = logging.getLogger(__name__)

MESH_SUFFIXES: tuple[str, ...] = (".obj", ".stl", ".ply", ".glb", ".gltf", ".off")
"""File types :func:`load_object_mesh` reads (``trimesh``'s loaders)."""

MIN_EXTENT_M = 0.005
"""Smallest accepted object extent [m] (a mesh in metres read with ``scale = 0.001`` is below)."""

MAX_EXTENT_M = 1.0
"""Largest accepted object extent [m] (a mesh in millimetres read as metres is far above)."""

CACHE_VERSION = 3
"""Bumped when the cached decomposition or grid changes meaning."""

COACD_THRESHOLD = 0.04
"""``coacd`` concavity threshold: the largest concavity a part may keep, relative to the mesh's
size (smaller: more, tighter parts)."""

MAX_HULL_VERTICES = 64
"""Vertices per convex part kept for physics (``coacd``'s ``max_ch_vertex``)."""


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
    if not mesh.is_winding_consistent:
        trimesh.repair.fix_winding(mesh)
    # Closed: every edge bounds an even number of faces (two, or four where two parts of a
    # scanned object touch along an edge), with consistent winding, so the volume is defined.
    if _open_edge_count(mesh) or not mesh.is_winding_consistent or abs(mesh.volume) <= 0:
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
    """Edges bounding an odd number of faces (a hole's rim, or a flap)."""
    edges = np.sort(mesh.edges, axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return int((counts % 2 == 1).sum())


# -- the cached collision shape -------------------------------------------------------------------


@dataclass(frozen=True)
class MeshCollision:
    """An object mesh's collision shape: its convex parts and their signed-distance grid."""

    parts: tuple[ConvexPart, ...]
    sdf: SdfGrid
    cached: bool = False
    """True when read from the disk cache rather than computed."""


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


def mesh_cache_dir() -> Path:
    """Where decompositions and grids are cached: ``<cache dir>/objects``."""
    return cache_dir() / OBJECTS_DIR


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
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    return MeshCollision(parts, sdf)
