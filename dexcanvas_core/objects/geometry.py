"""Object geometry for the demonstration generator: primitive compositions with a signed distance.

Every catalogue object (``dexcanvas_core.taxonomy.OBJECTS``) is a union of primitives — boxes,
cylinders, spheres and capsules — posed in the **object frame**: origin at the centre of the
composition's axis-aligned bounding box, **z up when the object rests on the table** (so a lying
cylinder has its axis along the object frame's x, unlike ``ObjectSpec.bounding_box_m`` which puts
every cylinder axis on z). Resting on the table (z = 0 plane of the world), the object frame sits
at height ``rest_z`` with no rotation other than a yaw about z.

Primitive sizes follow MuJoCo's conventions so that a scene builder can copy them (half sizes):

* ``box``: ``(hx, hy, hz)`` half extents [m];
* ``cylinder``: ``(radius, half_height)`` [m], axis along the primitive's z;
* ``capsule``: ``(radius, half_length)`` [m] of the cylindrical part, axis along z;
* ``sphere``: ``(radius,)`` [m].

Primitives of the catalogue are exact (sizes from ``ObjectSpec.size_m``, the paper's table,
posed as ``ObjectSpec.placement`` says). YCB-style items (``ObjectSpec.approximate``) are
documented compositions (``ObjectGeometry.description``) sized after the catalogue's estimated
boxes (DexRobot collision meshes) and the YCB proportions; masses always come from the catalogue.

The signed distance of a union is the minimum of its primitives' exact signed distances: exact
outside, and inside a lower bound of the depth where primitives overlap (conservative for a
penetration check). Normals are the gradient of the minimising primitive's distance. Objects
given as meshes (``dexcanvas_core.objects``) are unions of convex parts whose distance comes from
their signed-distance grid instead.

The primitives and their distances are in :mod:`.primitives`, the YCB-style compositions in
:mod:`.ycb_shapes`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.objects.mesh import ObjectMesh, load_object_mesh, mesh_collision
from dexcanvas_core.objects.primitives import Y90, Primitive, sdf_local
from dexcanvas_core.objects.sdf import SdfGrid
from dexcanvas_core.objects.ycb_shapes import YCB_BUILDERS
from dexcanvas_core.rotations import aa_to_matrix
from dexcanvas_core.taxonomy import ObjectSpec, object_spec


@dataclass(frozen=True)
class ObjectGeometry:
    """An object's solid shape as a union of primitives (object frame, z up at rest).

    Attributes:
        object_id: catalogue id (``"cube2"``).
        primitives: the composition, each posed in the object frame (a mesh object: its convex
            parts, ``"mesh"`` primitives).
        mass_kg: the catalogue mass [kg].
        rest_z: height [m] of the object frame's origin above the table when the object rests.
        description: how the composition was built and from what.
        sdf_grid: a mesh object's signed-distance grid (distances then come from it, not from
            the primitives); ``None`` for primitive compositions.
        visual: a mesh object's drawn surface, ``(vertices (V, 3) [m], faces (F, 3))`` in the
            object frame; ``None`` for primitive compositions (drawn as their primitives).
        friction: sliding friction coefficient of the object's surface; ``None``: the scene's
            default.
        inertia_diag: principal moments of inertia [kg·m²] about the centre of mass along the
            object frame's axes, when given; ``None``: computed from the shape and mass with
            uniform density.
        approximate: the shape stands in for a real object (a built-in composition of a
            YCB-style item, not its model).

    Signed distances [m] of points given in the object frame (negative inside):

    >>> import numpy as np
    >>> from dexcanvas_core import object_geometry
    >>> cube = object_geometry("cube2")  # a 5 cm cube centred on its frame's origin
    >>> cube.signed_distance(np.array([[0.0, 0.0, 0.1], [0.0, 0.0, 0.0]])).round(3).tolist()
    [0.075, -0.025]
    """

    object_id: str
    primitives: tuple[Primitive, ...]
    mass_kg: float
    rest_z: float
    description: str
    sdf_grid: SdfGrid | None = field(default=None, repr=False, compare=False)
    visual: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False, compare=False)
    friction: float | None = None
    inertia_diag: tuple[float, float, float] | None = None
    approximate: bool = False
    _R: np.ndarray = field(init=False, repr=False, compare=False)
    _c: np.ndarray = field(init=False, repr=False, compare=False)
    _rho: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not self.primitives:
            raise ValidationError(f"object {self.object_id!r} has no primitive", field="primitives")
        if self.sdf_grid is None and any(p.type == "mesh" for p in self.primitives):
            raise ValidationError(
                f"object {self.object_id!r}: mesh parts need the object's signed-distance grid",
                field="sdf_grid",
            )
        object.__setattr__(self, "primitives", tuple(self.primitives))
        R = np.stack([p.R for p in self.primitives])  # (P, 3, 3) primitive → object
        c = np.stack([np.asarray(p.pos) for p in self.primitives])  # (P, 3)
        # bounding sphere radius of each primitive about its centre (for culling)
        rho = np.array([np.linalg.norm(p.local_aabb_half()) for p in self.primitives])
        for a in (R, c, rho):
            a.setflags(write=False)
        object.__setattr__(self, "_R", R)
        object.__setattr__(self, "_c", c)
        object.__setattr__(self, "_rho", rho)

    # -- shape queries (object frame) ------------------------------------------------------

    def sdf_and_normal(self, points_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance ``(...)`` [m] (negative inside) and unit outward normal ``(..., 3)``
        (the distance's gradient) of points ``(..., 3)`` given in the object frame."""
        p = np.asarray(points_obj, dtype=np.float64)
        if p.shape[-1:] != (3,):
            raise ValidationError(f"points must have shape (..., 3), got {p.shape}", field="points")
        lead = p.shape[:-1]
        flat = p.reshape(-1, 3)
        if self.sdf_grid is not None:
            d, g = self.sdf_grid.sdf_and_normal(flat)
            return d.reshape(lead), g.reshape((*lead, 3))
        prims = self.primitives
        if len(prims) == 1:
            d, g = sdf_local(prims[0].type, prims[0].size, (flat - self._c[0]) @ self._R[0])
            return d.reshape(lead), (g @ self._R[0].T).reshape((*lead, 3))
        # Union: minimum over primitives. A primitive lies inside its bounding sphere (centre c,
        # radius rho), so |p - c| - rho bounds its distance from below and |p - c| + rho from
        # above; only primitives whose lower bound beats the best so far are evaluated exactly.
        centre_d = np.linalg.norm(flat[:, None, :] - self._c[None], axis=-1)  # (N, P)
        lower = centre_d - self._rho
        best_d = np.min(centre_d + self._rho, axis=1)
        best_g = np.zeros_like(flat)
        for i in np.argsort(lower.mean(axis=0)):
            idx = np.flatnonzero(lower[:, i] < best_d)
            if idx.size == 0:
                continue
            d, g = sdf_local(prims[i].type, prims[i].size, (flat[idx] - self._c[i]) @ self._R[i])
            better = d < best_d[idx]
            sel = idx[better]
            best_d[sel] = d[better]
            best_g[sel] = g[better] @ self._R[i].T
        return best_d.reshape(lead), best_g.reshape((*lead, 3))

    def signed_distance(self, points_obj: np.ndarray) -> np.ndarray:
        """``(...)`` signed distance [m] of points ``(..., 3)`` (object frame); < 0 inside."""
        return self.sdf_and_normal(points_obj)[0]

    def normal(self, points_obj: np.ndarray) -> np.ndarray:
        """``(..., 3)`` unit outward normal (gradient of the signed distance) at the points."""
        return self.sdf_and_normal(points_obj)[1]

    def closest_point(self, points_obj: np.ndarray) -> np.ndarray:
        """``(..., 3)`` closest surface point to each point (object frame) [m]."""
        d, g = self.sdf_and_normal(points_obj)
        return np.asarray(points_obj, dtype=np.float64) - d[..., None] * g

    # -- extents and resting ---------------------------------------------------------------

    @property
    def aabb_half(self) -> np.ndarray:
        """``(3,)`` half extents [m] of the composition's bounding box in the object frame."""
        lo, hi = _aabb(self.primitives)
        return 0.5 * (hi - lo)

    @property
    def is_mesh(self) -> bool:
        """The object is a mesh (convex parts and a signed-distance grid)."""
        return self.sdf_grid is not None

    @property
    def volume_m3(self) -> float:
        """Sum of the primitives' volumes [m³] (overlaps counted twice)."""
        return float(sum(p.volume for p in self.primitives))

    @property
    def com(self) -> np.ndarray:
        """``(3,)`` centre of mass [m] in the object frame, uniform density over primitives."""
        vols = np.array([p.volume for p in self.primitives])
        cents = np.array([p.centroid for p in self.primitives])
        return (vols[:, None] * cents).sum(0) / vols.sum()

    def lowest_z(self, R_world_obj: np.ndarray, p_world_obj: np.ndarray) -> np.ndarray:
        """Lowest world z [m] of the posed object; ``R (..., 3, 3)``, ``p (..., 3)`` → ``(...)``."""
        R = np.asarray(R_world_obj, dtype=np.float64)
        p = np.asarray(p_world_obj, dtype=np.float64)
        low = None
        for prim in self.primitives:
            Rp = R @ prim.R  # (..., 3, 3) primitive frame in world
            cz = p[..., 2] + (R @ np.asarray(prim.pos))[..., 2]
            row = Rp[..., 2, :]  # world z of the primitive's axes
            s = prim.size
            if prim.type == "mesh":
                low_p = p[..., 2] + (row @ prim.part.vertices.T).min(axis=-1)
                low = low_p if low is None else np.minimum(low, low_p)
                continue
            if prim.type == "box":
                ext = np.abs(row) @ np.asarray(s)
            elif prim.type == "sphere":
                ext = np.full(cz.shape, s[0])
            elif prim.type == "cylinder":
                az = row[..., 2]
                ext = s[1] * np.abs(az) + s[0] * np.sqrt(np.clip(1.0 - az * az, 0.0, 1.0))
            else:
                ext = s[1] * np.abs(row[..., 2]) + s[0]
            z = cz - ext
            low = z if low is None else np.minimum(low, z)
        return low

    def rest_pose(self, x: float = 0.0, y: float = 0.0, yaw: float = 0.0) -> np.ndarray:
        """``(4, 4)`` world pose ``T_world_obj`` of the object resting at ``(x, y)``, ``yaw``."""
        T = np.eye(4)
        T[:3, :3] = aa_to_matrix(np.array([0.0, 0.0, yaw]))
        T[:3, 3] = (x, y, self.rest_z)
        return T

    def scaled(self, factor: float, mass_kg: float | None = None) -> ObjectGeometry:
        """The same shape scaled uniformly about the object frame's origin by ``factor``.

        The mass stays the catalogue mass unless ``mass_kg`` is given (size and mass are
        perturbed separately by the synthesis stage). The id keeps the catalogue id.
        """
        if not (math.isfinite(factor) and factor > 0):
            raise ValidationError(f"scale factor must be positive, got {factor!r}", field="scale")
        prims = tuple(
            dataclasses.replace(
                p,
                size=tuple(s * factor for s in p.size),
                pos=tuple(v * factor for v in p.pos),
                part=None if p.part is None else p.part.scaled(factor),
            )
            for p in self.primitives
        )
        mass = self.mass_kg if mass_kg is None else float(mass_kg)
        inertia = None
        if self.inertia_diag is not None:  # I ∝ m·L²
            inertia = tuple(i * factor**2 * mass / self.mass_kg for i in self.inertia_diag)
        return dataclasses.replace(
            self,
            primitives=prims,
            mass_kg=mass,
            rest_z=self.rest_z * factor,
            description=f"{self.description} (scaled x{factor:.3f})",
            sdf_grid=None if self.sdf_grid is None else self.sdf_grid.scaled(factor),
            visual=None if self.visual is None else (self.visual[0] * factor, self.visual[1]),
            inertia_diag=inertia,
        )

    def to_dict(self) -> dict:
        """A JSON-ready description (for scene builders and reports)."""
        return {
            "object_id": self.object_id,
            "mass_kg": self.mass_kg,
            "rest_z": self.rest_z,
            "aabb_half": self.aabb_half.tolist(),
            "description": self.description,
            "approximate": self.approximate,
            "primitives": [p.to_dict() for p in self.primitives],
        }


def _aabb(prims) -> tuple[np.ndarray, np.ndarray]:
    bounds = [p.aabb() for p in prims]
    lo = np.min([b[0] for b in bounds], axis=0)
    hi = np.max([b[1] for b in bounds], axis=0)
    return lo, hi


def _centred(prims: list[Primitive]) -> tuple[tuple[Primitive, ...], float]:
    """Shift a composition so its bounding-box centre is the origin; return it and ``rest_z``."""
    lo, hi = _aabb(prims)
    c = 0.5 * (lo + hi)
    out = tuple(
        Primitive(p.type, p.size, tuple(np.asarray(p.pos) - c), p.rot_aa, p.name) for p in prims
    )
    return out, float(0.5 * (hi - lo)[2])


def _primitive_composition(spec: ObjectSpec) -> tuple[list[Primitive], str]:
    """A primitive object as one MuJoCo-style primitive in the object frame (z up as the first
    placement rests it; a lying cylinder's axis along x), and its description."""
    s = spec.size_m
    if spec.shape == "cube":
        e = s[0]
        return [Primitive("box", (e / 2,) * 3, name="cube")], f"box {e * 1e3:.0f} mm edge"
    if spec.shape == "cuboid":
        return (
            [Primitive("box", (s[0] / 2, s[1] / 2, s[2] / 2), name="cuboid")],
            f"box {s[0] * 1e3:.0f} × {s[1] * 1e3:.0f} × {s[2] * 1e3:.0f} mm (x × y × z, z up)",
        )
    if spec.shape == "sphere":
        return [Primitive("sphere", (s[0] / 2,), name="sphere")], f"sphere Ø {s[0] * 1e3:.0f} mm"
    d, h = s
    if spec.lying:
        return (
            [Primitive("cylinder", (d / 2, h / 2), rot_aa=Y90, name="cylinder")],
            f"cylinder Ø {d * 1e3:.0f} × {h * 1e3:.0f} mm lying on its side, axis along x",
        )
    return (
        [Primitive("cylinder", (d / 2, h / 2), name="cylinder")],
        f"cylinder Ø {d * 1e3:.0f} × {h * 1e3:.0f} mm standing, axis along z",
    )


def mesh_object_geometry(
    object_id: str,
    mesh: ObjectMesh,
    mass_kg: float,
    *,
    friction: float | None = None,
    inertia_diag: tuple[float, float, float] | None = None,
) -> ObjectGeometry:
    """The geometry of an object given as a mesh (its own frame is the object frame).

    Collision parts and the signed-distance grid come from :func:`mesh_collision` (cached on
    disk by the mesh's content hash); the object rests with its lowest point on the table.
    """
    col = mesh_collision(mesh)
    prims = tuple(Primitive.from_part(p, name=f"part{i}") for i, p in enumerate(col.parts))
    low = min(float(p.vertices[:, 2].min()) for p in col.parts)
    ext = " × ".join(f"{v * 1e3:.0f}" for v in mesh.extent_m)
    how = "convex, used as it is" if mesh.convex else f"{len(prims)} convex parts (coacd)"
    text = f"mesh {Path(mesh.source).name}, {ext} mm, {how}; mass {mass_kg:g} kg"
    return ObjectGeometry(
        object_id,
        prims,
        float(mass_kg),
        -low,
        text,
        sdf_grid=col.sdf,
        visual=(mesh.vertices, mesh.faces),
        friction=friction,
        inertia_diag=inertia_diag,
    )


@lru_cache(maxsize=64)
def _build(spec: ObjectSpec) -> ObjectGeometry:
    if spec.mesh is not None:
        mesh = load_object_mesh(spec.mesh, spec.mesh_scale)
        return mesh_object_geometry(
            spec.id, mesh, spec.mass_kg, friction=spec.friction, inertia_diag=spec.inertia_diag
        )
    if spec.source == "ycb":
        prims, text = YCB_BUILDERS[spec.id]()
    else:
        prims, text = _primitive_composition(spec)
    centred, rest_z = _centred(prims)
    text = f"{text}; mass {spec.mass_kg:g} kg (catalogue)"
    return ObjectGeometry(
        spec.id, centred, spec.mass_kg, rest_z, text, approximate=spec.approximate
    )


def object_record(object_id: str | ObjectSpec) -> dict:
    """What an output says about the object it used (JSON-ready): id, mass [kg], bounding box
    [m], where the shape came from (``"primitive"``, ``"built-in composition"`` or
    ``"mesh"``), the mesh file and its sha256 when there is one, and ``approximate`` — the shape
    stands in for a real object whose model was not given."""
    spec = object_spec(object_id)
    geom = object_geometry(spec)
    out = {
        "id": spec.id,
        "name": spec.name,
        "mass_kg": geom.mass_kg,
        "size_m": [float(v) for v in 2.0 * geom.aabb_half],
        "shape_source": (
            "mesh" if spec.mesh else "built-in composition" if spec.approximate else "primitive"
        ),
        "approximate": spec.approximate,
        "description": geom.description,
    }
    if spec.mesh:
        out["mesh"] = spec.mesh
        out["mesh_scale"] = spec.mesh_scale
        out["mesh_sha256"] = hashlib.sha256(Path(spec.mesh).read_bytes()).hexdigest()
        out["convex_parts"] = len(geom.primitives)
    return out


def object_geometry(object_id: str | ObjectSpec) -> ObjectGeometry:
    """The geometry of an object (any spelling ``object_spec`` accepts, or a spec), cached.

    Catalogue objects are built from primitives; objects with a mesh (custom objects, objects
    read from an objects directory) from the mesh.

    Raises:
        UnknownNameError: unknown object (the message lists close matches).
        ValidationError: the object's mesh cannot be used (unreadable, open, absurd scale).

    >>> from dexcanvas_core import object_geometry
    >>> geom = object_geometry("Cube 2")
    >>> geom.object_id, geom.mass_kg, [p.type for p in geom.primitives]
    ('cube2', 0.037, ['box'])
    """
    return _build(object_spec(object_id))
