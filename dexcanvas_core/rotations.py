"""Rotation conversions with the convention in every name.

Axis-angle (``aa``, a rotation vector [rad]), quaternions (``quat_wxyz`` scalar first or
``quat_xyzw`` scalar last), rotation matrices (``matrix``, ``(..., 3, 3)``) and the intrinsic
``XYZ`` Euler angles of the DexCanvas ``urdf_dof`` wrist (``euler_XYZ``). All functions take
arrays with any leading batch shape and return float64 arrays of the matching shape; the
numerics are SciPy's ``Rotation``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from dexcanvas_core.errors import ValidationError


def _as_batch(x, tail: tuple[int, ...], name: str) -> tuple[np.ndarray, tuple[int, ...]]:
    a = np.asarray(x, dtype=np.float64)
    if a.shape[a.ndim - len(tail) :] != tail:
        want = "(..., " + ", ".join(map(str, tail)) + ")"
        raise ValidationError(f"{name} must have shape {want}, got {a.shape}", field=name)
    if not np.all(np.isfinite(a)):
        raise ValidationError(f"{name} contains NaN or inf", field=name)
    lead = a.shape[: a.ndim - len(tail)]
    return a.reshape((-1, *tail)), lead


def _rot(x, kind: str) -> tuple[Rotation, tuple[int, ...]]:
    if kind == "aa":
        a, lead = _as_batch(x, (3,), "axis-angle")
        return Rotation.from_rotvec(a), lead
    if kind == "matrix":
        a, lead = _as_batch(x, (3, 3), "rotation matrix")
        return Rotation.from_matrix(a), lead
    if kind in ("wxyz", "xyzw"):
        a, lead = _as_batch(x, (4,), f"quaternion ({kind})")
        norm = np.linalg.norm(a, axis=-1)
        if np.any(norm < 1e-9):
            raise ValidationError(f"quaternion ({kind}) has zero norm", field=f"quat_{kind}")
        return Rotation.from_quat(a, scalar_first=kind == "wxyz"), lead
    if kind == "euler_XYZ":
        a, lead = _as_batch(x, (3,), "euler XYZ")
        return Rotation.from_euler("XYZ", a), lead
    raise ValueError(kind)


def _out(r: Rotation, kind: str, lead: tuple[int, ...]) -> np.ndarray:
    if kind == "aa":
        return r.as_rotvec().reshape((*lead, 3))
    if kind == "matrix":
        return r.as_matrix().reshape((*lead, 3, 3))
    if kind in ("wxyz", "xyzw"):
        q = r.as_quat(canonical=True, scalar_first=kind == "wxyz")
        return q.reshape((*lead, 4))
    if kind == "euler_XYZ":
        return r.as_euler("XYZ").reshape((*lead, 3))
    raise ValueError(kind)


def _convert(x, src: str, dst: str) -> np.ndarray:
    r, lead = _rot(x, src)
    return _out(r, dst, lead)


def aa_to_matrix(aa) -> np.ndarray:
    """Axis-angle ``(..., 3)`` [rad] → rotation matrix ``(..., 3, 3)``."""
    return _convert(aa, "aa", "matrix")


def matrix_to_aa(matrix) -> np.ndarray:
    """Rotation matrix ``(..., 3, 3)`` → axis-angle ``(..., 3)`` with norm in [0, π]."""
    return _convert(matrix, "matrix", "aa")


def aa_to_quat_wxyz(aa) -> np.ndarray:
    """Axis-angle ``(..., 3)`` → unit quaternion ``(..., 4)``, scalar first, w ≥ 0."""
    return _convert(aa, "aa", "wxyz")


def aa_to_quat_xyzw(aa) -> np.ndarray:
    """Axis-angle ``(..., 3)`` → unit quaternion ``(..., 4)``, scalar last, w ≥ 0."""
    return _convert(aa, "aa", "xyzw")


def quat_wxyz_to_aa(q_wxyz) -> np.ndarray:
    """Quaternion ``(..., 4)`` scalar first (normalised here) → axis-angle ``(..., 3)``."""
    return _convert(q_wxyz, "wxyz", "aa")


def quat_xyzw_to_aa(q_xyzw) -> np.ndarray:
    """Quaternion ``(..., 4)`` scalar last (normalised here) → axis-angle ``(..., 3)``."""
    return _convert(q_xyzw, "xyzw", "aa")


def quat_wxyz_to_matrix(q_wxyz) -> np.ndarray:
    """Quaternion ``(..., 4)`` scalar first → rotation matrix ``(..., 3, 3)``."""
    return _convert(q_wxyz, "wxyz", "matrix")


def quat_xyzw_to_matrix(q_xyzw) -> np.ndarray:
    """Quaternion ``(..., 4)`` scalar last → rotation matrix ``(..., 3, 3)``."""
    return _convert(q_xyzw, "xyzw", "matrix")


def matrix_to_quat_wxyz(matrix) -> np.ndarray:
    """Rotation matrix ``(..., 3, 3)`` → quaternion ``(..., 4)`` scalar first, w ≥ 0."""
    return _convert(matrix, "matrix", "wxyz")


def matrix_to_quat_xyzw(matrix) -> np.ndarray:
    """Rotation matrix ``(..., 3, 3)`` → quaternion ``(..., 4)`` scalar last, w ≥ 0."""
    return _convert(matrix, "matrix", "xyzw")


def quat_wxyz_to_xyzw(q_wxyz) -> np.ndarray:
    """Reorder a quaternion from scalar-first to scalar-last (no normalisation)."""
    q, lead = _as_batch(q_wxyz, (4,), "quaternion (wxyz)")
    return q[:, [1, 2, 3, 0]].reshape((*lead, 4))


def quat_xyzw_to_wxyz(q_xyzw) -> np.ndarray:
    """Reorder a quaternion from scalar-last to scalar-first (no normalisation)."""
    q, lead = _as_batch(q_xyzw, (4,), "quaternion (xyzw)")
    return q[:, [3, 0, 1, 2]].reshape((*lead, 4))


def euler_XYZ_to_aa(euler_XYZ) -> np.ndarray:
    """Intrinsic XYZ Euler angles [rad] (the ``urdf_dof[:, 3:6]`` wrist) → axis-angle."""
    return _convert(euler_XYZ, "euler_XYZ", "aa")


def aa_to_euler_XYZ(aa) -> np.ndarray:
    """Axis-angle → intrinsic XYZ Euler angles [rad] (the ``urdf_dof[:, 3:6]`` convention)."""
    return _convert(aa, "aa", "euler_XYZ")


def slerp_aa(t_src, aa_src, t_dst) -> np.ndarray:
    """Spherical interpolation of rotations given as axis-angle.

    Args:
        t_src: sample times ``(T,)`` [s], strictly increasing.
        aa_src: rotations ``(T, ..., 3)`` at ``t_src``; every trailing rotation is interpolated
            independently (e.g. ``(T, 15, 3)`` finger joints).
        t_dst: query times ``(M,)`` [s] inside ``[t_src[0], t_src[-1]]``.

    Returns:
        ``(M, ..., 3)`` axis-angle along the shortest arc between neighbouring samples.
    """
    t_src = np.asarray(t_src, dtype=np.float64)
    t_dst = np.asarray(t_dst, dtype=np.float64)
    aa = np.asarray(aa_src, dtype=np.float64)
    if aa.shape[0] != t_src.shape[0] or aa.shape[-1] != 3:
        raise ValidationError(
            f"slerp_aa: rotations {aa.shape} do not match times {t_src.shape}", field="aa_src"
        )
    inner = aa.shape[1:-1]
    flat = aa.reshape(aa.shape[0], -1, 3)
    out = np.empty((t_dst.shape[0], flat.shape[1], 3))
    if t_src.shape[0] == 1:
        out[:] = flat[0]
        return out.reshape((t_dst.shape[0], *inner, 3))
    for k in range(flat.shape[1]):
        out[:, k] = Slerp(t_src, Rotation.from_rotvec(flat[:, k]))(t_dst).as_rotvec()
    return out.reshape((t_dst.shape[0], *inner, 3))


def rotation_angle_between_aa(aa_a, aa_b) -> np.ndarray:
    """Geodesic angle [rad] between two rotations given as axis-angle ``(..., 3)``."""
    ra, lead = _rot(aa_a, "aa")
    rb, _ = _rot(aa_b, "aa")
    return (ra.inv() * rb).magnitude().reshape(lead)


def tangent_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents of the unit normal ``n``: ``t₁ = n × a / ‖n × a‖`` (``a`` a world axis
    away from ``n``) and ``t₂ = n × t₁`` (scalar cross products: ``np.cross`` costs ~25 µs a
    call). Shared by the retargeting's force QP cones and contact-term surface frames."""
    x, y, z = float(n[0]), float(n[1]), float(n[2])
    t1 = np.array([0.0, z, -y]) if abs(x) < 0.9 else np.array([-z, 0.0, x])  # n × x̂, n × ŷ
    t1 /= np.sqrt(t1 @ t1)
    a, b, c = t1
    return t1, np.array([y * c - z * b, z * a - x * c, x * b - y * a])
