"""The up direction (against gravity) of a capture recorded in a camera frame.

Camera frames (HO-3D, DexYCB, …) carry no gravity direction. :func:`estimate_up` recovers it from
the manipulated object, assuming the object **rests on a flat table at the rest frame** (frame 0
by default) and is then **lifted**:

1. **Resting poses.** The object mesh is posed at the rest frame and its convex hull is taken.
   A rigid body resting on a plane stands on the hull triangle through which the vertical from
   its centre of mass passes (the centroid of the hull solid stands in for the centre of mass),
   so only those triangles are candidates. Each one's stability margin is the distance from the
   centre of mass's projection to the edge of its support polygon (the hull vertices within
   ``SUPPORT_TOLERANCE_M`` of its plane); poses with a margin under ``MIN_MARGIN_M`` (balanced
   on an edge) are dropped.
2. **Lift.** The lift direction is the mean direction of the object's displacement from the rest
   frame, over the frames where it has moved by at least ``min_lift`` [m] and by at least half of
   its largest displacement.
3. **Choice.** Among the candidate poses, the one whose outward triangle normal points most
   against the lift is the resting pose; ``up`` is that normal negated. People lift towards
   themselves, so the lift is typically 10–40° off the vertical: it only has to pick the right
   pose among the few stable ones, whose normals are much further apart for most objects.
4. **Checks.** ``cos(lift, up)`` is the confidence (doubtful under ``MIN_CONFIDENT_COS``); with
   hand keypoints, the hand must not go below the table plane by more than
   ``HAND_BELOW_TABLE_TOLERANCE_M``. The resting plane is below the centre of mass by
   construction (it is a hull face under it).

The table height is ``min(up · x)`` over the object's vertices at the rest frame — the height of
the resting plane along ``up``.

The estimate fails (:class:`~dexcanvas_core.errors.ValidationError`) when the object never moves
by ``min_lift``: a static object gives no direction; pass the up direction instead.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.rotations import quat_wxyz_to_matrix

MIN_LIFT_M = 0.02
"""Smallest displacement [m] of the object from its rest pose that counts as a lift."""

SUPPORT_TOLERANCE_M = 0.002
"""Hull vertices within this distance [m] of a resting triangle's plane touch the table (a scanned
flat bottom is not exactly flat): they make the support polygon."""

MIN_MARGIN_M = 0.002
"""Smallest stability margin [m] (distance from the centre of mass's projection to the support
polygon's edge) of a resting pose taken as a candidate; poses balanced on an edge are not."""

HAND_BELOW_TABLE_TOLERANCE_M = 0.02
"""How far [m] hand keypoints may go below the estimated table plane before the estimate is
flagged (keypoints sit inside the fingers, a few mm below the skin)."""

MIN_CONFIDENT_COS = 0.7
"""``cos(lift, up)`` under which the estimate is reported as doubtful (lift more than 45° off the
up direction)."""


@dataclass(frozen=True)
class UpEstimate:
    """Result of :func:`estimate_up`.

    Attributes:
        up: ``(3,)`` unit vector against gravity, in the frame of the inputs.
        table_height: height [m] of the table top along ``up`` (``up · x`` of its plane).
        confidence: in ``[0, 1]``; ``cos(lift, up)`` (1 for a given ``up``), halved when the hand
            goes below the table.
        reason: one line saying how ``up`` was found and what was checked.
        lift_direction: ``(3,)`` unit mean lift direction, ``None`` for a given ``up``.
        lift_up_angle_deg: angle [deg] between the lift and ``up`` (``None`` for a given ``up``).
        support_area_m2: area [m²] of the support polygon of the resting pose (0 for a given
            ``up``).
        stability_margin_m: the resting pose's stability margin [m] (0 for a given ``up``).
        hand_below_table_m: deepest hand keypoint below the table [m] (0 if none or no hand given).
    """

    up: np.ndarray
    table_height: float
    confidence: float
    reason: str
    lift_direction: np.ndarray | None = None
    lift_up_angle_deg: float | None = None
    support_area_m2: float = 0.0
    stability_margin_m: float = 0.0
    hand_below_table_m: float = 0.0


def _check_array(a: np.ndarray, shape: tuple[int | None, ...], name: str) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != len(shape) or any(
        s is not None and s != n for s, n in zip(shape, a.shape, strict=True)
    ):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValidationError(f"{name} must have shape {want}, got {a.shape}", field=name)
    if not np.isfinite(a).all():
        raise ValidationError(f"{name} has NaN or inf values", field=name)
    return a


def _unit(v: np.ndarray, name: str) -> np.ndarray:
    v = _check_array(v, (3,), name)
    n = float(np.linalg.norm(v))
    if n < 1e-9:
        raise ValidationError(f"{name} must be a non-zero 3-vector, got {v.tolist()}", field=name)
    return v / n


@dataclass(frozen=True)
class _Rest:
    """A stable resting pose of a convex body on a plane: one hull triangle under the COM."""

    normal: np.ndarray  # outward unit normal of the triangle (the table pushes along -normal)
    margin: float  # distance [m] from the COM's projection to the support polygon's edge
    area: float  # area [m²] of the support polygon


def _polygon_margin(points2: np.ndarray, c2: np.ndarray) -> tuple[float, float]:
    """Signed distance of ``c2`` to the edge of the convex hull of ``points2`` (> 0 inside) and
    the hull's area; ``(-inf, 0)`` for fewer than 3 non-collinear points."""
    if len(points2) < 3:
        return -np.inf, 0.0
    try:
        poly = ConvexHull(points2)
    except (QhullError, ValueError):
        return -np.inf, 0.0
    # equations: unit outward normal · p + offset <= 0 inside
    return float(-(poly.equations[:, :2] @ c2 + poly.equations[:, 2]).max()), float(poly.volume)


def solid_centroid(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray | None:
    """Centroid of the solid a closed triangle mesh encloses (uniform density), or ``None`` when
    the mesh encloses no volume (open, flat or inconsistently wound)."""
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    ref = tri.reshape(-1, 3).mean(axis=0)
    rel = tri - ref
    vols = np.einsum("ij,ij->i", rel[:, 0], np.cross(rel[:, 1], rel[:, 2])) / 6
    total = float(vols.sum())
    extent = float(np.ptp(tri.reshape(-1, 3), axis=0).max())
    if not np.isfinite(total) or abs(total) < 1e-3 * extent**3:
        return None
    return ref + (vols[:, None] * rel.sum(axis=1) / 4).sum(axis=0) / total


def resting_poses(
    points: np.ndarray,
    support_tolerance: float = SUPPORT_TOLERANCE_M,
    com: np.ndarray | None = None,
) -> tuple[list[_Rest], np.ndarray]:
    """The stable resting poses of the convex hull of ``points`` on a plane, and the centre of
    mass used (``com``, default the centroid of the hull solid).

    A convex body rests on a plane on the hull triangle through which the vertical from its
    centre of mass passes. Its stability margin is measured on the support polygon: the hull
    vertices within ``support_tolerance`` [m] of that triangle's plane (a scanned flat bottom is
    not exactly flat).

    Raises:
        ValidationError: fewer than 4 points or all points (nearly) on a plane.
    """
    points = np.asarray(points, dtype=np.float64)
    try:
        hull = ConvexHull(points)
    except (QhullError, ValueError) as exc:
        raise ValidationError(
            f"object mesh has no 3-D convex hull ({len(points)} vertices; flat or degenerate): "
            f"{str(exc).splitlines()[0]}",
            field="object_vertices",
        ) from exc
    eq = hull.equations  # outward unit normal · x + offset <= 0 inside
    tri = points[hull.simplices]  # (F, 3, 3)
    inner = points[hull.vertices].mean(axis=0)
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    if com is None:
        rel = tri - inner
        vols = np.abs(np.einsum("ij,ij->i", rel[:, 0], np.cross(rel[:, 1], rel[:, 2]))) / 6
        com = (vols[:, None] * (tri.sum(axis=1) + inner) / 4).sum(axis=0) / vols.sum()
    com = np.asarray(com, dtype=np.float64)

    # Barycentric test: does the COM, projected along the normal, fall inside the triangle?
    n = eq[:, :3]
    q = com - n * (n @ com + eq[:, 3])[:, None]
    v0 = q - tri[:, 0]
    d00 = np.einsum("ij,ij->i", e1, e1)
    d01 = np.einsum("ij,ij->i", e1, e2)
    d11 = np.einsum("ij,ij->i", e2, e2)
    d20 = np.einsum("ij,ij->i", v0, e1)
    d21 = np.einsum("ij,ij->i", v0, e2)
    den = d00 * d11 - d01 * d01
    ok = den > 1e-18
    b1 = np.where(ok, (d11 * d20 - d01 * d21) / np.where(ok, den, 1), -1)
    b2 = np.where(ok, (d00 * d21 - d01 * d20) / np.where(ok, den, 1), -1)
    inside = ok & (b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1)

    hv = points[hull.vertices]
    rests: list[_Rest] = []
    for i in np.flatnonzero(inside):
        normal = n[i]
        h = -eq[i, 3]
        near = hv[h - hv @ normal <= support_tolerance]
        a = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(normal, a)
        margin, area = _polygon_margin(
            np.stack([near @ a, near @ b], axis=1), np.array([com @ a, com @ b])
        )
        rests.append(_Rest(normal=normal, margin=margin, area=area))
    return rests, com


def _lift_direction(
    centres: np.ndarray, rest_frame: int, min_lift: float
) -> tuple[np.ndarray, float]:
    """Mean unit displacement over the frames moved by ≥ max(min_lift, half the largest)."""
    d = centres - centres[rest_frame]
    dist = np.linalg.norm(d, axis=1)
    biggest = float(dist.max())
    if biggest < min_lift:
        return np.zeros(3), biggest
    sel = dist >= max(min_lift, 0.5 * biggest)
    mean = (d[sel] / dist[sel, None]).mean(axis=0)
    norm = float(np.linalg.norm(mean))
    if norm < 1e-6:  # displacements cancel out (e.g. moved away and back on both sides)
        k = int(np.argmax(dist))
        return d[k] / dist[k], biggest
    return mean / norm, biggest


def estimate_up(
    object_vertices: np.ndarray,
    object_pos: np.ndarray,
    object_quat_wxyz: np.ndarray,
    *,
    object_faces: np.ndarray | None = None,
    up: np.ndarray | None = None,
    rest_frame: int = 0,
    min_lift: float = MIN_LIFT_M,
    hand_points: np.ndarray | None = None,
    where: str = "capture",
) -> UpEstimate:
    """Estimate the up direction and the table height from an object resting, then lifted.

    Args:
        object_vertices: ``(V, 3)`` object mesh vertices [m] in the object frame.
        object_pos: ``(T, 3)`` object frame origin [m] per frame.
        object_quat_wxyz: ``(T, 4)`` object orientation per frame (scalar first).
        object_faces: ``(F, 3)`` triangles of a closed mesh: the centre of mass is then the
            centroid of the enclosed solid (default: the centroid of the convex hull's solid,
            which is off for non-convex objects such as a banana or a clamp).
        up: a known up direction ``(3,)``; then only the table height is computed.
        rest_frame: the frame at which the object rests on the table (default 0).
        min_lift: smallest displacement [m] from the rest pose that counts as a lift.
        hand_points: optional ``(T, K, 3)`` hand keypoints [m] for the below-the-table check.
        where: what the data is (a file, a sequence) for error messages.

    Raises:
        ValidationError: bad shapes or values; or, without ``up``, the object never moves by
            ``min_lift`` (a static object gives no lift direction: pass the up direction).
    """
    verts = _check_array(object_vertices, (None, 3), "object_vertices")
    pos = _check_array(object_pos, (None, 3), "object_pos")
    quat = _check_array(object_quat_wxyz, (len(pos), 4), "object_quat_wxyz")
    if not 0 <= rest_frame < len(pos):
        raise ValidationError(
            f"{where}: rest_frame {rest_frame} is outside the {len(pos)} frames", field="rest_frame"
        )
    R = quat_wxyz_to_matrix(quat)
    rest = verts @ R[rest_frame].T + pos[rest_frame]

    hand = None
    if hand_points is not None:
        hand = _check_array(hand_points, (len(pos), None, 3), "hand_points")

    def below(u: np.ndarray, height: float) -> float:
        if hand is None:
            return 0.0
        return float(max(0.0, height - float((hand @ u).min())))

    if up is not None:
        u = _unit(np.asarray(up, dtype=np.float64), "up")
        height = float((rest @ u).min())
        depth = below(u, height)
        return UpEstimate(
            up=u,
            table_height=height,
            confidence=1.0,
            reason=f"given up {np.round(u, 4).tolist()}; table height from the object's lowest "
            f"vertex at frame {rest_frame}",
            hand_below_table_m=depth,
        )

    com = None
    if object_faces is not None:
        com = solid_centroid(rest, object_faces)
    rests, centroid_rest = resting_poses(rest, com=com)
    # The centroid moves with the object: its track gives the object's displacement.
    centroid_obj = R[rest_frame].T @ (centroid_rest - pos[rest_frame])
    centres = np.einsum("tij,j->ti", R, centroid_obj) + pos
    lift, biggest = _lift_direction(centres, rest_frame, min_lift)
    if biggest < min_lift:
        raise ValidationError(
            f"{where}: cannot estimate the up direction: the object moves at most "
            f"{biggest * 1000:.1f} mm from its pose at frame {rest_frame} (a lift of at least "
            f"{min_lift * 1000:.0f} mm is needed); give the up direction instead "
            "(up_axis / --up-axis, e.g. a unit vector in the source frame)",
            field="up_axis",
        )
    if not rests:  # cannot happen for a convex hull (its lowest point along any g rests it)
        raise ValidationError(f"{where}: the object mesh has no stable resting pose")
    candidates = [r for r in rests if r.margin >= MIN_MARGIN_M] or rests
    best = max(candidates, key=lambda r: float(-r.normal @ lift))
    u = -best.normal
    cos_lift = float(u @ lift)
    height = float((rest @ u).min())
    depth = below(u, height)

    notes = [
        f"object resting at frame {rest_frame} on a {best.area * 1e4:.1f} cm² support "
        f"(stability margin {best.margin * 1000:.0f} mm, {len(candidates)} stable poses)",
        f"lift {biggest * 1000:.0f} mm at {np.degrees(np.arccos(np.clip(cos_lift, -1, 1))):.0f}° "
        "from up",
    ]
    confidence = max(0.0, cos_lift)
    if cos_lift < MIN_CONFIDENT_COS:
        notes.append("doubtful: the lift is far from the up direction")
    if depth > HAND_BELOW_TABLE_TOLERANCE_M:
        notes.append(f"doubtful: the hand goes {depth * 1000:.0f} mm below the table")
        confidence *= 0.5
    return UpEstimate(
        up=u,
        table_height=height,
        confidence=confidence,
        reason="; ".join(notes),
        lift_direction=lift,
        lift_up_angle_deg=float(np.degrees(np.arccos(np.clip(cos_lift, -1.0, 1.0)))),
        support_area_m2=best.area,
        stability_margin_m=best.margin,
        hand_below_table_m=depth,
    )


CONSENSUS_ANGLE_DEG = 10.0
"""Per-sequence estimates within this angle [deg] of each other support one consensus."""

CONSENSUS_MIN_SHARE = 0.5
"""Share of the estimates of a group that must support the consensus."""

CONSENSUS_MIN_COUNT = 3
"""Fewest supporting estimates for a consensus."""


@dataclass(frozen=True)
class SharedUp:
    """Result of :func:`consensus_up`.

    Attributes:
        up: ``(3,)`` the consensus up direction (mean of the supporting estimates).
        supporters: ``(N,)`` bool, which estimates are within ``max_angle_deg`` of it.
        angles_deg: ``(N,)`` angle [deg] of each estimate to it (``nan`` for a missing one).
    """

    up: np.ndarray
    supporters: np.ndarray
    angles_deg: np.ndarray


def consensus_up(
    ups: list[np.ndarray | None],
    *,
    max_angle_deg: float = CONSENSUS_ANGLE_DEG,
    min_share: float = CONSENSUS_MIN_SHARE,
    min_count: int = CONSENSUS_MIN_COUNT,
    where: str = "sequences",
) -> SharedUp:
    """The up direction shared by sequences recorded in one frame (one fixed camera).

    Per-sequence estimates fail when the object does not rest on the table at the rest frame
    (stacked on another object) or is carried sideways more than it is lifted; the sequences of
    one camera setup share one up direction, so the largest group of estimates that agree
    within ``max_angle_deg`` gives it robustly. ``None`` entries (sequences without an estimate,
    e.g. an object that never moved) count in the total but support nothing.

    Raises:
        ValidationError: fewer than ``min_count`` estimates, or fewer than ``min_share`` of them,
            agree (the sequences may not share a frame).
    """
    have = [i for i, u in enumerate(ups) if u is not None]
    U = np.array([np.asarray(ups[i], dtype=np.float64) for i in have]).reshape(-1, 3)
    cos_max = np.cos(np.radians(max_angle_deg))
    best: np.ndarray | None = None
    if len(U):
        U = U / np.linalg.norm(U, axis=1, keepdims=True)
        support = (U @ U.T) >= cos_max
        seed = int(np.argmax(support.sum(axis=1)))
        best = U[support[seed]].mean(axis=0)
        for _ in range(3):  # re-centre on the supporters of the mean
            best /= np.linalg.norm(best)
            best = U[U @ best >= cos_max].mean(axis=0)
        best /= np.linalg.norm(best)
    angles = np.full(len(ups), np.nan)
    if best is not None:
        angles[have] = np.degrees(np.arccos(np.clip(U @ best, -1.0, 1.0)))
    supporters = np.nan_to_num(angles, nan=180.0) <= max_angle_deg
    n = int(supporters.sum())
    if best is None or n < min_count or n < min_share * len(ups):
        raise ValidationError(
            f"{where}: no shared up direction: {n} of {len(ups)} per-sequence estimates agree "
            f"within {max_angle_deg:g}° (need {min_count} and {min_share:.0%}); the sequences "
            "may not share one camera frame: estimate each on its own or give the up direction",
            field="up_axis",
        )
    return SharedUp(up=best, supporters=supporters, angles_deg=angles)
