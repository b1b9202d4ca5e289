"""The description of one robot hand and the common MuJoCo model building.

A :class:`HandModel` says where a hand's model comes from (a PyPI package or ``robots/<hand>/``),
how its base frame sits relative to MANO's wrist frame, which robot finger each human finger drives,
where its keypoint sites are, which joints are coupled, and how its joints are actuated. From that,
:meth:`HandModel.build_spec` builds one MuJoCo model (an ``mujoco.MjSpec``) with the same layout for
every hand:

``world → wrist`` (6-DoF floating base: slides ``wrist_tx/ty/tz`` then hinges ``wrist_rx/ry/rz``)
``→ frame T_mano_robot_wrist → <the hand's own root body> → …``

**The ``wrist`` body frame is MANO's wrist frame** (right hand: fingers along -x, palm normal -y,
thumb side +z; origin at MANO's wrist joint J0). The hand's own root frame is attached at
``T_mano_robot_wrist``, chosen per hand so that the robot's fingers point along -x, its palm faces
-y and its thumb is on the +z side, with the robot's wrist point (its mount, at the proximal end of
the palm) on J0. A human wrist pose therefore maps to the floating base directly::

    q_wrist = (p_world_J0, euler_XYZ(R_world_mano))  # see wrist_qpos_from_mano()

and the robot's own base pose is ``T_world_robot = T_world_mano @ T_mano_robot_wrist``. The three
hinges compose as intrinsic X-Y-Z rotations (MuJoCo applies the joints of one body in order, each
about its axis in the already-rotated frame), i.e. ``R = Rx(rx) @ Ry(ry) @ Rz(rz)``.

Everything else (Pinocchio model, QP objectives, re-simulation) is derived from the compiled
``mujoco.MjModel``: joints, sites ``<finger>_tip_site`` and ``<finger>_<joint>_site``, tendon and
equality couplings, actuators named ``<joint>_act``, collision geoms named ``*_collision``.

Physical conventions (``../shared/DESIGN.md``, "Physics conventions"): ``implicitfast``
integrator, elliptic friction cones, ``impratio`` 10, timestep 2 ms, condim 4 on fingertip geoms
and 3 elsewhere. The hand's weight is carried by gravity compensation (``gravcomp`` 1 on every hand
body): the arm that would hold the hand is not modelled, and the fingers' position servos are not
asked to hold their own weight.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from dexcanvas_core.keypoints import FINGERS, MANO21
from retarget.errors import HandModelError

log = logging.getLogger(__name__)

WRIST_BODY = "wrist"
WRIST_SITE = "wrist_site"
WRIST_JOINTS: tuple[str, ...] = (
    "wrist_tx",
    "wrist_ty",
    "wrist_tz",
    "wrist_rx",
    "wrist_ry",
    "wrist_rz",
)
"""The 6 floating-wrist joints (3 slides, then 3 hinges), first in ``qpos``/``qvel``/``ctrl``."""

HUMAN_FINGERS: tuple[str, ...] = FINGERS
"""thumb, index, middle, ring, pinky."""

_HUMAN_JOINT_LABELS = {
    # MANO21 joint keypoints per finger: (MANO name suffix, anatomical label of the robot site)
    "thumb": (("1", "cmc"), ("2", "mcp"), ("3", "ip")),
    "index": (("1", "mcp"), ("2", "pip"), ("3", "dip")),
    "middle": (("1", "mcp"), ("2", "pip"), ("3", "dip")),
    "ring": (("1", "mcp"), ("2", "pip"), ("3", "dip")),
    "pinky": (("1", "mcp"), ("2", "pip"), ("3", "dip")),
}

# --- simulation options (../shared/DESIGN.md "Physics conventions") ---
TIMESTEP = 0.002  # [s]; DESIGN: timestep <= 2.5 ms
IMPRATIO = 10.0  # DESIGN: elliptic cones with impratio ~ 10


@dataclass(frozen=True)
class ContactParams:
    """Contact parameters given to every hand collision geom.

    ``friction`` (sliding, torsional [m], rolling [m]), ``solref``, ``solimp`` are MuJoCo's
    defaults (MuJoCo XML reference, ``geom``); condim 4 on fingertip geoms (torsional friction
    for pinches) and 3 elsewhere as in ../shared/DESIGN.md.
    """

    friction: tuple[float, float, float] = (1.0, 0.005, 0.0001)
    solref: tuple[float, float] = (0.02, 1.0)
    solimp: tuple[float, float, float, float, float] = (0.9, 0.95, 0.001, 0.5, 2.0)
    condim: int = 3
    tip_condim: int = 4


@dataclass(frozen=True)
class WristGains:
    """Gains and limits of the floating wrist: what the arm that would carry the hand can do.

    Design values of an arm-like carrier, not any robot arm's specification. The models
    :meth:`HandModel.build_spec` builds drive the six wrist joints with MuJoCo position servos
    of these gains (critically damped, force range ± ``force_slide`` / ``torque_hinge`` per
    joint); the re-simulation replaces them with its wrist driver (:mod:`retarget.wrist_drive`):
    by default a computed-torque controller that feeds the commanded motion forward, with
    ``kp_slide`` / ``kp_hinge`` as its feedback stiffness, ``dampratio`` its damping ratio,
    and ``force_slide`` (the norm of the force on the wrist) and ``torque_hinge`` (each hinge's
    torque) as its limits.

    Both are stable at the 2 ms timestep (``sqrt(kp / (m or I + armature)) · timestep`` well
    below 1 for every hand here) and sit on a held target (the hand's weight is compensated).
    Moving, a critically damped servo trails a target moving at speed ``v`` by about
    ``2 v / ω_n`` (``ω_n = sqrt(kp / m)``, ``m`` the hand's mass: 4 cm at 1 m/s for a 0.9 kg
    hand); the computed-torque driver follows it (benchmarks/wrist_tracking.py).
    """

    kp_slide: float = 2000.0  # [N/m]
    force_slide: float = 200.0  # [N]
    kp_hinge: float = 100.0  # [N·m/rad]
    torque_hinge: float = 20.0  # [N·m]
    dampratio: float = 1.0  # critical damping of each servo (MuJoCo position ``dampratio``)
    armature_slide: float = 0.0  # [kg]
    armature_hinge: float = 0.005  # [kg·m^2] reflected inertia of the virtual arm's wrist
    range_slide: float = 2.0  # [m] ± target range
    range_hinge: float = 2 * np.pi  # [rad] ± target range


@dataclass(frozen=True)
class ModelSource:
    """Where a hand's model comes from (shown by ``retarget hands``)."""

    kind: Literal["package", "robots"]
    """``package``: a file inside an installed PyPI package; ``robots``: ``robots/<hand>/``."""
    location: str
    """PyPI distribution and path inside it, or the ``robots/`` file."""
    licence: str
    upstream: str
    """Where the model (or the kinematics it was authored from) was published."""

    @property
    def short(self) -> str:
        """The package (or ``robots/<hand>``) alone, for tables."""
        head = self.location.split(":")[0]
        return head if self.kind == "package" else "/".join(self.location.split("/")[:2])

    @property
    def licence_short(self) -> str:
        return self.licence.split(" (")[0].split(";")[0]


@dataclass(frozen=True)
class SitePlacement:
    """A site on ``body`` at ``pos`` [m] in the body frame (source model names)."""

    body: str
    pos: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class ActuatorSpec:
    """A position servo on one joint (named ``<joint>_act``).

    ``kp`` [N·m/rad or N/m], ``kv`` [N·m·s/rad] (0: no actuator damping), ``forcerange`` [N·m]
    (None: unlimited), ``ctrlrange`` [rad] (None: the joint range). ``source`` names where the
    numbers come from.
    """

    joint: str
    kp: float
    kv: float = 0.0
    forcerange: tuple[float, float] | None = None
    ctrlrange: tuple[float, float] | None = None
    source: str = ""


@dataclass(frozen=True)
class JointCoupling:
    """``q[follower] = offset + multiplier * q[leader]`` (a mimic joint / linkage).

    Added to the model as a MuJoCo joint equality constraint named ``<follower>_coupling``.
    """

    follower: str
    leader: str
    multiplier: float
    offset: float = 0.0
    source: str = ""


@dataclass(frozen=True)
class WristAlignment:
    """How the robot's root frame maps onto MANO's wrist frame.

    ``distal`` and ``radial`` are unit vectors in the robot's root-body frame: the direction its
    fingers point (wrist → middle fingertip, fingers open) and the direction of its thumb side.
    ``wrist_point`` [m] is the robot's wrist (its mount at the proximal end of the palm) in the
    same frame. The palm normal (volar side) is ``radial × distal`` for a right hand.
    """

    distal: tuple[float, float, float]
    radial: tuple[float, float, float]
    wrist_point: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def R_mano_robot(self) -> np.ndarray:
        """(3, 3) rotation taking robot-root vectors into MANO's wrist frame."""
        d = np.asarray(self.distal, float)
        r = np.asarray(self.radial, float)
        d = d / np.linalg.norm(d)
        r = r - d * (r @ d)  # Gram–Schmidt: radial ⟂ distal
        r = r / np.linalg.norm(r)
        v = np.cross(r, d)  # volar
        robot = np.column_stack([d, v, r])
        mano = np.column_stack([[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])
        return mano @ robot.T

    @property
    def T_mano_robot(self) -> np.ndarray:
        """(4, 4) pose of the robot's root frame in MANO's wrist frame."""
        T = np.eye(4)
        T[:3, :3] = self.R_mano_robot
        T[:3, 3] = -T[:3, :3] @ np.asarray(self.wrist_point, float)
        return T


@dataclass(frozen=True)
class WristOffset:
    """Where the robot's wrist should be, relative to the scaled human wrist, for its fingers to
    land on the human's: the robot wrist site's pose in MANO's wrist frame.

    :class:`WristAlignment` puts MANO's wrist frame on the robot by the robot's own kinematics
    (finger direction, thumb side, mount point), which fixes the frames but not the pose a grasp
    needs: a hand whose fingers curl differently from a human's (one motor per finger on Inspire
    and Ability) reaches the human's fingertips only with its wrist flexed and moved. The
    retargeter (``RetargetConfig.wrist.use_offset``) aims the wrist at the human wrist pose
    composed with this offset
    (``R* = R_h exp(rotvec)``, ``p* = p_h + R_h translation``). Measured, not designed:
    ``retarget calibrate-wrist --hand NAME`` (:mod:`retarget.calibration`) prints it.
    """

    rotvec: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """[rad] rotation vector in MANO's wrist frame."""
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """[m] in MANO's wrist frame, at the robot's size (after ``HandModel.scale``)."""
    source: str = ""
    """How it was measured (command, demonstrations)."""

    def __post_init__(self) -> None:
        for name in ("rotvec", "translation"):
            v = np.asarray(getattr(self, name), float)
            if v.shape != (3,) or not np.isfinite(v).all():
                raise HandModelError(f"WristOffset.{name} must be 3 finite numbers, got {v}")

    @property
    def R(self) -> np.ndarray:
        """(3, 3) the rotation of ``rotvec``."""
        from dexcanvas_core.rotations import aa_to_matrix

        return aa_to_matrix(np.asarray(self.rotvec, float))

    def apply(self, R_world_mano: np.ndarray, p_world_wrist: np.ndarray):
        """The robot wrist targets ``(R (..., 3, 3), p (..., 3))`` for human wrist poses."""
        R_h = np.asarray(R_world_mano, float)
        p = np.asarray(p_world_wrist, float) + R_h @ np.asarray(self.translation, float)
        return R_h @ self.R, p

    def human_wrist(self, R_world_robot: np.ndarray, p_world_robot: np.ndarray):
        """The inverse of :meth:`apply`: the human wrist poses ``(R, p)`` whose robot wrist
        targets are the given poses."""
        R_h = np.asarray(R_world_robot, float) @ self.R.T
        p = np.asarray(p_world_robot, float) - R_h @ np.asarray(self.translation, float)
        return R_h, p


def _quat_wxyz(R: np.ndarray) -> np.ndarray:
    import mujoco

    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R, dtype=float).reshape(9))
    return q


@dataclass(frozen=True, eq=False)
class HandModel:
    """One robot hand: model source, frames, human↔robot correspondence, couplings, gains.

    Instances are immutable descriptions; :meth:`build_spec` returns a fresh ``mujoco.MjSpec``
    each call and :meth:`compile` a cached ``mujoco.MjModel`` (treat it as read-only; build your
    own from :meth:`build_spec` to change it). Hand modules create one instance named ``HAND``.
    """

    name: str
    description: str
    source: ModelSource
    loader: Callable[[], object] = field(repr=False)
    """Returns a fresh ``mujoco.MjSpec`` that contains ``root_body`` (the source model)."""
    root_body: str
    fingers: Mapping[str, str | None]
    """Human finger (thumb…pinky) → robot finger name, or None when the robot has no such finger."""
    tip_sites: Mapping[str, SitePlacement | None]
    """Robot finger → where its ``<finger>_tip_site`` goes (None: the source model has it)."""
    joint_sites: Mapping[str, SitePlacement]
    """MANO21 joint keypoint (e.g. ``index1``) → placement of the robot's matching site."""
    wrist: WristAlignment
    actuators: tuple[ActuatorSpec, ...]
    couplings: tuple[JointCoupling, ...] = ()
    """Couplings added here (those already in the source model are kept as they are)."""
    coupling_notes: str = ""
    default_posture: Mapping[str, float] = field(default_factory=dict)
    """Open-hand posture [rad or m] of the finger joints (joints not listed: 0 or their range)."""
    joint_armature: float | None = None
    """If set, the armature [kg·m^2] of every finger joint (overrides the source)."""
    joint_damping: float | None = None
    """If set, the passive damping [N·m·s/rad] of every finger joint (overrides the source)."""
    joint_frictionloss: float | None = None
    """If set, the dry friction [N·m] of every finger joint (overrides the source)."""
    joint_ranges: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    """Joint range overrides [rad] (e.g. where a published range is narrower than the source)."""
    contact: ContactParams = ContactParams()
    wrist_gains: WristGains = WristGains()
    wrist_offset: WristOffset | None = None
    """The wrist target's offset from the human wrist (:class:`WristOffset`); None: none."""
    joint_limit_margin: float = 0.0
    """How far [rad or m] the retargeting's kinematic solution keeps this hand's finger joints
    inside their ranges unless ``RetargetConfig.joint_limits.margin`` says otherwise (for a hand
    whose fingers press badly from a limit; see there)."""
    wrist_weight: float = 1.0
    """Factor on the retargeting's wrist-pose weights (``RetargetConfig.wrist``'s weights) for
    this hand; 0: the wrist is placed by the fingertips, the contacts and
    the smoothness term alone. For a hand whose wrist the human wrist pose places badly even
    with its calibrated offset (the Panda gripper has none: no one offset describes it;
    ``retarget calibrate-wrist``)."""
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        def bad(msg: str):
            raise HandModelError(f"hand {self.name!r}: {msg}")

        if set(self.fingers) != set(HUMAN_FINGERS):
            bad(f"fingers must map exactly {', '.join(HUMAN_FINGERS)}, got {sorted(self.fingers)}")
        for human, robot in self.fingers.items():
            if robot is not None and robot not in self.tip_sites:
                bad(f"finger {human!r} maps to {robot!r}, which has no entry in tip_sites")
        if self.fingers["thumb"] is None:
            bad("the thumb must drive a robot finger")
        joints = {f"{f}{i}" for f in HUMAN_FINGERS for i in "123"}
        for kp in self.joint_sites:
            if kp not in joints:
                bad(f"joint_sites key {kp!r} is not a MANO21 joint keypoint ({sorted(joints)})")
            self._joint_site_name(kp)  # raises for an unmapped finger
        if not (np.isfinite(self.joint_limit_margin) and self.joint_limit_margin >= 0):
            bad(f"joint_limit_margin must be finite and >= 0, got {self.joint_limit_margin}")
        if not (np.isfinite(self.wrist_weight) and self.wrist_weight >= 0):
            bad(f"wrist_weight must be finite and >= 0, got {self.wrist_weight}")
        names = [a.joint for a in self.actuators]
        if len(set(names)) != len(names):
            bad("two actuators on the same joint")

    # ------------------------------------------------------------------ correspondence
    @property
    def robot_fingers(self) -> tuple[str, ...]:
        """Robot finger names, in the order of ``tip_sites``."""
        return tuple(self.tip_sites)

    @property
    def mapped_human_fingers(self) -> tuple[str, ...]:
        """The human fingers this hand maps, thumb…pinky order: the retargeter's fingertip
        targets, and the columns of a force-matched run's ``human_force`` / ``robot_force``."""
        return tuple(f for f in FINGERS if self.fingers.get(f) is not None)

    @property
    def robot_to_human(self) -> dict[str, str]:
        """Robot finger → the first human finger (thumb…pinky order) mapped to it (a gripper's
        finger driven by index and middle: index)."""
        out: dict[str, str] = {}
        for human in FINGERS:
            robot = self.fingers.get(human)
            if robot is not None and robot not in out:
                out[robot] = human
        return out

    @property
    def tip_site_names(self) -> dict[str, str]:
        """Robot finger → its fingertip site name."""
        return {f: f"{f}_tip_site" for f in self.tip_sites}

    @property
    def keypoint_map(self) -> dict[str, str]:
        """MANO21 keypoint name → robot site name, for every keypoint the robot can match.

        Always the wrist and the tip of every mapped human finger; MCP/PIP/DIP (thumb CMC/MCP/IP)
        where the robot has a matching joint.
        """
        out = {"wrist": WRIST_SITE}
        for human in HUMAN_FINGERS:
            robot = self.fingers.get(human)
            if robot is not None:
                out[f"{human}_tip"] = f"{robot}_tip_site"
        for kp in self.joint_sites:
            out[kp] = self._joint_site_name(kp)
        return {k: out[k] for k in MANO21 if k in out}

    def _joint_site_name(self, keypoint: str) -> str:
        human = keypoint.rstrip("123")
        robot = self.fingers.get(human)
        if robot is None:
            raise HandModelError(f"hand {self.name!r}: keypoint {keypoint!r} on an unmapped finger")
        label = dict(_HUMAN_JOINT_LABELS[human])[keypoint[len(human) :]]
        return f"{robot}_{label}_site"

    @property
    def T_mano_robot_wrist(self) -> np.ndarray:
        """(4, 4) pose of the robot's root frame in MANO's wrist frame (see module docstring)."""
        return self.wrist.T_mano_robot

    # ------------------------------------------------------------------ model building
    def build_spec(self, *, self_collision: bool = False):
        """A new ``mujoco.MjSpec``: floating wrist + the hand, sites, couplings, actuators.

        ``self_collision``: let the hand's collision geoms touch each other (off by default;
        hand–object contacts are always on). Collision geoms use ``contype`` 2 and
        ``conaffinity`` 1, so they touch any geom with the default ``contype``/``conaffinity``
        of 1 but not each other; with ``self_collision`` both are 3, the source's explicit
        contact pairs are kept, and the body pairs already touching at the open posture (palm
        and finger bases) are excluded.
        """
        import mujoco

        try:
            src = self.loader()
        except HandModelError:
            raise
        except Exception as e:  # a missing package file, a parse error in a third-party model
            raise HandModelError(
                f"hand {self.name!r}: cannot load its model from {self.source.location}: {e}"
            ) from e
        _prepare_source(src)
        root = src.body(self.root_body)
        if root is None:
            raise HandModelError(f"hand {self.name!r}: no body {self.root_body!r} in its model")
        root.pos = [0.0, 0.0, 0.0]
        root.quat = [1.0, 0.0, 0.0, 0.0]

        spec = mujoco.MjSpec()
        spec.modelname = f"{self.name}_right"
        spec.compiler.degree = False
        spec.option.timestep = TIMESTEP
        spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
        spec.option.impratio = IMPRATIO
        for attr in ("iterations", "ls_iterations", "tolerance"):
            setattr(src.option, attr, getattr(spec.option, attr))

        # 1 g, 1e-7 kg·m^2: negligible next to any hand, but keeps the floating base valid when
        # the hand's root body has joints of its own (Shadow's WRJ1).
        wrist = spec.worldbody.add_body(
            name=WRIST_BODY, mass=1e-3, inertia=[1e-7, 1e-7, 1e-7], explicitinertial=True
        )
        g = self.wrist_gains
        for i, jn in enumerate(WRIST_JOINTS):
            axis = np.eye(3)[i % 3]
            slide = i < 3
            wrist.add_joint(
                name=jn,
                type=mujoco.mjtJoint.mjJNT_SLIDE if slide else mujoco.mjtJoint.mjJNT_HINGE,
                axis=axis,
                armature=g.armature_slide if slide else g.armature_hinge,
                range=[-g.range_slide, g.range_slide] if slide else [-g.range_hinge, g.range_hinge],
                limited=mujoco.mjtLimited.mjLIMITED_FALSE,
            )
        wrist.add_site(name=WRIST_SITE, size=[0.006, 0.006, 0.006], rgba=[1, 0, 0, 1], group=4)
        T = self.T_mano_robot_wrist
        frame = wrist.add_frame(pos=T[:3, 3], quat=_quat_wxyz(T[:3, :3]))
        _attach_keeping_names(frame, root)
        self._finish(spec, self_collision=self_collision)
        # The copy forgets the attachment: compiling it does not repeat MuJoCo's notice that an
        # empty-prefix attachment happened (names are unique here by construction).
        spec = spec.copy()
        if self_collision:
            self._exclude_resting_contacts(spec)
        return spec

    def _finish(self, spec, *, self_collision: bool) -> None:
        import mujoco

        bodies = {b.name: b for b in spec.bodies if b.name}
        # --- sites ---
        for f, place in self.tip_sites.items():
            name = f"{f}_tip_site"
            if place is None:
                if spec.site(name) is None:
                    raise HandModelError(f"hand {self.name!r}: model has no site {name!r}")
                continue
            self._add_site(spec, bodies, name, place, rgba=(0, 1, 0, 1))
        for kp, place in self.joint_sites.items():
            self._add_site(spec, bodies, self._joint_site_name(kp), place, rgba=(0, 0, 1, 1))

        # --- joints ---
        finger_joints = [j for j in spec.joints if j.name not in WRIST_JOINTS]
        names = {j.name for j in finger_joints}
        for jn, rng in self.joint_ranges.items():
            if jn not in names:
                raise HandModelError(f"hand {self.name!r}: joint_ranges names unknown {jn!r}")
            spec.joint(jn).range = list(rng)
            spec.joint(jn).limited = mujoco.mjtLimited.mjLIMITED_TRUE
        for j in finger_joints:
            if self.joint_armature is not None:
                j.armature = self.joint_armature
            if self.joint_damping is not None:
                d = np.atleast_1d(np.array(j.damping, dtype=float))
                d[0] = self.joint_damping
                j.damping = d if d.size > 1 else float(d[0])
            if self.joint_frictionloss is not None:
                j.frictionloss = self.joint_frictionloss

        # --- couplings ---
        for c in self.couplings:
            for jn in (c.follower, c.leader):
                if jn not in names:
                    raise HandModelError(f"hand {self.name!r}: coupling names unknown joint {jn!r}")
            eq = spec.add_equality(
                name=f"{c.follower}_coupling",
                type=mujoco.mjtEq.mjEQ_JOINT,
                name1=c.follower,
                name2=c.leader,
            )
            data = np.zeros(len(eq.data))
            data[:2] = (c.offset, c.multiplier)  # polycoef: follower = c0 + c1 * leader
            eq.data = data
            eq.solref = [0.005, 1.0]  # stiffer than the default 0.02 s: a linkage, not a spring

        # --- collision geoms, contact parameters ---
        tip_bodies = set()
        for f, place in self.tip_sites.items():
            site = spec.site(f"{f}_tip_site")
            tip_bodies.add(site.parent.name if place is None else place.body)
        cp = self.contact
        bit = 3 if self_collision else 2
        renamed: dict[str, str] = {}
        per_body: dict[str, int] = {}
        for geom in spec.geoms:
            body = geom.parent.name
            if geom.contype == 0 and geom.conaffinity == 0:
                geom.group = 2 if geom.group in (0, 1) else geom.group  # visual
                continue
            geom.contype = bit
            geom.conaffinity = 1 | (2 if self_collision else 0)
            geom.group = 3
            geom.friction = list(cp.friction)
            geom.solref = list(cp.solref)
            geom.solimp = list(cp.solimp)
            geom.condim = cp.tip_condim if body in tip_bodies else cp.condim
            if not geom.name.endswith("_collision"):
                k = per_body.get(body, 0)
                per_body[body] = k + 1
                new = f"{body}_collision" if k == 0 else f"{body}_collision_{k}"
                while spec.geom(new) is not None:
                    k += 1
                    per_body[body] = k + 1
                    new = f"{body}_collision_{k}"
                if geom.name:
                    renamed[geom.name] = new
                geom.name = new
        for pair in list(spec.pairs):
            if not self_collision:
                spec.delete(pair)
                continue
            pair.geomname1 = renamed.get(pair.geomname1, pair.geomname1)
            pair.geomname2 = renamed.get(pair.geomname2, pair.geomname2)

        # --- gravity compensation (the unmodelled arm carries the hand) ---
        for b in spec.bodies:
            if b.name:
                b.gravcomp = 1.0

        # --- actuators: the wrist, then the hand's ---
        g = self.wrist_gains
        for i, jn in enumerate(WRIST_JOINTS):
            slide = i < 3
            act = spec.add_actuator(name=f"{jn}_act", target=jn)
            act.trntype = mujoco.mjtTrn.mjTRN_JOINT
            act.set_to_position(kp=g.kp_slide if slide else g.kp_hinge, dampratio=g.dampratio)
            lim = g.force_slide if slide else g.torque_hinge
            act.forcerange = [-lim, lim]
            act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
            r = g.range_slide if slide else g.range_hinge
            act.ctrlrange = [-r, r]
            act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        for a in self.actuators:
            j = spec.joint(a.joint)
            if j is None:
                raise HandModelError(f"hand {self.name!r}: actuator on unknown joint {a.joint!r}")
            act = spec.add_actuator(name=f"{a.joint}_act", target=a.joint)
            act.trntype = mujoco.mjtTrn.mjTRN_JOINT
            act.set_to_position(kp=a.kp, kv=a.kv if a.kv > 0 else -1)
            rng = a.ctrlrange if a.ctrlrange is not None else tuple(j.range)
            act.ctrlrange = list(rng)
            act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
            if a.forcerange is not None:
                act.forcerange = list(a.forcerange)
                act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE

    def _exclude_resting_contacts(self, spec) -> None:
        """Exclude the body pairs that touch at the open posture (palm vs finger bases …)."""
        import mujoco

        m = spec.compile()
        d = mujoco.MjData(m)
        d.qpos[:] = self.default_qpos(m)
        mujoco.mj_forward(m, d)
        seen: set[tuple[str, str]] = set()
        pairs_in_contact: set[str] = set()
        for i in range(d.ncon):
            c = d.contact[i]
            b1, b2 = (m.body(m.geom_bodyid[g]).name for g in c.geom)
            key = (min(b1, b2), max(b1, b2))
            if key not in seen:
                seen.add(key)
                spec.add_exclude(bodyname1=key[0], bodyname2=key[1])
            pairs_in_contact.add(f"{m.geom(c.geom[0]).name}/{m.geom(c.geom[1]).name}")
        for pair in list(spec.pairs):
            names = {f"{pair.geomname1}/{pair.geomname2}", f"{pair.geomname2}/{pair.geomname1}"}
            if names & pairs_in_contact:
                spec.delete(pair)

    @staticmethod
    def _add_site(spec, bodies, name: str, place: SitePlacement, rgba) -> None:
        body = bodies.get(place.body)
        if body is None:
            raise HandModelError(f"site {name!r}: no body {place.body!r} in the model")
        if spec.site(name) is not None:
            raise HandModelError(f"site {name!r} already exists in the model")
        body.add_site(name=name, pos=list(place.pos), size=[0.004, 0.004, 0.004], rgba=list(rgba),
                      group=4)  # fmt: skip

    def compile(self):
        """The compiled ``mujoco.MjModel`` (cached; do not modify it in place)."""
        model = self._cache.get("model")
        if model is None:
            spec = self.build_spec()
            try:
                model = spec.compile()
            except Exception as e:
                raise HandModelError(f"hand {self.name!r}: MuJoCo cannot compile it: {e}") from e
            self._cache["model"] = model
        return model

    # ------------------------------------------------------------------ postures and queries
    def default_qpos(self, model=None) -> np.ndarray:
        """``qpos`` (nq,) with the wrist at the origin and the fingers at ``default_posture``.

        Joints not listed in ``default_posture`` sit at 0 clipped into their range; followers of a
        joint coupling are set from their leader.
        """
        import mujoco

        m = self.compile() if model is None else model
        q = m.qpos0.copy()
        for j in range(m.njnt):
            name = m.joint(j).name
            adr = m.jnt_qposadr[j]
            val = self.default_posture.get(name, q[adr])
            if m.jnt_limited[j]:
                lo, hi = m.jnt_range[j]
                val = float(np.clip(val, lo, hi))
            q[adr] = val
        for e in range(m.neq):
            if m.eq_type[e] != mujoco.mjtEq.mjEQ_JOINT or m.eq_obj2id[e] < 0:
                continue
            c = m.eq_data[e]
            x = q[m.jnt_qposadr[m.eq_obj2id[e]]]
            q[m.jnt_qposadr[m.eq_obj1id[e]]] = c[0] + c[1] * x + c[2] * x**2 + c[3] * x**3
        return q

    def default_ctrl(self, model=None) -> np.ndarray:
        """``ctrl`` (nu,) holding :meth:`default_qpos` (every actuator here is a joint servo)."""
        m = self.compile() if model is None else model
        q = self.default_qpos(m)
        ctrl = np.zeros(m.nu)
        for a in range(m.nu):
            ctrl[a] = q[m.jnt_qposadr[m.actuator_trnid[a, 0]]]
        return np.clip(ctrl, m.actuator_ctrlrange[:, 0], m.actuator_ctrlrange[:, 1])

    def hand_parts(self, model=None) -> dict[str, list[str]]:
        """Robot finger (and ``palm``) → names of its bodies, for contact reports.

        A finger owns the bodies on the chain from its tip site up to where it branches off the
        palm; every other hand body is the palm.
        """
        m = self.compile() if model is None else model
        wrist_id = m.body(WRIST_BODY).id
        chains = {}
        for f, site in self.tip_site_names.items():
            b = int(m.site_bodyid[m.site(site).id])
            chain = []
            while b != wrist_id and b > 0:
                chain.append(int(b))
                b = m.body_parentid[b]
            chains[f] = chain
        counts: dict[int, int] = {}
        for chain in chains.values():
            for b in chain:
                counts[b] = counts.get(b, 0) + 1
        parts = {f: [m.body(b).name for b in chain if counts[b] == 1][::-1]
                 for f, chain in chains.items()}  # fmt: skip
        owned = {n for names in parts.values() for n in names}
        parts["palm"] = [m.body(b).name for b in range(1, m.nbody) if m.body(b).name not in owned]
        return parts

    def self_collision_pairs(self) -> list[tuple[str, str]]:
        """Collision geom pairs (names) of different hand parts that must not interpenetrate.

        A pair's geoms belong to different parts of :meth:`hand_parts` (finger vs finger, or
        finger vs palm), and MuJoCo's own filters of the self-collision variant
        (``build_spec(self_collision=True)``) would let them touch: not on one weld body or on a
        weld parent and child, and not in an excluded body pair (the variant excludes the body
        pairs touching at the open posture, e.g. palm vs finger bases). Pairs that still touch
        at the open posture (signed distance ≤ 0, "by construction") are left out too. Geom
        names are those of :meth:`build_spec`, which the retargeting scene shares. Cached.
        """
        pairs = self._cache.get("self_collision_pairs")
        if pairs is not None:
            return list(pairs)
        import mujoco

        m = self.build_spec(self_collision=True).compile()
        d = mujoco.MjData(m)
        d.qpos[:] = self.default_qpos(m)
        mujoco.mj_kinematics(m, d)
        part_of = {m.body(b).id: p for p, bodies in self.hand_parts(m).items() for b in bodies}
        geoms = [
            g
            for g in range(m.ngeom)
            if (m.geom_contype[g] or m.geom_conaffinity[g]) and m.geom_bodyid[g] in part_of
        ]
        excluded = {(int(s) >> 16, int(s) & 0xFFFF) for s in m.exclude_signature}
        weld = m.body_weldid
        fromto = np.zeros(6)
        pairs = []
        for i, a in enumerate(geoms):
            for b in geoms[i + 1 :]:
                ba, bb = int(m.geom_bodyid[a]), int(m.geom_bodyid[b])
                if part_of[ba] == part_of[bb]:
                    continue
                wa, wb = int(weld[ba]), int(weld[bb])
                if wa == wb or weld[m.body_parentid[wa]] == wb or weld[m.body_parentid[wb]] == wa:
                    continue  # MuJoCo's parent-child filter (on weld bodies)
                if any((min(x, y), max(x, y)) in excluded for x, y in ((ba, bb), (wa, wb))):
                    continue
                if mujoco.mj_geomDistance(m, d, a, b, 0.01, fromto) <= 0.0:
                    continue  # touching at the open posture
                pairs.append((m.geom(a).name, m.geom(b).name))
        self._cache["self_collision_pairs"] = pairs
        return list(pairs)

    @property
    def scale(self) -> float:
        """Robot/human hand size ratio (dimensionless).

        Mean wrist→fingertip distance of the robot fingers (open posture) over that of the
        human fingers they are mapped to, on MANO's default (mean) right hand.
        """
        val = self._cache.get("scale")
        if val is None:
            val = self._compute_scale()
            self._cache["scale"] = val
        return val

    def _compute_scale(self) -> float:
        import mujoco

        from dexcanvas_core.mano.skeleton import HandSkeleton

        m = self.compile()
        d = mujoco.MjData(m)
        d.qpos[:] = self.default_qpos(m)
        mujoco.mj_kinematics(m, d)
        wrist = d.site(WRIST_SITE).xpos
        human = HandSkeleton.default("right").rest_keypoints
        h_wrist = human[MANO21.index("wrist")]
        r, h = [], []
        for f in HUMAN_FINGERS:
            rf = self.fingers.get(f)
            if rf is None:
                continue
            r.append(np.linalg.norm(d.site(f"{rf}_tip_site").xpos - wrist))
            h.append(np.linalg.norm(human[MANO21.index(f"{f}_tip")] - h_wrist))
        return float(np.mean(r) / np.mean(h))

    def summary(self) -> dict:
        """One row of ``retarget hands``: name, DoF, actuators, fingers, source, licence."""
        m = self.compile()
        n_finger_dof = m.nv - len(WRIST_JOINTS)
        n_finger_act = m.nu - len(WRIST_JOINTS)
        return {
            "name": self.name,
            "description": self.description,
            "dof": m.nv,
            "dof_wrist": len(WRIST_JOINTS),
            "dof_fingers": n_finger_dof,
            "actuators": m.nu,
            "actuators_fingers": n_finger_act,
            "couplings": int(m.neq + len(coupling_tendons(m))),
            "fingers": {f: self.fingers.get(f) for f in HUMAN_FINGERS},
            "tip_sites": self.tip_site_names,
            "scale": round(self.scale, 3),
            # The retargeting's per-hand settings (see their fields).
            "wrist_offset": self.wrist_offset is not None,
            "wrist_weight": round(self.wrist_weight, 4),
            "joint_limit_margin": self.joint_limit_margin,
            "source": self.source.short,
            "source_kind": self.source.kind,
            "location": self.source.location,
            "licence": self.source.licence_short,
            "licence_full": self.source.licence,
            "upstream": self.source.upstream,
        }


def _attach_keeping_names(frame, body) -> None:
    """``frame.attach_body(body)`` with an empty prefix, so the source's names are kept.

    MuJoCo warns that empty-prefix attachments may not save back to XML with the child's
    defaults; the hand specs built here are compiled, not re-saved through the child, so the
    notice is captured instead of printed. Any other warning is passed on to ``logging``.
    """
    import mujoco

    notices: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(notices.append)
    try:
        frame.attach_body(body, "", "")
    finally:
        mujoco.set_mju_user_warning(previous)
    for msg in notices:
        if "empty prefix" not in msg:
            log.warning("MuJoCo: %s", msg)


def coupling_tendons(m) -> list[int]:
    """Ids of the fixed tendons that couple joints: over two or more joints, limited to a range
    no wider than ``COUPLING_TENDON_WIDTH_M`` (2 mm; Shadow's ``T_*J1c``; its other two-joint
    tendons only bound the sum)."""
    import mujoco

    from retarget.limits.coupling import COUPLING_TENDON_WIDTH_M

    out = []
    for t in range(m.ntendon):
        adr, num = m.tendon_adr[t], m.tendon_num[t]
        fixed = all(m.wrap_type[adr + k] == mujoco.mjtWrap.mjWRAP_JOINT for k in range(num))
        lo, hi = m.tendon_range[t]
        if fixed and num >= 2 and m.tendon_limited[t] and hi - lo <= COUPLING_TENDON_WIDTH_M:
            out.append(t)
    return out


def _prepare_source(src) -> None:
    """Drop what is not the hand's kinematics: actuators, sensors, keyframes, global sizes."""
    for kind in ("actuators", "sensors", "keys"):
        for el in list(getattr(src, kind)):
            src.delete(el)
    # Global sizes / user-data widths would conflict with the parent spec when attaching.
    for attr in ("njmax", "nconmax", "nstack"):
        setattr(src, attr, -1)
    for attr in (
        "nuser_body", "nuser_jnt", "nuser_geom", "nuser_site", "nuser_cam", "nuser_tendon",
        "nuser_actuator", "nuser_sensor",
    ):  # fmt: skip
        setattr(src, attr, -1)


def wrist_qpos_from_mano(R_world_mano, p_world_wrist) -> np.ndarray:
    """The 6 wrist joint values (x, y, z [m], rx, ry, rz [rad]) for a MANO wrist pose.

    ``R_world_mano`` (..., 3, 3): MANO's global rotation; ``p_world_wrist`` (..., 3): the posed
    wrist joint J0 [m]. A batch (a whole trajectory at once) gives (..., 6).
    """
    from scipy.spatial.transform import Rotation

    R = np.asarray(R_world_mano, float)
    p = np.asarray(p_world_wrist, float)
    if R.shape[-2:] != (3, 3) or p.shape[-1:] != (3,) or R.shape[:-2] != p.shape[:-1]:
        raise ValueError(f"expected R (..., 3, 3) and p (..., 3), got {R.shape} and {p.shape}")
    euler = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_euler("XYZ").reshape(p.shape)
    return np.concatenate([p, euler], axis=-1)


def package_path(module: str, *parts: str, pip_name: str | None = None):
    """Path of a data file inside an installed package, without importing the package.

    ``importlib.util.find_spec`` locates the package directory only (importing
    ``robosuite_models`` would fail without robosuite; ``gymnasium_robotics`` prints notices).
    Raises :class:`HandModelError` naming the pip package when it is not installed.
    """
    import importlib.util
    from pathlib import Path

    try:
        spec = importlib.util.find_spec(module)
    except (ImportError, ValueError):
        spec = None
    if spec is None or not spec.submodule_search_locations:
        raise HandModelError(
            f"the package {module!r} is not installed; run: pip install {pip_name or module}"
        )
    path = Path(next(iter(spec.submodule_search_locations))).joinpath(*parts)
    if not path.exists():
        raise HandModelError(f"{path} is missing from the installed package {module!r}")
    return path


def example_robot_data_path(*parts: str):
    """Path inside example-robot-data's data tree (``cmeel.prefix/share/example-robot-data``).

    The wheel ships data only (no Python module); its files live under the ``cmeel.prefix``
    directory of site-packages.
    """
    import sysconfig
    from pathlib import Path

    roots = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    for root in roots:
        p = Path(root, "cmeel.prefix", "share", "example-robot-data", "robots", *parts)
        if p.exists():
            return p
    raise HandModelError(
        f"example-robot-data file robots/{'/'.join(parts)} not found; "
        "run: pip install example-robot-data"
    )


def urdf_with_mujoco_compiler(urdf_text: str, **compiler: str) -> str:
    """Insert a ``<mujoco><compiler .../></mujoco>`` extension right after ``<robot ...>``."""
    start = urdf_text.find("<robot")
    if start < 0:
        raise HandModelError("not a URDF: no <robot> element")
    end = urdf_text.index(">", start) + 1
    attrs = " ".join(f'{k}="{v}"' for k, v in compiler.items())
    return urdf_text[:end] + f"<mujoco><compiler {attrs}/></mujoco>" + urdf_text[end:]


def robots_dir():
    """The repository's ``robots/`` folder (models authored by this project)."""
    from pathlib import Path

    return Path(__file__).resolve().parents[2] / "robots"
