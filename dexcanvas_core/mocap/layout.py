"""The mocap marker layout: 14 hand markers on anatomical landmarks, 4 markers per object.

Hand markers (``HAND_MARKERS``)
===============================

Every hand marker is rigidly carried by one MANO joint frame (its ``parent``, a name of
``keypoints.MANO_JOINTS``). Its rest position in MANO's template frame (fingers −x, palm −y,
thumb +z for the right hand) is a point on a bone — ``fraction`` of the way from the bone's
proximal keypoint ``bone[0]`` to its distal keypoint ``bone[1]`` — moved ``skin_m`` along the
bone's dorsal normal (the part of template +y perpendicular to the bone: the back of the hand,
the same direction as the ``abd`` row of ``mano.limits.joint_frames``) and ``radial_m`` along
template +z (towards the thumb). ``skin_m`` is the distance from the bone axis to the centre of
the marker: soft tissue + marker base + marker radius (3–4 mm hemispherical markers on 2 mm
bases), so it does not scale with hand size; the point on the bone does.

==============  ======  ==================  ====  =====  ======  ===============================
name            parent  bone                frac  skin   radial  landmark
==============  ======  ==================  ====  =====  ======  ===============================
``mc2_base``    wrist   wrist → index1      0.12  12 mm  12 mm   dorso-radial base, metacarpal 2
``mc2_head``    wrist   wrist → index1      0.85  12 mm   0      head of metacarpal 2 (knuckle)
``mc5_head``    wrist   wrist → pinky1      0.90  12 mm   0      head of metacarpal 5 (knuckle)
``thumb_mc``    thumb1  thumb1 → thumb2     0.50   9 mm   0      dorsal shaft, metacarpal 1
``thumb_pp``    thumb2  thumb2 → thumb3     0.50   8 mm   0      thumb proximal phalanx, dorsal
``thumb_nail``  thumb3  thumb3 → thumb_tip  0.55   7 mm   0      thumbnail
``{f}_mp``      {f}2    {f}2 → {f}3         0.50   8 mm   0      middle phalanx, dorsal
``{f}_nail``    {f}3    {f}3 → {f}_tip      0.55   7 mm   0      fingernail
==============  ======  ==================  ====  =====  ======  ===============================

(``{f}`` = index, middle, ring, pinky: 3 palm + 3 thumb + 8 finger markers = 14.)

**Why these 14 make the 21 keypoints observable** (given the fitter's priors, ``fit``):

* *Wrist and the five MCP/CMC keypoints* are fixed points of MANO's root frame (the palm). Three
  palm markers on a scalene triangle (about 65 × 76 × 59 mm) give its 6-DoF pose; the finger
  and thumb markers add further constraints, and short dropouts are spline-filled.
* *Fingers.* Below the MCP a finger has four active angles (MCP flexion and abduction, PIP and
  DIP flexion; axial twist and PIP/DIP abduction are held near zero by the anatomical prior).
  The middle-phalanx marker ``{f}_mp`` is carried by MCP ∘ PIP and the nail marker by
  MCP ∘ PIP ∘ DIP: six coordinates for four (five with the MCP twist) unknowns. A marker on
  the *proximal* phalanx instead would leave a two-link chain (PIP, DIP) ending in one point —
  two mirror solutions about the angle at which the nail marker lines up with the middle
  phalanx (≈ 30° of DIP flexion, mid-range), which tests showed the fitter confusing. With the
  middle-phalanx marker, the middle phalanx's position and direction are measured, and DIP
  flexion is a rotation about a known joint that moves the nail marker on a circle: unique.
* *Thumb.* CMC (flexion, abduction, axial rotation), MCP (flexion, abduction) and IP flexion:
  six angles. One marker per segment — metacarpal, proximal phalanx, nail — measures each
  segment, so thumb2 (MCP) and thumb3 (IP) are observed rather than inferred. With only two
  thumb markers, the tests showed a millimetre-level bias at the thumb joints even on exact
  data (one marker per segment pair leaves a weakly observed CMC/MCP trade-off); the third
  thumb marker is worth more than a fourth palm marker.
* Markers sit on the distal phalanges themselves, so fingertips — points of the same rigid
  segment — follow from the nail markers, not from a chain extrapolated out of the palm. The
  dorsal offsets put every marker off its bone axis, so a segment's rotation, not only a point
  on its axis, enters the measurement.

Object markers (``object_marker_positions``)
============================================

Four markers (``obj1`` … ``obj4``) per catalogue object, in the object frame (origin at the
centre of the object's bounding box, cylinder axis along z). Each is the surface point of the
object's primitive (box, cylinder, sphere; YCB items use their bounding box) reached from the
centre towards an aim point inside the bounding box, raised along the surface normal by a
stand-off (a marker on a short post: base + radius, 8–30 mm). The aim points come from 256
fixed candidate patterns (seeded; all in the upper half: the object rests on its −z face), tried
with three stand-off sets. Among the candidates whose six inter-marker distances differ pairwise
by at least ``MIN_DISTANCE_GAP_M`` (5 mm) — so labels can be recovered from distances alone —
the one whose rotation is best conditioned (largest ``rotation_conditioning``) is used.
``object_marker_table()`` lists the result for every object; it never changes between runs.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from functools import cache, lru_cache

import numpy as np

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import MANO21, MANO_JOINTS
from dexcanvas_core.taxonomy import OBJECTS, object_spec

# -- hand --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class HandMarker:
    """One hand marker of the layout (see the module docstring's table)."""

    name: str
    """Layout label, e.g. ``'index_nail'``."""
    parent: str
    """MANO joint (``keypoints.MANO_JOINTS``) whose frame carries the marker."""
    bone: tuple[str, str]
    """The bone the landmark lies on: proximal and distal keypoint (``keypoints.MANO21``)."""
    fraction: float
    """Position along the bone, 0 = ``bone[0]``, 1 = ``bone[1]``."""
    skin_m: float
    """Distance [m] from the bone axis to the marker centre, along the dorsal normal."""
    radial_m: float
    """Shift [m] towards the thumb side (template +z)."""
    landmark: str
    """Anatomical landmark."""
    finger: str | None
    """Finger the marker belongs to (``None`` for the dorsum markers on the palm)."""


def _finger_markers() -> tuple[HandMarker, ...]:
    out = [
        HandMarker(
            "thumb_mc",
            "thumb1",
            ("thumb1", "thumb2"),
            0.50,
            0.009,
            0.0,
            "dorsal shaft of the 1st metacarpal",
            "thumb",
        ),
        HandMarker(
            "thumb_pp",
            "thumb2",
            ("thumb2", "thumb3"),
            0.50,
            0.008,
            0.0,
            "dorsal proximal phalanx of the thumb",
            "thumb",
        ),
        HandMarker(
            "thumb_nail", "thumb3", ("thumb3", "thumb_tip"), 0.55, 0.007, 0.0, "thumbnail", "thumb"
        ),
    ]
    for f in ("index", "middle", "ring", "pinky"):
        out.append(
            HandMarker(
                f"{f}_mp", f"{f}2", (f"{f}2", f"{f}3"), 0.50, 0.008, 0.0, "dorsal middle phalanx", f
            )
        )
        out.append(
            HandMarker(
                f"{f}_nail", f"{f}3", (f"{f}3", f"{f}_tip"), 0.55, 0.007, 0.0, "fingernail", f
            )
        )
    return tuple(out)


HAND_MARKERS: tuple[HandMarker, ...] = (
    HandMarker(
        "mc2_base",
        "wrist",
        ("wrist", "index1"),
        0.12,
        0.012,
        0.012,
        "dorso-radial base of the 2nd metacarpal",
        None,
    ),
    HandMarker(
        "mc2_head",
        "wrist",
        ("wrist", "index1"),
        0.85,
        0.012,
        0.0,
        "dorsal head of the 2nd metacarpal (index knuckle)",
        None,
    ),
    HandMarker(
        "mc5_head",
        "wrist",
        ("wrist", "pinky1"),
        0.90,
        0.012,
        0.0,
        "dorsal head of the 5th metacarpal (little-finger knuckle)",
        None,
    ),
    *_finger_markers(),
)
"""The 14 hand markers, in the column order of every hand-marker array."""

HAND_MARKER_NAMES: tuple[str, ...] = tuple(m.name for m in HAND_MARKERS)
DORSUM_MARKERS: tuple[str, ...] = tuple(m.name for m in HAND_MARKERS if m.parent == "wrist")
"""The three hand markers on the palm (root frame), which fix the wrist pose."""

OBJECT_MARKER_NAMES: tuple[str, ...] = ("obj1", "obj2", "obj3", "obj4")
"""Labels of the four object markers."""

MARKER_NAMES: tuple[str, ...] = (*HAND_MARKER_NAMES, *OBJECT_MARKER_NAMES)
"""All 18 layout labels: 14 hand markers, then 4 object markers (column order of a stream)."""

MIN_DISTANCE_GAP_M = 0.005
"""Smallest difference [m] between any two of an object's six inter-marker distances."""


def hand_marker_parents() -> np.ndarray:
    """``(14,)`` int: index into ``MANO_JOINTS`` of each hand marker's parent joint."""
    return np.array([MANO_JOINTS.index(m.parent) for m in HAND_MARKERS], dtype=np.int64)


def hand_marker_rest_positions(rest_keypoints: np.ndarray, side: str = "right") -> np.ndarray:
    """``(14, 3)`` [m]: marker centres on a hand at rest, in its template frame.

    Args:
        rest_keypoints: ``(21, 3)`` rest keypoints (``HandSkeleton.rest_keypoints``), MANO21.
        side: ``'right'`` or ``'left'``; the layout is defined on the right hand, and the left
            one is its mirror image across the template's x = 0 plane (the same landmarks).
    """
    kp = np.asarray(rest_keypoints, dtype=np.float64)
    if kp.shape != (21, 3):
        raise ValidationError(f"rest_keypoints must be (21, 3), got {kp.shape}")
    if side not in ("right", "left"):
        raise ValidationError(f"side must be 'right' or 'left', got {side!r}", field="side")
    if side == "left":
        kp = kp * np.array([-1.0, 1.0, 1.0])  # build on the mirrored (right) hand
    out = np.empty((len(HAND_MARKERS), 3))
    up = np.array([0.0, 1.0, 0.0])
    radial = np.array([0.0, 0.0, 1.0])
    for k, m in enumerate(HAND_MARKERS):
        a, b = kp[MANO21.index(m.bone[0])], kp[MANO21.index(m.bone[1])]
        axis = (b - a) / np.linalg.norm(b - a)
        dorsal = up - (up @ axis) * axis
        dorsal /= np.linalg.norm(dorsal)
        out[k] = a + m.fraction * (b - a) + m.skin_m * dorsal + m.radial_m * radial
    if side == "left":
        out = out * np.array([-1.0, 1.0, 1.0])
    return out


def hand_marker_offsets(rest_keypoints: np.ndarray, side: str = "right") -> np.ndarray:
    """``(14, 3)`` [m]: each marker's rest position minus its parent joint's rest position
    (template frame) — the constant vector the parent joint's rotation carries."""
    kp = np.asarray(rest_keypoints, dtype=np.float64)
    return hand_marker_rest_positions(kp, side) - kp[hand_marker_parents()]


# -- objects -----------------------------------------------------------------------------------

_PATTERN_SEED = 20240611
"""Seed of the candidate aim patterns (fixed: the layout must not change between runs)."""
_N_PATTERNS = 256
_STANDOFFS_M = (
    (0.008, 0.011, 0.014, 0.017),
    (0.010, 0.015, 0.020, 0.025),
    (0.012, 0.018, 0.024, 0.030),
)
"""Stand-off sets [m] tried in turn (marker base + radius, then short posts)."""


@lru_cache(maxsize=1)
def _object_patterns() -> np.ndarray:
    """``(N, 4, 3)`` aim points as fractions of the half-extents, upper half (z in [0.1, 1])."""
    rng = np.random.default_rng(_PATTERN_SEED)
    xy = rng.uniform(-1.0, 1.0, size=(_N_PATTERNS, 4, 2))
    z = rng.uniform(0.1, 1.0, size=(_N_PATTERNS, 4, 1))
    return np.concatenate([xy, z], axis=-1)


def _surface_point(shape: str, half: np.ndarray, aim: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Surface point and outward normal of a primitive centred at the origin, towards ``aim``."""
    if shape == "sphere":
        n = aim / np.linalg.norm(aim)
        return half[0] * n, n
    if shape == "cylinder":
        r, hz = half[0], half[2]
        rho = np.hypot(aim[0], aim[1])
        if abs(aim[2]) / hz >= rho / r:  # leaves through an end cap
            s = hz / abs(aim[2])
            n = np.array([0.0, 0.0, np.sign(aim[2])])
        else:
            s = r / rho
            n = np.array([aim[0], aim[1], 0.0]) / rho
        return s * aim, n
    # box (cube, cuboid, ycb bounding box): leave through the face with the largest ratio
    ratios = np.abs(aim) / half
    axis = int(np.argmax(ratios))
    s = 1.0 / ratios[axis]
    n = np.zeros(3)
    n[axis] = np.sign(aim[axis])
    return s * aim, n


def _distance_gap(p: np.ndarray) -> float:
    d = sorted(np.linalg.norm(p[i] - p[j]) for i, j in itertools.combinations(range(len(p)), 2))
    return float(min(b - a for a, b in itertools.pairwise(d)))


@cache
def _object_markers(object_id: str) -> tuple[tuple[float, float, float], ...]:
    spec = object_spec(object_id)
    half = np.array(spec.bounding_box_m) / 2.0
    best: tuple[float, np.ndarray] | None = None
    for standoffs in _STANDOFFS_M:
        for pattern in _object_patterns():
            pts = []
            for frac, h in zip(pattern, standoffs, strict=True):
                p, n = _surface_point(spec.shape, half, frac * half)
                pts.append(p + h * n)
            P = np.array(pts)
            if _distance_gap(P) < MIN_DISTANCE_GAP_M:
                continue
            score = rotation_conditioning(P)
            if best is None or score > best[0] + 1e-12:
                best = (score, P)
    if best is None:  # pragma: no cover - every catalogue object has a passing candidate
        raise ValidationError(f"no asymmetric marker placement found for object {object_id!r}")
    return tuple(tuple(float(v) for v in row) for row in best[1])


def object_marker_positions(object_id: str) -> np.ndarray:
    """``(4, 3)`` [m]: the object's marker centres in its object frame (``obj1`` … ``obj4``).

    Raises:
        UnknownNameError: ``object_id`` is not in the catalogue.
    """
    return np.array(_object_markers(object_spec(object_id).id))


def object_marker_table() -> dict[str, np.ndarray]:
    """Object id → ``(4, 3)`` marker positions [m] for the whole catalogue."""
    return {oid: object_marker_positions(oid) for oid in OBJECTS}


def rotation_conditioning(points: np.ndarray) -> float:
    """Smallest eigenvalue [m²] of the marker set's "inertia" ``Σ_k (|c_k|² I − c_k c_kᵀ)``
    (``c_k`` = marker minus centroid): rigid registration's rotation error about the worst axis
    is ≈ σ / √λ_min for marker noise σ."""
    c = np.asarray(points, dtype=np.float64)
    c = c - c.mean(0)
    inertia = np.eye(3) * float((c * c).sum()) - c.T @ c
    return float(np.linalg.eigvalsh(inertia)[0])


def distance_gap_m(points: np.ndarray) -> float:
    """Smallest difference [m] between two pairwise distances of a marker set."""
    return _distance_gap(np.asarray(points, dtype=np.float64))
