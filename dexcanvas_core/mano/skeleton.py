"""The built-in MANO-compatible hand skeleton: rest keypoints, bone lengths, measurement.

No MANO model file is needed. A :class:`HandSkeleton` holds the 21 rest keypoints of one hand
(MANO21 order: 16 MANO joints, then the thumb…pinky tips) in MANO's template frame; the
:class:`~dexcanvas_core.mano.layer.ManoLayer` poses it with MANO's axis-angle semantics.

**MANO's template frame** (right hand; facts read from the MANO mean joint locations published in
public code, see ``_MANO_MEAN_RIGHT_KEYPOINTS``), units metres:

* the fingers point along **-x** (wrist joint J0 at x ≈ +0.096, middle fingertip at x ≈ -0.079);
* the thumb lies on the **+z** side, the little finger on the -z side;
* the palm (volar side) faces **-y**, the back of the hand +y (volar normal = radial × distal =
  (+z) × (-x) = -y, and the thumb sits at y < 0, in front of the palm);
* the origin is not at the wrist: J0 ≈ (0.0957, 0.0064, 0.0062) m, so a posed wrist lands at
  ``J0 + transl`` (as in MANO / ``smplx``);
* finger flexion is mostly a positive rotation about +z (right hand): MANO's mean pose
  ``hands_mean`` has positive z components on the finger joints and curls the tips towards -y.

**Default skeleton** (``HandSkeleton.default``): MANO's own mean hand, i.e. MANO's regressed joint
locations and mesh fingertips at β = 0, so that keypoints match MANO data (DexCanvas
``mano_joint_pos``). MANO's regressed joints are not anatomical joint centres (its MCP joints sit
distal to the anatomical ones), so anatomical segment ratios are offered separately
(``HandSkeleton.anthropometric``, Buchholz et al. 1992). A subject's own lengths come from
``measure_bone_lengths`` + ``HandSkeleton.from_bone_lengths``, which keep the default directions.

The left MANO model is the mirror image of the right across the template's **x = 0** plane
(``x → -x``; the official left mean joints are the right ones with x negated, e.g. the left wrist
at (-0.0957, 0.0064, 0.0062) m). The left skeleton here is built the same way. A left-hand pose
that mirrors a right-hand pose has its axis-angles mapped ``(x, y, z) → (x, -y, -z)``.

**Bone lengths** are the distances between each of the 20 non-wrist MANO21 keypoints and its
parent keypoint, in ``BONE_NAMES`` order (= ``MANO21[1:]``: index1..3, middle1..3, pinky1..3,
ring1..3, thumb1..3, then the five tips thumb, index, middle, ring, pinky). The bone named
``index1`` is wrist→index1 (the palm/metacarpal ray), ``index_tip`` is index3→index tip (the distal
phalanx). ``HandSkeleton.bone_lengths_by_finger()`` regroups them per finger, proximal to distal.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np

from dexcanvas_core.errors import UnknownNameError, ValidationError
from dexcanvas_core.keypoints import (
    FINGERS,
    MANO21,
    MANO_JOINTS,
    MANO_PARENTS,
    convert_keypoints,
)

Side = Literal["right", "left"]
SIDES: tuple[str, ...] = ("right", "left")

TIP_PARENTS: tuple[int, ...] = tuple(MANO_JOINTS.index(f"{f}3") for f in FINGERS)
"""Index (in ``MANO_JOINTS``) of the distal joint that carries each fingertip, thumb…pinky."""

MANO21_PARENTS: tuple[int, ...] = (*MANO_PARENTS, *TIP_PARENTS)
"""Parent keypoint of each MANO21 keypoint (``-1`` for the wrist)."""

BONE_NAMES: tuple[str, ...] = MANO21[1:]
"""The 20 bones, each named by its distal keypoint, in the order of every bone-length array."""

FINGER_BONES: dict[str, tuple[int, ...]] = {
    f: tuple(BONE_NAMES.index(n) for n in (f"{f}1", f"{f}2", f"{f}3", f"{f}_tip")) for f in FINGERS
}
"""Per finger, the indices into ``BONE_NAMES`` of its four bones, proximal to distal."""

# MANO's mean right hand in its template frame [m], MANO21 order. Source: ``MANO_REF_JOINTS`` in
# oarriaga/paz ``examples/minimal_hand/joint_config.py`` (after CalciferZh/minimal-hand, which
# builds it from MANO_LEFT.pkl: ``J_regressor @ v_template`` for the 16 joints and the mesh
# vertices 333, 444, 672, 555, 744 for the index, middle, pinky, ring, thumb tips). We negate x to
# get the right hand (the same 16 joints appear for MANO_RIGHT, x un-negated, e.g. in public
# MANO-to-joint converters: wrist J0 = (0.09566994, 0.00638343, 0.0061863)). Tips reordered to
# MANO21's thumb, index, middle, ring, pinky.
_MANO_MEAN_RIGHT_KEYPOINTS = np.array(
    [
        [0.09566993, 0.00638343, 0.00618631],  # wrist
        [0.00757268, 0.00118307, 0.02687229],  # index1 (MCP)
        [-0.02510622, 0.00519243, 0.02908936],  # index2 (PIP)
        [-0.04726213, 0.00389400, 0.02897525],  # index3 (DIP)
        [0.00100949, 0.00490447, 0.00282876],  # middle1
        [-0.03017318, 0.00676579, -0.00276574],  # middle2
        [-0.05307782, 0.00551369, -0.00671026],  # middle3
        [0.02688296, -0.00355690, -0.03702304],  # pinky1
        [0.00986855, -0.00349508, -0.04952181],  # pinky2
        [-0.00599835, -0.00418623, -0.05985372],  # pinky3
        [0.01393438, 0.00242601, -0.02048689],  # ring1
        [-0.01437990, 0.00449301, -0.02558543],  # ring2
        [-0.03790041, 0.00280490, -0.03321924],  # ring3
        [0.07158022, -0.00913891, 0.03199915],  # thumb1 (CMC)
        [0.05194698, -0.00824762, 0.05569871],  # thumb2 (MCP)
        [0.02972924, -0.01368059, 0.07022282],  # thumb3 (IP)
        [0.00371570, -0.01635903, 0.09410497],  # thumb tip (vertex 744)
        [-0.07238572, 0.00295241, 0.02766223],  # index tip (vertex 333)
        [-0.07899282, 0.00614665, -0.01204086],  # middle tip (vertex 444)
        [-0.06249190, 0.00242686, -0.04066927],  # ring tip (vertex 555)
        [-0.02368740, -0.00552932, -0.06978841],  # pinky tip (vertex 672)
    ],
    dtype=np.float64,
)
_MANO_MEAN_RIGHT_KEYPOINTS.setflags(write=False)

# Segment lengths as fractions of hand length (distal wrist crease to middle fingertip), from
# Buchholz, Armstrong & Goldstein (1992), "Anthropometric data for describing the kinematics of
# the human hand", Ergonomics 35(3):261-273, as tabulated in the AnyBody hand model. Per finger:
# (wrist→MCP — thumb: wrist→CMC, MCP→PIP, PIP→DIP, DIP→tip); thumb: (wrist→CMC, CMC→MCP, MCP→IP,
# IP→tip). The first column is consistent with the paper's MCP/CMC locations relative to the wrist
# crease (e.g. middle MCP at 0.446 × hand length along the third metacarpal).
BUCHHOLZ_SEGMENT_RATIOS: dict[str, tuple[float, float, float, float]] = {
    "thumb": (0.118, 0.251, 0.196, 0.158),
    "index": (0.463, 0.245, 0.143, 0.097),
    "middle": (0.446, 0.266, 0.170, 0.108),
    "ring": (0.421, 0.244, 0.165, 0.107),
    "pinky": (0.414, 0.204, 0.117, 0.093),
}

BETA0_SCALE_PER_UNIT = 0.06
"""Relative change of hand size per unit of β₀ in the skeleton path: ``scale = exp(0.06 β₀)``.

Derivation (an approximation, not MANO): MANO's betas are coefficients of a PCA shape space
learned from scans of many subjects, with roughly unit variance, and its first component carries
most of the overall size variation. Adult hand length varies with a coefficient of variation of
about 5–7 % (e.g. ≈ 18.9 cm men / 17.0 cm women with ≈ 1 cm standard deviations in anthropometric
surveys), so one standard deviation of β₀ ≈ 6 % of size. The **sign** (β₀ > 0 → larger hand) is an
assumption that could not be checked without the licence-restricted model file; the exact MANO
path (``MANO_MODEL_DIR``) is the reference, and measured bone lengths beat any betas.
"""


def _mirror_x(points: np.ndarray) -> np.ndarray:
    out = np.array(points, dtype=np.float64, copy=True)
    out[..., 0] *= -1.0
    return out


def _check_side(side: str) -> None:
    if side not in SIDES:
        raise UnknownNameError("hand side", side, SIDES)


def _coerce_bone_lengths(lengths: object) -> np.ndarray:
    """A ``(20,)`` float64 array in ``BONE_NAMES`` order from an array or a mapping.

    Mappings may be keyed by bone name (all 20 of ``BONE_NAMES``) or by finger name (the five
    ``FINGERS``, each with 4 lengths proximal to distal).
    """
    if isinstance(lengths, Mapping):
        keys = set(lengths)
        if keys == set(FINGERS):
            out = np.empty(len(BONE_NAMES))
            for f in FINGERS:
                per_finger = np.asarray(lengths[f], dtype=np.float64)
                if per_finger.shape != (4,):
                    raise ValidationError(
                        f"bone_lengths[{f!r}] must have shape (4,) (palm ray, proximal, middle, "
                        f"distal), got {per_finger.shape}",
                        field="bone_lengths",
                    )
                out[list(FINGER_BONES[f])] = per_finger
        elif keys == set(BONE_NAMES):
            out = np.array([float(lengths[n]) for n in BONE_NAMES])
        else:
            unknown = sorted(map(str, keys - set(BONE_NAMES) - set(FINGERS)))
            raise ValidationError(
                "bone_lengths mapping must be keyed by the 5 fingers "
                f"({', '.join(FINGERS)}) or by the 20 bone names ({', '.join(BONE_NAMES)}); "
                f"got keys {sorted(map(str, keys))}"
                + (f" (unknown: {unknown})" if unknown else ""),
                field="bone_lengths",
            )
    else:
        try:
            out = np.asarray(lengths, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValidationError(
                f"bone_lengths must be numeric, got {type(lengths).__name__}", field="bone_lengths"
            ) from exc
        if out.shape != (len(BONE_NAMES),):
            raise ValidationError(
                f"bone_lengths must have shape (20,) in BONE_NAMES order, got {out.shape}",
                field="bone_lengths",
            )
    if not np.isfinite(out).all() or (out <= 0).any():
        raise ValidationError(
            f"bone_lengths must be finite and > 0 [m], got {np.round(out, 5).tolist()}",
            field="bone_lengths",
        )
    return out


@dataclass(frozen=True, eq=False)
class HandSkeleton:
    """Rest pose of a MANO-compatible hand: 21 keypoints in the template frame of ``side``.

    Attributes:
        rest_keypoints: ``(21, 3)`` rest keypoints [m] in MANO21 order (16 MANO joints, then the
            thumb, index, middle, ring, pinky tips), in MANO's template frame (see module doc).
        side: ``"right"`` or ``"left"``; the left template is the right one mirrored in x.

    Posing (done by ``ManoLayer``): joint frames rotate about the rest joints exactly as in MANO;
    each tip is carried rigidly by its distal joint (``tip = p3 + R3 @ tip_offset``), so the tip
    lies along the distal bone's rest direction at the distal bone's length.

    >>> from dexcanvas_core import HandSkeleton
    >>> skeleton = HandSkeleton.default("right")
    >>> skeleton.rest_keypoints.shape, skeleton.side
    ((21, 3), 'right')
    """

    rest_keypoints: np.ndarray
    side: Side = "right"

    def __post_init__(self) -> None:
        _check_side(self.side)
        kp = np.array(self.rest_keypoints, dtype=np.float64, copy=True)
        if kp.shape != (len(MANO21), 3):
            raise ValidationError(
                f"rest_keypoints must have shape (21, 3), got {kp.shape}", field="rest_keypoints"
            )
        if not np.isfinite(kp).all():
            raise ValidationError("rest_keypoints has NaN or inf", field="rest_keypoints")
        kp.setflags(write=False)
        object.__setattr__(self, "rest_keypoints", kp)
        lengths = self.bone_lengths()
        if (lengths <= 1e-6).any():
            bad = [BONE_NAMES[i] for i in np.flatnonzero(lengths <= 1e-6)]
            raise ValidationError(
                f"rest_keypoints give zero-length bones: {', '.join(bad)}", field="rest_keypoints"
            )

    # -- constructors -------------------------------------------------------------------------

    @classmethod
    def default(cls, side: Side = "right") -> HandSkeleton:
        """MANO's mean hand (β = 0): joints and tips at MANO's mean template locations."""
        _check_side(side)
        kp = (
            _MANO_MEAN_RIGHT_KEYPOINTS if side == "right" else _mirror_x(_MANO_MEAN_RIGHT_KEYPOINTS)
        )
        return cls(kp, side)

    @classmethod
    def from_bone_lengths(
        cls,
        lengths: object,
        side: Side = "right",
        reference: HandSkeleton | None = None,
    ) -> HandSkeleton:
        """A skeleton with the given bone lengths and the bone directions of ``reference``.

        Args:
            lengths: ``(20,)`` lengths [m] in ``BONE_NAMES`` order (e.g. from
                :func:`measure_bone_lengths`), or a mapping by finger (4 lengths each) or by bone
                name.
            side: hand side of the result.
            reference: skeleton whose rest bone directions and wrist location are kept (mirrored
                if its side differs); default ``HandSkeleton.default(side)``.
        """
        _check_side(side)
        L = _coerce_bone_lengths(lengths)
        ref = cls.default(side) if reference is None else reference
        if ref.side != side:
            ref = ref.mirrored()
        directions = ref.bone_directions()
        kp = np.empty((len(MANO21), 3))
        kp[0] = ref.rest_keypoints[0]
        for i in range(1, len(MANO21)):  # parents precede children in MANO21
            kp[i] = kp[MANO21_PARENTS[i]] + L[i - 1] * directions[i - 1]
        return cls(kp, side)

    @classmethod
    def from_keypoints(
        cls, keypoints: object, side: Side = "right", order: str = "mano21"
    ) -> HandSkeleton:
        """A skeleton with the bone lengths measured from posed keypoints (see
        :func:`measure_bone_lengths`) and the default bone directions."""
        return cls.from_bone_lengths(measure_bone_lengths(keypoints, order=order), side=side)

    @classmethod
    def anthropometric(cls, hand_length: float, side: Side = "right") -> HandSkeleton:
        """Bone lengths from Buchholz et al. (1992) segment ratios × ``hand_length`` [m].

        Directions and the wrist location are MANO's mean hand. The ratios describe anatomical
        joint centres, which differ from MANO's regressed joints (MANO's MCP joints sit further
        distal: its wrist→middle1 is ≈ 0.095 m while its middle1→middle2 is only ≈ 0.032 m), so
        keypoints from this skeleton do not match MANO data as closely as ``default()``; use it
        for an anatomically proportioned hand of a given size (e.g. a simulated hand).
        """
        if not (isinstance(hand_length, int | float) and math.isfinite(hand_length)) or not (
            0.05 <= hand_length <= 0.35
        ):
            raise ValidationError(
                f"hand_length must be a length in metres within [0.05, 0.35], got {hand_length!r}",
                field="hand_length",
            )
        lengths = {f: [r * hand_length for r in BUCHHOLZ_SEGMENT_RATIOS[f]] for f in FINGERS}
        return cls.from_bone_lengths(lengths, side=side)

    # -- derived quantities -------------------------------------------------------------------

    @property
    def rest_joints(self) -> np.ndarray:
        """``(16, 3)`` rest locations of the MANO joints [m], template frame."""
        return self.rest_keypoints[: len(MANO_JOINTS)]

    @property
    def tip_offsets(self) -> np.ndarray:
        """``(5, 3)`` tip minus distal joint at rest [m], thumb…pinky, template frame."""
        return self.rest_keypoints[len(MANO_JOINTS) :] - self.rest_keypoints[list(TIP_PARENTS)]

    def bone_lengths(self) -> np.ndarray:
        """``(20,)`` bone lengths [m] in ``BONE_NAMES`` order."""
        kp = self.rest_keypoints
        return np.linalg.norm(kp[1:] - kp[list(MANO21_PARENTS[1:])], axis=-1)

    def bone_lengths_by_finger(self) -> dict[str, np.ndarray]:
        """Per finger (``FINGERS`` order) its 4 bone lengths [m]: palm ray, then the 3 distal
        segments (thumb: wrist→CMC, CMC→MCP, MCP→IP, IP→tip)."""
        L = self.bone_lengths()
        return {f: L[list(FINGER_BONES[f])] for f in FINGERS}

    def bone_directions(self) -> np.ndarray:
        """``(20, 3)`` unit vectors parent→child at rest, ``BONE_NAMES`` order."""
        kp = self.rest_keypoints
        d = kp[1:] - kp[list(MANO21_PARENTS[1:])]
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def mirrored(self) -> HandSkeleton:
        """The same hand for the other side (mirror across the template's x = 0 plane)."""
        return HandSkeleton(
            _mirror_x(self.rest_keypoints), "left" if self.side == "right" else "right"
        )

    def scaled(self, scale: float) -> HandSkeleton:
        """The hand scaled uniformly by ``scale`` about its wrist joint J0."""
        if not (math.isfinite(scale) and scale > 0):
            raise ValidationError(f"scale must be finite and > 0, got {scale!r}", field="scale")
        j0 = self.rest_keypoints[0]
        return HandSkeleton(j0 + scale * (self.rest_keypoints - j0), self.side)


def measure_bone_lengths(keypoints: object, order: str = "mano21") -> np.ndarray:
    """Bone lengths of a subject measured from posed hand keypoints.

    Args:
        keypoints: ``(T, 21, 3)`` or ``(21, 3)`` keypoints [m], e.g. DexCanvas ``mano_joint_pos``
            (any frame: lengths do not depend on the pose). Frames with NaN are skipped.
        order: keypoint order of the input, ``"mano21"`` (DexCanvas) or ``"openpose21"``.

    Returns:
        ``(20,)`` float64 bone lengths [m] in ``BONE_NAMES`` order: per bone, the median over the
        frames of the distance between the keypoint and its parent.
    """
    if hasattr(keypoints, "detach"):  # torch tensor, possibly on a GPU or with a graph
        keypoints = keypoints.detach().cpu().numpy()
    try:
        x = np.asarray(keypoints, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValidationError(
            f"keypoints must be numeric, got {type(keypoints).__name__}", field="keypoints"
        ) from exc
    if x.ndim == 2:
        x = x[None]
    if x.ndim != 3 or x.shape[1:] != (21, 3) or x.shape[0] == 0:
        raise ValidationError(
            f"keypoints must have shape (T, 21, 3) or (21, 3), got {np.shape(keypoints)}",
            field="keypoints",
        )
    if order != "mano21":
        x = convert_keypoints(x, order, "mano21")
    if np.isinf(x).any():
        raise ValidationError("keypoints has inf values", field="keypoints")
    d = np.linalg.norm(x[:, 1:] - x[:, list(MANO21_PARENTS[1:])], axis=-1)  # (T, 20)
    valid = np.isfinite(d).any(axis=0)
    if not valid.all():
        bad = [BONE_NAMES[i] for i in np.flatnonzero(~valid)]
        raise ValidationError(
            f"keypoints are NaN in every frame for bones {', '.join(bad)}", field="keypoints"
        )
    return np.nanmedian(d, axis=0)
