"""The simulated MANO hand: an actuated capsule hand built with ``mujoco.MjSpec``.

**Kinematic tree.** MANO's 16 joints, each a body placed at its rest joint location relative to
its parent (MANO's rest frames are all aligned with the template frame, so every body starts
with the identity orientation). The palm body's origin is the wrist joint J0.

**Degrees of freedom (a documented superset of the public 26-DoF ``urdf_dof`` layout).**

* wrist: three slides along world x, y, z (the position of J0 [m]) and three hinges about the
  axes of a per-scene base frame ``R_base`` (intrinsic X-Y-Z Euler angles, so the wrist
  orientation is ``R_base @ Rx(a) @ Ry(b) @ Rz(c)``; ``R_base`` is chosen near the
  demonstration's wrist orientations to keep the Euler angles far from gimbal lock);
* fingers: three hinges per finger joint about its anatomical axes (``flex``, ``abd``,
  ``twist`` of :mod:`dexcanvas_core.mano.limits`), chained in that order. Any MANO axis-angle of
  a joint is reached exactly by the intrinsic Euler decomposition of its rotation in the joint's
  anatomical frame; the only loss comes from the joint limits (reported as a residual by
  :func:`mano_to_joint_angles`). The 20 finger angles of ``urdf_dof`` are the subset
  ``{thumb_cmc_abd, thumb_cmc_flex, thumb_mcp, thumb_ip, {finger}_{mcp_abd, mcp_flex, pip,
  dip}}`` of these 45 (:data:`URDF26_FROM_HINGE`).

Every hinge and slide has a position actuator with a force limit: 51 actuators.

**Geometry.** One capsule per bone of :data:`dexcanvas_core.mano.hand_model.CAPSULES` (the same
collision model the demonstrations were generated and checked with), radii scaled with the
hand's size, density 1.1 g/cm³; fingertip sites at the five tip keypoints. Contact parts (the
DexCanvas ``joint_name`` values) are kept per geom in :attr:`SimHand.geom_part`.

**Gravity.** The hand's own weight is carried by the arm, not by the actuators: hand bodies
have ``gravcomp = 1``.

**Gains.** Position gains are chosen so that a finger pressing an object with a few degrees of
flexion beyond the surface produces human-scale grip forces (2–10 N at the fingertip), and
force limits bound them near adult maximum voluntary strength (e.g. index MCP ≈ 2 N·m; see
the table in :data:`FINGER_GAINS`). Gains 2.5× and 5× stiffer were tried on the 57 built-in
demonstrations (open-loop tracker): 32 and 31 successes against 30, within the spread that a
different demonstration seed gives, so the softer, more human-like gains stay.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import FINGERS, MANO21, MANO_JOINTS
from dexcanvas_core.mano.hand_model import CAPSULES
from dexcanvas_core.mano.limits import ANGLE_NAMES, FINGER_JOINTS, HIGH, LOW, joint_frames
from dexcanvas_core.mano.skeleton import HandSkeleton

WRIST_SLIDES: tuple[str, ...] = ("wrist_tx", "wrist_ty", "wrist_tz")
WRIST_HINGES: tuple[str, ...] = ("wrist_rx", "wrist_ry", "wrist_rz")
WRIST_JOINTS: tuple[str, ...] = WRIST_SLIDES + WRIST_HINGES
FINGER_HINGES: tuple[str, ...] = tuple(f"{j}_{a}" for j in FINGER_JOINTS for a in ANGLE_NAMES)
"""The 45 finger hinges, ``{mano_joint}_{flex|abd|twist}`` in MANO joint order."""
HAND_JOINTS: tuple[str, ...] = WRIST_JOINTS + FINGER_HINGES
"""All 51 hand joints (and actuators, same order)."""

URDF26_FROM_HINGE: dict[str, str] = {
    "thumb_cmc_abd": "thumb1_abd",
    "thumb_cmc_flex": "thumb1_flex",
    "thumb_mcp": "thumb2_flex",
    "thumb_ip": "thumb3_flex",
    **{
        f"{f}_{n}": f"{f}{lvl}_{a}"
        for f in ("index", "middle", "ring", "pinky")
        for n, lvl, a in (("mcp_abd", 1, "abd"), ("mcp_flex", 1, "flex"), ("pip", 2, "flex"),
                          ("dip", 3, "flex"))
    },
}  # fmt: skip
"""The 20 finger entries of the public 26-DoF ``urdf_dof`` and the hinge that carries each."""

LIMIT_MARGIN = np.deg2rad(10.0)
"""Hinge ranges are the anatomical limits widened by this margin [rad]: the limits bound
plausible human data, and MANO fits of real captures sit at them often."""

DENSITY = 1100.0
"""Hand tissue density [kg/m³] (soft tissue and bone, ≈ 1.1 × water)."""

# (kp [N·m/rad], force limit [N·m]) per joint level; thumb CMC and MCP are stronger.
# Limits are of the order of maximal isometric joint torques of adult fingers (index MCP
# flexion ≈ 2–3 N·m, PIP ≈ 1–1.5 N·m, DIP ≈ 0.5 N·m; thumb CMC ≈ 3–4 N·m): values as recalled
# from the finger-strength literature (e.g. Li et al. 2000, "Biomechanical analysis of finger
# flexor tendon forces"), order-of-magnitude estimates, not per-subject measurements.
FINGER_GAINS: dict[tuple[str, int], tuple[float, float]] = {
    ("finger", 1): (4.0, 2.0),
    ("finger", 2): (3.0, 1.2),
    ("finger", 3): (2.0, 0.6),
    ("thumb", 1): (6.0, 3.5),
    ("thumb", 2): (4.0, 2.0),
    ("thumb", 3): (2.5, 1.0),
}
FINGER_ARMATURE = 2e-4
"""Reflected inertia added to finger hinges [kg·m²]: keeps the stiff, very light phalanges
stable at millisecond time steps (tendons and muscles add inertia in a real hand too)."""
FINGER_DAMPING = 0.02
WRIST_POS_GAINS = (4000.0, 150.0)
"""Wrist slides: kp [N/m], force limit [N]."""
WRIST_ROT_GAINS = (150.0, 15.0)
"""Wrist hinges: kp [N·m/rad], force limit [N·m]."""
WRIST_ARMATURE = (0.2, 0.002)
"""Reflected mass [kg] of the slides and inertia [kg·m²] of the hinges (the arm behind)."""

HAND_CONTYPE = 2
HAND_CONAFFINITY = 0
"""Hand geoms collide with the object (whose conaffinity has bit 2) only: not with each other
(MANO fits interpenetrate neighbouring fingers) and not with the table."""


def _finger_of(joint: str) -> tuple[str, int]:
    return joint[:-1], int(joint[-1])


@dataclass
class SimHand:
    """The ids and tables of a compiled simulated hand (see the module docstring).

    Attributes:
        skeleton: the skeleton the hand was built from.
        scale: capsule radius scale (hand size relative to MANO's mean hand).
        R_base: ``(3, 3)`` base frame of the wrist hinges (world).
        qpos_adr, dof_adr: ``(51,)`` addresses of the hand joints (``HAND_JOINTS`` order).
        actuator: ``(51,)`` actuator ids, same order.
        geom_part: hand geom id → contact part name (``CONTACT_PARTS``).
        tip_sites: ``(5,)`` fingertip site ids (thumb … pinky).
        ctrl_low, ctrl_high: ``(51,)`` actuator control ranges (the joint ranges).
    """

    skeleton: HandSkeleton
    scale: float
    R_base: np.ndarray
    qpos_adr: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    dof_adr: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    actuator: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    geom_part: dict[int, str] = field(default_factory=dict)
    tip_sites: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    palm_body: int = -1
    ctrl_low: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ctrl_high: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def bind(self, model: mujoco.MjModel) -> SimHand:
        """Resolve ids in a compiled model that contains this hand."""

        def jid(name: str) -> int:
            return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)

        ids = np.array([jid(n) for n in HAND_JOINTS])
        if (ids < 0).any():
            raise ValidationError("model does not contain the simulated MANO hand")
        self.qpos_adr = model.jnt_qposadr[ids].astype(np.int64)
        self.dof_adr = model.jnt_dofadr[ids].astype(np.int64)
        self.actuator = np.array(
            [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in HAND_JOINTS]
        )
        self.ctrl_low = model.actuator_ctrlrange[self.actuator, 0].copy()
        self.ctrl_high = model.actuator_ctrlrange[self.actuator, 1].copy()
        self.geom_part = {}
        for g in range(model.ngeom):
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or ""
            if name.startswith("mano_"):
                cap = CAPSULES[_CAPSULE_BY_GEOM[name]]
                self.geom_part[g] = cap.part
        self.tip_sites = np.array(
            [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"mano_tip_{f}") for f in FINGERS]
        )
        self.palm_body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "mano_palm")
        return self


_CAPSULE_BY_GEOM = {f"mano_{c.name}": i for i, c in enumerate(CAPSULES)}


def skeleton_scale(skeleton: HandSkeleton) -> float:
    """Hand size relative to MANO's mean hand: ratio of summed bone lengths."""
    return float(skeleton.bone_lengths().sum() / HandSkeleton.default("right").bone_lengths().sum())


def add_hand(
    spec: mujoco.MjSpec,
    skeleton: HandSkeleton,
    *,
    R_base: np.ndarray | None = None,
    rgba: tuple[float, float, float, float] = (0.93, 0.75, 0.62, 1.0),
) -> SimHand:
    """Add the actuated MANO hand to ``spec`` (right hands only; see the module docstring)."""
    if skeleton.side != "right":
        raise ValidationError(
            "the simulated hand is built for right hands; mirror left-hand data first "
            "(HandSkeleton.mirrored / mirror_axis_angle)",
            field="side",
        )
    if spec.compiler.degree:
        raise ValidationError("add_hand needs a spec with compiler.degree = False (radians)")
    R_base = np.eye(3) if R_base is None else np.asarray(R_base, dtype=np.float64)
    scale = skeleton_scale(skeleton)
    kp = np.asarray(skeleton.rest_keypoints)
    F = np.asarray(joint_frames("right"))  # rows flex, abd, twist
    parents = (-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14)

    base = spec.worldbody.add_body(name="mano_base", gravcomp=1.0)
    _small_inertia(base)
    for name, axis in zip(WRIST_SLIDES, np.eye(3), strict=True):
        base.add_joint(
            name=name, type=mujoco.mjtJoint.mjJNT_SLIDE, axis=list(axis),
            armature=WRIST_ARMATURE[0], damping=0.0, range=[-2.0, 2.0], limited=True,
        )  # fmt: skip
    rot = base.add_body(
        name="mano_wrist_rot",
        quat=list(Rotation.from_matrix(R_base).as_quat(scalar_first=True)),
        gravcomp=1.0,
    )
    _small_inertia(rot)
    for name, axis in zip(WRIST_HINGES, np.eye(3), strict=True):
        rot.add_joint(
            name=name, type=mujoco.mjtJoint.mjJNT_HINGE, axis=list(axis),
            armature=WRIST_ARMATURE[1], range=[-np.pi, np.pi], limited=True,
        )  # fmt: skip
    # the palm: a massless frame; bodies of the tree hold the capsules (mass from density)
    bodies: dict[int, mujoco.MjsBody] = {0: rot.add_body(name="mano_palm", gravcomp=1.0)}
    for j in range(1, 16):
        parent = bodies[parents[j]]
        body = parent.add_body(
            name=f"mano_{MANO_JOINTS[j]}", pos=list(kp[j] - kp[parents[j]]), gravcomp=1.0
        )
        finger, level = _finger_of(MANO_JOINTS[j])
        for a, ang in enumerate(ANGLE_NAMES):
            k = j - 1
            body.add_joint(
                name=f"{MANO_JOINTS[j]}_{ang}", type=mujoco.mjtJoint.mjJNT_HINGE,
                axis=list(F[k, a]), range=[LOW[k, a] - LIMIT_MARGIN, HIGH[k, a] + LIMIT_MARGIN],
                limited=True, armature=FINGER_ARMATURE, damping=FINGER_DAMPING,
            )  # fmt: skip
        bodies[j] = body
    for c in CAPSULES:
        body = bodies[c.joint]
        origin = kp[c.joint]
        a, b = kp[c.a] - origin, kp[c.b] - origin
        r = c.radius * scale
        if c.tip:  # the distal capsule's cap is the fingertip: end one radius short of it
            u = (b - a) / np.linalg.norm(b - a)
            b = b - r * u
        g = body.add_geom(
            name=f"mano_{c.name}", type=mujoco.mjtGeom.mjGEOM_CAPSULE,
            fromto=[*a, *b], size=[r, 0, 0], density=DENSITY, rgba=list(rgba),
        )  # fmt: skip
        g.contype = HAND_CONTYPE
        g.conaffinity = HAND_CONAFFINITY
        g.condim = 4 if c.tip else 3
        g.friction = [1.0, 0.005, 0.0001]
    for f in FINGERS:
        tip = MANO21.index(f"{f}_tip")
        j = MANO_JOINTS.index(f"{f}3")
        bodies[j].add_site(name=f"mano_tip_{f}", pos=list(kp[tip] - kp[j]), size=[0.003, 0, 0])
    # actuators, HAND_JOINTS order
    for name in WRIST_SLIDES:
        _position_actuator(spec, name, *WRIST_POS_GAINS, ctrlrange=(-2.0, 2.0))
    for name in WRIST_HINGES:
        _position_actuator(spec, name, *WRIST_ROT_GAINS, ctrlrange=(-np.pi, np.pi))
    for j in range(1, 16):
        finger, level = _finger_of(MANO_JOINTS[j])
        kp_gain, limit = FINGER_GAINS[("thumb" if finger == "thumb" else "finger", level)]
        for a, ang in enumerate(ANGLE_NAMES):
            k = j - 1
            gain = kp_gain if ang == "flex" else 0.6 * kp_gain
            _position_actuator(
                spec, f"{MANO_JOINTS[j]}_{ang}", gain, limit,
                ctrlrange=(LOW[k, a] - LIMIT_MARGIN, HIGH[k, a] + LIMIT_MARGIN),
            )  # fmt: skip
    return SimHand(skeleton=skeleton, scale=scale, R_base=R_base)


def _small_inertia(body: mujoco.MjsBody) -> None:
    """The wrist's intermediate joint bodies: 10 g, a 2 cm sphere's inertia (the actuated
    wrist's real inertia is the palm's plus the joint armature)."""
    body.explicitinertial = True
    body.mass = 0.01
    body.inertia = [1.6e-6, 1.6e-6, 1.6e-6]


def _position_actuator(
    spec: mujoco.MjSpec, joint: str, kp: float, force_limit: float, ctrlrange: tuple[float, float]
) -> None:
    act = spec.add_actuator(name=joint, target=joint, trntype=mujoco.mjtTrn.mjTRN_JOINT)
    act.set_to_position(kp=kp, dampratio=1.0)
    act.ctrlrange = list(ctrlrange)
    act.ctrllimited = True
    act.forcerange = [-force_limit, force_limit]
    act.forcelimited = True


# -- pose conversion -------------------------------------------------------------------------


def mano_to_joint_angles(pose45: np.ndarray) -> np.ndarray:
    """``(..., 45)`` hinge angles [rad] (``FINGER_HINGES`` order) from MANO finger axis-angles.

    Exact intrinsic Euler decomposition of each joint's rotation in its anatomical frame; no
    limits applied (see :func:`clip_to_limits`).
    """
    p = np.asarray(pose45, dtype=np.float64)
    if p.shape[-1] != 45:
        raise ValidationError(f"pose must have shape (..., 45), got {p.shape}", field="hand_pose")
    lead = p.shape[:-1]
    F = np.asarray(joint_frames("right"))
    R = Rotation.from_rotvec(p.reshape(-1, 3)).as_matrix().reshape(-1, 15, 3, 3)
    R_anat = np.einsum("jab,njbc,jdc->njad", F, R, F)  # F R F^T per joint
    eul = Rotation.from_matrix(R_anat.reshape(-1, 3, 3)).as_euler("XYZ")
    return eul.reshape(*lead, 45)


def joint_angles_to_mano(angles: np.ndarray) -> np.ndarray:
    """Inverse of :func:`mano_to_joint_angles`: ``(..., 45)`` hinge angles → axis-angles."""
    a = np.asarray(angles, dtype=np.float64)
    if a.shape[-1] != 45:
        raise ValidationError(f"angles must have shape (..., 45), got {a.shape}", field="angles")
    lead = a.shape[:-1]
    F = np.asarray(joint_frames("right"))
    R_anat = Rotation.from_euler("XYZ", a.reshape(-1, 3)).as_matrix().reshape(-1, 15, 3, 3)
    R = np.einsum("jba,njbc,jcd->njad", F, R_anat, F)  # F^T R_anat F
    return Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec().reshape(*lead, 45)


HINGE_LOW = (LOW - LIMIT_MARGIN).reshape(45)
HINGE_HIGH = (HIGH + LIMIT_MARGIN).reshape(45)


def clip_to_limits(angles: np.ndarray) -> np.ndarray:
    """Hinge angles clipped to the simulated hand's ranges."""
    return np.clip(angles, HINGE_LOW, HINGE_HIGH)


def urdf_dof_26(wrist_pos: np.ndarray, wrist_euler: np.ndarray, hinges: np.ndarray) -> np.ndarray:
    """``(T, 26)`` public ``urdf_dof`` row from wrist position, world XYZ-Euler and hinges."""
    idx = [FINGER_HINGES.index(URDF26_FROM_HINGE[n]) for n in URDF26_FROM_HINGE]
    return np.concatenate([wrist_pos, wrist_euler, hinges[..., idx]], axis=-1)
