"""Solid primitives posed in an object frame, with their exact signed distances.

Sizes follow MuJoCo's conventions (half sizes, see ``dexcanvas_core.objects.geometry``); a
``"mesh"`` primitive is a convex part of a mesh object (``dexcanvas_core.objects.mesh``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.objects.parts import ConvexPart
from dexcanvas_core.rotations import aa_to_matrix

PrimitiveType = Literal["box", "cylinder", "sphere", "capsule", "mesh"]
PRIMITIVE_TYPES: tuple[str, ...] = ("box", "cylinder", "sphere", "capsule", "mesh")
_SIZE_LEN = {"box": 3, "cylinder": 2, "sphere": 1, "capsule": 2, "mesh": 3}
_EPS = 1e-12

Y90: tuple[float, float, float] = (0.0, math.pi / 2, 0.0)
"""Axis-angle [rad] of a quarter turn about y: turns a primitive's z axis onto the object's x axis
(a lying cylinder or capsule)."""


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


def sdf_local(kind: str, size: tuple[float, ...], p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
