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
penetration check). Normals are the gradient of the minimising primitive's distance.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Literal

import numpy as np

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.objects.mesh import (
    ConvexPart,
    ObjectMesh,
    SdfGrid,
    load_object_mesh,
    mesh_collision,
)
from dexcanvas_core.rotations import aa_to_matrix, matrix_to_aa
from dexcanvas_core.taxonomy import ObjectSpec, object_spec

PrimitiveType = Literal["box", "cylinder", "sphere", "capsule", "mesh"]
PRIMITIVE_TYPES: tuple[str, ...] = ("box", "cylinder", "sphere", "capsule", "mesh")
_SIZE_LEN = {"box": 3, "cylinder": 2, "sphere": 1, "capsule": 2, "mesh": 3}
_EPS = 1e-12


@dataclass(frozen=True)
class Primitive:
    """One solid primitive of an object, posed in the object frame.

    Attributes:
        type: ``"box"``, ``"cylinder"``, ``"sphere"``, ``"capsule"`` or ``"mesh"`` (a convex
            part of a mesh object, :class:`~dexcanvas_core.objects.mesh.ConvexPart`).
        size: half sizes [m] in MuJoCo's layout (see the module docstring); for a mesh part,
            the half extents of its bounding box.
        pos: ``(3,)`` position of the primitive's centre in the object frame [m] (a mesh
            part's vertices are in the object frame: its pos is the origin).
        rot_aa: ``(3,)`` orientation of the primitive frame in the object frame, axis-angle [rad].
        name: a label (``"body"``, ``"cap"``, …).
        part: the convex part of a ``"mesh"`` primitive, ``None`` otherwise.
    """

    type: PrimitiveType
    size: tuple[float, ...]
    pos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rot_aa: tuple[float, float, float] = (0.0, 0.0, 0.0)
    name: str = ""
    part: ConvexPart | None = field(default=None, compare=False, repr=False)

    @classmethod
    def from_part(cls, part: ConvexPart, name: str = "") -> Primitive:
        """A ``"mesh"`` primitive of a convex part (vertices in the object frame)."""
        half = 0.5 * (part.vertices.max(axis=0) - part.vertices.min(axis=0))
        return cls("mesh", tuple(np.maximum(half, 1e-6)), name=name, part=part)

    def __post_init__(self) -> None:
        if self.type not in PRIMITIVE_TYPES:
            raise ValidationError(
                f"unknown primitive type {self.type!r}; valid: {', '.join(PRIMITIVE_TYPES)}",
                field="type",
            )
        size = tuple(float(s) for s in self.size)
        if len(size) != _SIZE_LEN[self.type] or not all(math.isfinite(s) and s > 0 for s in size):
            raise ValidationError(
                f"a {self.type} needs {_SIZE_LEN[self.type]} positive half sizes [m], got {size}",
                field="size",
            )
        if (self.type == "mesh") != (self.part is not None):
            raise ValidationError("a mesh primitive needs its convex part, and only it has one")
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "pos", tuple(float(v) for v in self.pos))
        object.__setattr__(self, "rot_aa", tuple(float(v) for v in self.rot_aa))

    @property
    def volume(self) -> float:
        """Solid volume [m³]."""
        s = self.size
        if self.type == "box":
            return 8.0 * s[0] * s[1] * s[2]
        if self.type == "sphere":
            return 4.0 / 3.0 * math.pi * s[0] ** 3
        if self.type == "cylinder":
            return math.pi * s[0] ** 2 * 2.0 * s[1]
        if self.type == "capsule":
            return math.pi * s[0] ** 2 * 2.0 * s[1] + 4.0 / 3.0 * math.pi * s[0] ** 3
        return self.part.volume_m3

    @property
    def centroid(self) -> np.ndarray:
        """``(3,)`` centre of volume in the object frame [m]."""
        if self.type == "mesh":
            return self.part.centroid
        return np.asarray(self.pos, dtype=np.float64)

    @property
    def R(self) -> np.ndarray:
        """``(3, 3)`` rotation of the primitive frame in the object frame."""
        return aa_to_matrix(np.asarray(self.rot_aa, dtype=np.float64))

    def local_aabb_half(self) -> np.ndarray:
        """``(3,)`` half extents of the primitive's bounding box in its own frame [m]."""
        s = self.size
        if self.type == "mesh":  # about the object frame's origin, where the part's pos is
            return np.abs(self.part.vertices).max(axis=0)
        if self.type == "box":
            return np.array(s)
        if self.type == "sphere":
            return np.full(3, s[0])
        if self.type == "cylinder":
            return np.array([s[0], s[0], s[1]])
        return np.array([s[0], s[0], s[1] + s[0]])

    def aabb(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lo, hi)`` axis-aligned bounds in the object frame [m] (tight for all four types)."""
        if self.type == "mesh":
            return self.part.vertices.min(axis=0), self.part.vertices.max(axis=0)
        R = self.R
        c = np.asarray(self.pos)
        s = self.size
        if self.type == "box":
            half = np.abs(R) @ np.array(s)
        elif self.type == "sphere":
            half = np.full(3, s[0])
        else:  # cylinder / capsule, axis a = R e_z
            a = R[:, 2]
            r, h = s
            if self.type == "cylinder":
                half = h * np.abs(a) + r * np.sqrt(np.clip(1.0 - a * a, 0.0, 1.0))
            else:
                half = h * np.abs(a) + r
        return c - half, c + half

    def to_dict(self) -> dict:
        out = {
            "type": self.type,
            "size": list(self.size),
            "pos": list(self.pos),
            "rot_aa": list(self.rot_aa),
            "name": self.name,
        }
        if self.part is not None:
            out["vertices"] = len(self.part.vertices)
        return out


def _sdf_local(kind: str, size: tuple[float, ...], p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact signed distance ``(N,)`` [m] and its gradient ``(N, 3)`` for points ``p (N, 3)``
    given in the primitive's frame."""
    if kind == "sphere":
        n = np.linalg.norm(p, axis=-1)
        g = p / np.maximum(n, _EPS)[:, None]
        g[n < _EPS] = (0.0, 0.0, 1.0)
        return n - size[0], g
    if kind == "capsule":
        r, h = size
        q = p.copy()
        q[:, 2] -= np.clip(p[:, 2], -h, h)
        n = np.linalg.norm(q, axis=-1)
        g = q / np.maximum(n, _EPS)[:, None]
        g[n < _EPS] = (1.0, 0.0, 0.0)
        return n - r, g
    rows = np.arange(p.shape[0])
    if kind == "box":
        sgn = np.where(p < 0, -1.0, 1.0)
        q = np.abs(p) - np.asarray(size)
        qp = np.maximum(q, 0.0)
        out_n = np.linalg.norm(qp, axis=-1)
        inside = out_n < _EPS
        k = np.argmax(q, axis=-1)
        d = np.where(inside, q[rows, k], out_n)
        g = sgn * qp / np.maximum(out_n, _EPS)[:, None]
        if inside.any():
            gi = np.zeros_like(p)
            gi[rows, k] = sgn[rows, k]
            g[inside] = gi[inside]
        return d, g
    # cylinder, axis z: a 2-D box in (radial distance, |z|)
    r, h = size
    rho = np.hypot(p[:, 0], p[:, 1])
    ok = rho > _EPS
    safe = np.where(ok, rho, 1.0)
    q0 = rho - r
    q1 = np.abs(p[:, 2]) - h
    a0, a1 = np.maximum(q0, 0.0), np.maximum(q1, 0.0)
    out_n = np.hypot(a0, a1)
    inside = out_n < _EPS
    d = np.where(inside, np.maximum(q0, q1), out_n)
    inv = 1.0 / np.maximum(out_n, _EPS)
    w_rad = np.where(inside, (q0 >= q1) * 1.0, a0 * inv)
    w_ax = np.where(inside, (q0 < q1) * 1.0, a1 * inv)
    g = np.empty_like(p)
    g[:, 0] = w_rad * np.where(ok, p[:, 0] / safe, 1.0)
    g[:, 1] = w_rad * np.where(ok, p[:, 1] / safe, 0.0)
    g[:, 2] = w_ax * np.where(p[:, 2] < 0, -1.0, 1.0)
    return d, g


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
            d, g = _sdf_local(prims[0].type, prims[0].size, (flat - self._c[0]) @ self._R[0])
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
            d, g = _sdf_local(prims[i].type, prims[i].size, (flat[idx] - self._c[i]) @ self._R[i])
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
    def aabb_center(self) -> np.ndarray:
        """``(3,)`` centre [m] of the bounding box in the object frame (the origin for the
        built-in compositions; a mesh keeps its own frame)."""
        lo, hi = _aabb(self.primitives)
        return 0.5 * (hi + lo)

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


_Y90 = (0.0, math.pi / 2, 0.0)  # turns a primitive's z axis onto the object's x axis
_X90 = (math.pi / 2, 0.0, 0.0)  # turns a primitive's z axis onto the object's -y axis


# -- YCB-style compositions --------------------------------------------------------------------
# Each returns (primitives, description). Dimensions in metres. They approximate the items'
# shapes at the level a grasp needs (graspable widths, heights, loops, handles); the catalogue
# (``dexcanvas_core.taxonomy.objects``) documents where its bounding boxes come from.


def _mayonnaise() -> tuple[list[Primitive], str]:
    body_h, cap_h = 0.160, 0.034
    half_w, r = 0.0195, 0.031  # stadium cross-section 101 × 62 mm
    prims = [
        Primitive("box", (half_w, r, body_h / 2), (0, 0, body_h / 2), name="body"),
        Primitive("cylinder", (r, body_h / 2), (-half_w, 0, body_h / 2), name="body_side_a"),
        Primitive("cylinder", (r, body_h / 2), (half_w, 0, body_h / 2), name="body_side_b"),
        Primitive("cylinder", (0.018, cap_h / 2), (0, 0, body_h + cap_h / 2), name="cap"),
    ]
    return prims, (
        "squeeze bottle standing on its base: a stadium-section body 101 × 62 × 160 mm (a box "
        "between two cylinders of radius 31 mm) and a cap of Ø 36 × 34 mm; total 101 × 62 × "
        "194 mm, the catalogue's estimated box (the DexRobot collision mesh's)"
    )


def _banana() -> tuple[list[Primitive], str]:
    r = 0.018
    mid_h = 0.045  # half length of the middle segment's cylinder
    end_h = 0.025  # half length of each end segment's cylinder
    tilt = math.radians(28)
    prims = [Primitive("capsule", (r, mid_h), (0, 0, 0), _Y90, name="middle")]
    for side in (-1.0, 1.0):
        # end segments continue from the middle segment's ends, bending towards +y
        cx = side * (mid_h + end_h * math.cos(tilt))
        cy = end_h * math.sin(tilt)
        # rotation: z → (side·cos(tilt), sin(tilt), 0), a rotation about z after the Y90 turn
        ang = side * tilt
        Rz = aa_to_matrix(np.array([0.0, 0.0, ang]))
        R = Rz @ aa_to_matrix(np.array(_Y90))
        prims.append(
            Primitive("capsule", (r, end_h), (cx, cy, 0.0), tuple(matrix_to_aa(R)), name="end")
        )
    return prims, (
        "banana lying on its side: three capsules of radius 18 mm (a middle segment of 90 mm and "
        "two 50 mm end segments bent 28° towards +y); about 215 × 70 × 36 mm. The catalogue's "
        "box (95 × 69 × 220 mm) comes from a collision mesh with marker mounts; the banana "
        "itself is ~36 mm thick (YCB 011_banana)"
    )


def _bowl() -> tuple[list[Primitive], str]:
    n = 16
    r_top, r_bot, h, wall = 0.0845, 0.042, 0.071, 0.005
    slant = math.atan2(r_top - r_bot, h)
    length = math.hypot(r_top - r_bot, h)
    width = 2 * r_top * math.sin(math.pi / n) + 0.004
    prims = [Primitive("cylinder", (r_bot + 0.004, wall / 2), (0, 0, wall / 2), name="bottom")]
    for k in range(n):
        phi = 2 * math.pi * k / n
        # box frame: z along the slanted wall, x radial (wall thickness), y tangential
        Rz = aa_to_matrix(np.array([0.0, 0.0, phi]))
        Ry = aa_to_matrix(np.array([0.0, slant, 0.0]))
        R = Rz @ Ry
        rm = 0.5 * (r_top + r_bot) - 0.5 * wall * math.cos(slant)
        prims.append(
            Primitive(
                "box",
                (wall / 2, width / 2, length / 2),
                (rm * math.cos(phi), rm * math.sin(phi), h / 2),
                tuple(matrix_to_aa(R)),
                name="wall",
            )
        )
    return prims, (
        "bowl standing upright: a 5 mm wall of 16 slanted boxes from Ø 84 mm at the base to "
        "Ø 169 mm at the rim, 71 mm high, on a 5 mm base disc (YCB 024_bowl proportions, the "
        "catalogue's estimated box, the DexRobot collision mesh's)"
    )


def _clamp() -> tuple[list[Primitive], str]:
    t = 0.013  # half thickness of the flat-lying clamp
    prims = [Primitive("box", (0.035, 0.022, t), (0.065, 0.0, 0.0), name="jaws")]
    for side in (-1.0, 1.0):
        ang = side * math.radians(10)
        R = aa_to_matrix(np.array([0.0, 0.0, ang])) @ aa_to_matrix(np.array(_Y90))
        prims.append(
            Primitive(
                "capsule",
                (t, 0.052),
                (-0.022, side * 0.024, 0.0),
                tuple(matrix_to_aa(R)),
                name="handle",
            )
        )
    return prims, (
        "spring clamp lying flat: a jaw block 70 × 44 × 26 mm and two handle capsules (radius "
        "13 mm, 130 mm long) spreading at ±10°; about 185 × 85 × 26 mm (YCB 051_large_clamp "
        "proportions; the catalogue's 134 × 53 × 185 mm box is a collision mesh's)"
    )


def _pitcher() -> tuple[list[Primitive], str]:
    R_body, H = 0.054, 0.235
    prims = [
        Primitive("cylinder", (R_body, H / 2), (0, 0, H / 2), name="body"),
        Primitive("capsule", (0.011, 0.055), (R_body + 0.032, 0, 0.14), name="handle"),
        Primitive("capsule", (0.010, 0.016), (R_body + 0.014, 0, 0.196), _Y90, name="handle_top"),
        Primitive(
            "capsule", (0.010, 0.016), (R_body + 0.014, 0, 0.084), _Y90, name="handle_bottom"
        ),
    ]
    return prims, (
        "pitcher standing upright: a Ø 108 × 235 mm body cylinder and a handle on its far "
        "side (+x; a vertical capsule of radius 11 mm, 32 mm outside the body, joined by two "
        "short capsules); YCB 019_pitcher_base proportions"
    )


def _drill() -> tuple[list[Primitive], str]:
    batt_h = 0.048
    handle_len = 0.095
    tilt = math.radians(12)
    Rh = aa_to_matrix(np.array([0.0, -tilt, 0.0]))
    hc = np.array([0.0, 0.0, batt_h + handle_len / 2])
    prims = [
        Primitive("box", (0.058, 0.0335, batt_h / 2), (0.0, 0, batt_h / 2), name="battery"),
        Primitive(
            "box",
            (0.017, 0.0165, handle_len / 2 + 0.01),
            tuple(hc),
            tuple(matrix_to_aa(Rh)),
            name="handle",
        ),
        Primitive("cylinder", (0.031, 0.075), (0.035, 0, 0.166), _Y90, name="body"),
        Primitive("cylinder", (0.016, 0.015), (0.125, 0, 0.166), _Y90, name="chuck"),
    ]
    return prims, (
        "cordless drill standing on its battery: a battery block 116 × 67 × 48 mm, a handle "
        "34 × 33 mm in section tilted 12°, a Ø 62 × 150 mm motor body and a Ø 32 × 30 mm chuck "
        "on top, handle along z; about 190 × 67 × 197 mm (the catalogue's estimated box, the "
        "DexRobot collision mesh's; YCB 035_power_drill)"
    )


def _scissors() -> tuple[list[Primitive], str]:
    r = 0.007  # ring tube radius: 14 mm thick, the catalogue's thickness
    prims: list[Primitive] = [
        Primitive("box", (0.055, 0.009, 0.003), (0.062, 0.0, 0.0), name="blades"),
    ]

    def ring(cx: float, cy: float, ax: float, ay: float, n: int, name: str) -> None:
        # a closed loop of n capsules along an ellipse with semi-axes (ax, ay) (tube centre line)
        pts = [(cx + ax * math.cos(2 * math.pi * k / n), cy + ay * math.sin(2 * math.pi * k / n))
               for k in range(n)]  # fmt: skip
        for k in range(n):
            (x0, y0), (x1, y1) = pts[k], pts[(k + 1) % n]
            dx, dy = x1 - x0, y1 - y0
            L = math.hypot(dx, dy)
            ang = math.atan2(dy, dx)
            R = aa_to_matrix(np.array([0.0, 0.0, ang])) @ aa_to_matrix(np.array(_Y90))
            prims.append(
                Primitive(
                    "capsule",
                    (r, L / 2),
                    ((x0 + x1) / 2, (y0 + y1) / 2, 0.0),
                    tuple(matrix_to_aa(R)),
                    name=name,
                )
            )

    ring(-0.045, 0.024, 0.021, 0.018, 10, "thumb_loop")  # hole ≈ 28 × 22 mm
    ring(-0.050, -0.030, 0.030, 0.019, 12, "finger_loop")  # hole ≈ 46 × 24 mm
    for y in (0.012, -0.012):
        prims.append(Primitive("capsule", (0.005, 0.012), (-0.006, y, 0.0), _Y90, name="shank"))
    return prims, (
        "scissors lying flat: blades 110 × 18 × 6 mm, a thumb loop (hole ≈ 28 × 22 mm) and a "
        "finger loop for two fingers (hole ≈ 46 × 24 mm) made of capsules of radius 7 mm "
        "(14 mm thick, the catalogue's thickness), joined to the pivot by two shank capsules; "
        "about 190 × 94 × 14 mm (YCB 037_scissors)"
    )


_YCB_BUILDERS: dict[str, Callable[[], tuple[list[Primitive], str]]] = {
    "mayonnaisebottle": _mayonnaise,
    "banana": _banana,
    "bowl": _bowl,
    "largeclamp": _clamp,
    "pitcherbase": _pitcher,
    "powerdrill": _drill,
    "scissor": _scissors,
}


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
            [Primitive("cylinder", (d / 2, h / 2), rot_aa=_Y90, name="cylinder")],
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
        prims, text = _YCB_BUILDERS[spec.id]()
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
    """
    return _build(object_spec(object_id))
