"""The MANO hand as the demonstration generator and the force pipeline use it: fast batched
kinematics and a capsule collision model.

Kinematics are those of :class:`~dexcanvas_core.mano.ManoLayer` on the skeleton path (same tree,
same axis-angle semantics, tested against it), re-implemented in batched numpy because the grasp
optimiser evaluates hundreds of hand configurations per step.

**Degrees of freedom.** The generator drives 22 anatomical angles (``DOF_NAMES``), read in the
frames of :mod:`dexcanvas_core.mano.limits` and turned into MANO axis-angles by
``pose_from_anatomical``: per finger MCP flexion and abduction, PIP and DIP flexion; for the thumb
CMC flexion, abduction and twist (opposition), MCP flexion and abduction, IP flexion. The other
anatomical components stay zero. The wrist is a rigid pose ``T_frame_wrist`` whose origin is
MANO's wrist joint J0 (so ``mano_global_pos = p_wrist - J0_rest`` and
``mano_global_rot_aa = rotvec(R_wrist)``).

**Collision model.** A capsule per bone (``CAPSULES``): three per finger along the MANO joints,
the distal one ending one radius short of the fingertip keypoint so that its cap is the fingertip;
the palm as five capsules (wrist → each finger's MCP joint, and across the MCP row) and the thenar
as a capsule wrist → thumb CMC. Radii at the default hand size are half segment thicknesses
(depths) of an adult hand: finger segments 6.8–9.5 mm, thumb 9.5–12 mm, palm 12–13 mm — the range
of finger/thumb joint breadths and depths of US Army hand anthropometry (Greiner 1991,
"Hand anthropometry of U.S. Army personnel", NATICK/TR-92/011: distal-joint breadths ≈ 15–20 mm,
thumb ≈ 20–23 mm, hand thickness at the metacarpals ≈ 25–30 mm; values as recalled, not re-read)
and the segment ellipsoids of Buchholz & Armstrong (1991, "An ellipsoidal representation of human
hand anthropometry", Human Factors 33(4)), whose depths are smaller than breadths. Radii scale with
the operator's hand size. Capsules are sampled every ≤ 4 mm along their axes; a distance to a
capsule is the distance to its axis samples minus the radius (at most 0.3 mm more than the
true capsule's).

**Pads.** A finger's *pad* is the volar (palm-side) surface of its distal capsule; the volar
direction of a segment is the direction its tip moves when the segment's joint flexes (template
``-y`` made perpendicular to the bone, rotated with the segment). The radial side (towards the
thumb, template ``+z``) is the index finger's contact side in lateral pinches.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from dexcanvas_core.checks import check_float
from dexcanvas_core.keypoints import FINGERS, MANO21, MANO_JOINTS
from dexcanvas_core.mano.limits import FINGER_JOINTS, HIGH, LOW, joint_frames
from dexcanvas_core.mano.skeleton import HandSkeleton

ANGLE_INDEX = {"flex": 0, "abd": 1, "twist": 2}

DOF_NAMES: tuple[str, ...] = (
    *(f"{f}{j}_{a}" for f in ("index", "middle", "ring", "pinky")
      for j, a in ((1, "flex"), (1, "abd"), (2, "flex"), (3, "flex"))),
    "thumb1_flex", "thumb1_abd", "thumb1_twist", "thumb2_flex", "thumb2_abd", "thumb3_flex",
)  # fmt: skip
"""The 22 driven anatomical angles [rad], ``{joint}_{flex|abd|twist}`` (MANO joint names)."""

N_DOF = len(DOF_NAMES)

_DOF_JOINT = np.array([FINGER_JOINTS.index(n.rsplit("_", 1)[0]) for n in DOF_NAMES])
_DOF_COMP = np.array([ANGLE_INDEX[n.rsplit("_", 1)[1]] for n in DOF_NAMES])

DOF_LOW = LOW[_DOF_JOINT, _DOF_COMP]
"""(22,) lower anatomical limits [rad] of the driven angles (``limits.LOW``)."""
DOF_HIGH = HIGH[_DOF_JOINT, _DOF_COMP]
"""(22,) upper anatomical limits [rad]."""

FINGER_DOF_INDEX: dict[str, tuple[int, ...]] = {
    f: tuple(i for i, n in enumerate(DOF_NAMES) if n.startswith(f)) for f in FINGERS
}
"""Indices into ``DOF_NAMES`` of each finger's angles."""


def dof_index(name: str) -> int:
    """Index of a driven angle by name (``"index2_flex"``)."""
    return DOF_NAMES.index(name)


@dataclass(frozen=True)
class Capsule:
    """One collision capsule between two MANO21 keypoints.

    ``part`` is the DexCanvas contact part name (``CONTACT_PARTS``): ``palm``,
    ``{finger}_{mcp|pip|dip}`` for the proximal, middle and distal phalanges, ``thumb_{cmc|mcp|ip}``
    for the thumb's metacarpal, proximal and distal phalanges. ``joint`` is the MANO joint whose
    frame carries the segment (0 = wrist). ``radius`` is at the default hand size [m].
    """

    name: str
    part: str
    a: int
    b: int
    joint: int
    radius: float
    tip: bool = False


def _kp(name: str) -> int:
    return MANO21.index(name)


def _joint(name: str) -> int:
    return MANO_JOINTS.index(name)


_FINGER_RADII = {  # proximal, middle, distal phalanx [m] (thumb: metacarpal, proximal, distal)
    "thumb": (0.0120, 0.0105, 0.0095),
    "index": (0.0095, 0.0085, 0.0080),
    "middle": (0.0095, 0.0088, 0.0080),
    "ring": (0.0090, 0.0082, 0.0076),
    "pinky": (0.0080, 0.0072, 0.0068),
}


def _capsules() -> tuple[Capsule, ...]:
    caps = [
        Capsule(f"palm_{f}", "palm", _kp("wrist"), _kp(f"{f}1"), 0, r)
        for f, r in (("index", 0.0125), ("middle", 0.0125), ("ring", 0.0125), ("pinky", 0.012))
    ]
    caps.append(Capsule("palm_knuckles", "palm", _kp("index1"), _kp("pinky1"), 0, 0.0115))
    caps.append(Capsule("palm_thenar", "palm", _kp("wrist"), _kp("thumb1"), 0, 0.013))
    for f in FINGERS:
        parts = ("cmc", "mcp", "ip") if f == "thumb" else ("mcp", "pip", "dip")
        chain = [f"{f}1", f"{f}2", f"{f}3", f"{f}_tip"]
        for k in range(3):
            caps.append(
                Capsule(
                    f"{f}_{parts[k]}",
                    f"{f}_{parts[k]}",
                    _kp(chain[k]),
                    _kp(chain[k + 1]),
                    _joint(chain[k]),
                    _FINGER_RADII[f][k],
                    tip=k == 2,
                )
            )
    return tuple(caps)


CAPSULES: tuple[Capsule, ...] = _capsules()
"""The hand's collision capsules (palm first, then thumb…pinky, proximal to distal)."""

CAPSULE_INDEX: dict[str, int] = {c.name: i for i, c in enumerate(CAPSULES)}

DISTAL_CAPSULE: dict[str, int] = {
    f: CAPSULE_INDEX[f"{f}_ip" if f == "thumb" else f"{f}_dip"] for f in FINGERS
}
"""Index into ``CAPSULES`` of each finger's distal segment (its pad)."""

SAMPLE_SPACING = 0.004
"""Largest spacing [m] of a capsule's axis samples: the distance to the sampled capsule exceeds
the true capsule's by at most ``r - sqrt(r² - (2 mm)²)`` (0.15–0.3 mm for these radii)."""

_LEVEL_JOINTS = [
    [_joint(f"{f}{lvl}") for f in ("index", "middle", "pinky", "ring", "thumb")]
    for lvl in (1, 2, 3)
]
_TIP_PARENTS = [_joint(f"{f}3") for f in FINGERS]


def rodrigues(aa: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)`` rotation matrices from axis-angles ``(..., 3)`` (exact near zero)."""
    th2 = np.sum(aa * aa, axis=-1)[..., None, None]
    small = th2 < 1e-10
    th = np.sqrt(np.where(small, 1.0, th2))
    a = np.where(small, 1.0 - th2 / 6.0, np.sin(th) / th)
    b = np.where(small, 0.5 - th2 / 24.0, (1.0 - np.cos(th)) / np.where(small, 1.0, th2))
    x, y, z = aa[..., 0], aa[..., 1], aa[..., 2]
    K = np.zeros((*aa.shape[:-1], 3, 3))
    K[..., 0, 1], K[..., 0, 2] = -z, y
    K[..., 1, 0], K[..., 1, 2] = z, -x
    K[..., 2, 0], K[..., 2, 1] = -y, x
    return np.eye(3) + a * K + b * (K @ K)


class HandModel:
    """Kinematics and collision capsules of one operator's right hand.

    Args:
        skeleton: the operator's ``HandSkeleton`` (right side).
        scale: hand size relative to the default skeleton (scales the capsule radii).

    >>> import numpy as np
    >>> from dexcanvas_core import HandModel, HandSkeleton
    >>> hand = HandModel(HandSkeleton.default("right"))
    >>> q = np.zeros((1, 22))  # the driven angles (DOF_NAMES) [rad]
    >>> kp, R_joint = hand.forward(q, np.eye(3)[None], np.zeros((1, 3)))
    >>> kp.shape, R_joint.shape, len(hand.capsule_radius)
    ((1, 21, 3), (1, 16, 3, 3), 21)
    """

    def __init__(self, skeleton: HandSkeleton, scale: float = 1.0):
        self.skeleton = skeleton
        self.scale = float(scale)
        kp = skeleton.rest_keypoints
        self.j0 = kp[0].copy()
        self.rest = kp - self.j0  # (21, 3) wrist frame at rest
        self.frames = np.asarray(joint_frames("right"))  # (15, 3, 3) rows flex, abd, twist
        self.parents = np.array([-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14])
        self.tip_offsets = kp[16:] - kp[_TIP_PARENTS]
        # capsule samples
        radii = np.array([c.radius for c in CAPSULES]) * self.scale
        self.capsule_radius = radii
        ia, ib, t, cap = [], [], [], []
        for i, c in enumerate(CAPSULES):
            L = float(np.linalg.norm(self.rest[c.b] - self.rest[c.a]))
            usable = L - radii[i] if c.tip else L
            n = max(3, int(np.ceil(usable / SAMPLE_SPACING)) + 1)
            fr = np.linspace(0.0, usable / L, n)
            ia += [c.a] * n
            ib += [c.b] * n
            t += list(fr)
            cap += [i] * n
        self.s_a = np.array(ia)
        self.s_b = np.array(ib)
        self.s_t = np.array(t)[:, None]
        self.s_cap = np.array(cap)
        self.s_r = radii[self.s_cap]
        self.s_joint = np.array([CAPSULES[c].joint for c in self.s_cap])
        self.cap_slices = {
            i: np.flatnonzero(self.s_cap == i) for i in range(len(CAPSULES))
        }  # sample indices per capsule
        # rest volar / radial directions per joint (template frame), perpendicular to the bone
        self.volar_rest = np.zeros((16, 3))
        self.radial_rest = np.zeros((16, 3))
        for c in CAPSULES:
            if c.joint == 0:
                continue
            u = self.rest[c.b] - self.rest[c.a]
            u /= np.linalg.norm(u)
            for vec, out in ((np.array([0.0, -1.0, 0.0]), self.volar_rest),
                             (np.array([0.0, 0.0, 1.0]), self.radial_rest)):  # fmt: skip
                v = vec - u * (u @ vec)
                out[c.joint] = v / np.linalg.norm(v)
        self.volar_rest[0] = (0.0, -1.0, 0.0)
        self.radial_rest[0] = (0.0, 0.0, 1.0)

    @property
    def num_samples(self) -> int:
        return self.s_a.shape[0]

    # -- angles -----------------------------------------------------------------------------

    @staticmethod
    def anatomical(q: np.ndarray) -> np.ndarray:
        """``(..., 15, 3)`` anatomical angles from the driven angles ``q (..., 22)``."""
        q = np.asarray(q, dtype=np.float64)
        out = np.zeros((*q.shape[:-1], 15, 3))
        out[..., _DOF_JOINT, _DOF_COMP] = q
        return out

    def pose45(self, q: np.ndarray) -> np.ndarray:
        """``(..., 45)`` MANO finger axis-angles [rad] from driven angles ``(..., 22)``."""
        ang = self.anatomical(q)
        r = np.einsum("jab,...ja->...jb", self.frames, ang)  # F^T a, as pose_from_anatomical
        return r.reshape((*ang.shape[:-2], 45))

    # -- kinematics -------------------------------------------------------------------------

    def forward(
        self, q: np.ndarray, R_wrist: np.ndarray, p_wrist: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Keypoints and joint orientations of posed hands.

        Args:
            q: ``(B, 22)`` driven angles [rad].
            R_wrist: ``(B, 3, 3)`` wrist orientation in the output frame.
            p_wrist: ``(B, 3)`` position of the wrist joint J0 in the output frame [m].

        Returns:
            ``kp (B, 21, 3)`` MANO21 keypoints [m] and ``R_joint (B, 16, 3, 3)`` orientation of
            every MANO joint frame, both in the output frame.
        """
        B = q.shape[0]
        aa = self.pose45(q).reshape(B, 15, 3)
        R_loc = rodrigues(aa)  # (B, 15, 3, 3) MANO joint order 1..15
        Rw = np.empty((B, 16, 3, 3))
        pw = np.empty((B, 16, 3))
        Rw[:, 0] = np.eye(3)
        pw[:, 0] = 0.0
        J = self.rest[:16]
        for level in _LEVEL_JOINTS:
            idx = np.array(level)
            par = self.parents[idx]
            Rp = Rw[:, par]
            Rw[:, idx] = Rp @ R_loc[:, idx - 1]
            pw[:, idx] = pw[:, par] + np.einsum("bjik,jk->bji", Rp, J[idx] - J[par])
        tips = pw[:, _TIP_PARENTS] + np.einsum(
            "bjik,jk->bji", Rw[:, _TIP_PARENTS], self.tip_offsets
        )
        kp_w = np.concatenate([pw, tips], axis=1)
        kp = np.einsum("bik,bjk->bji", R_wrist, kp_w) + p_wrist[:, None, :]
        R_joint = R_wrist[:, None] @ Rw
        return kp, R_joint

    def samples(self, kp: np.ndarray) -> np.ndarray:
        """``(B, S, 3)`` capsule axis samples from keypoints ``(B, 21, 3)``."""
        a = kp[:, self.s_a]
        return a + self.s_t * (kp[:, self.s_b] - a)

    def directions(self, R_joint: np.ndarray, joints: np.ndarray, side: str) -> np.ndarray:
        """``(B, K, 3)`` volar or radial unit directions of the segments carried by ``joints``."""
        rest = self.volar_rest if side == "volar" else self.radial_rest
        return np.einsum("bkij,kj->bki", R_joint[:, joints], rest[joints])


@lru_cache(maxsize=16)
def hand_model(scale: float) -> HandModel:
    """The (cached) hand model of a default skeleton scaled by ``scale`` about its wrist.

    >>> from dexcanvas_core import hand_model
    >>> hand_model(1.07) is hand_model(1.07), hand_model(1.07).scale
    (True, 1.07)
    """
    check_float("scale", scale, positive=True)
    return HandModel(HandSkeleton.default("right").scaled(scale), scale)
