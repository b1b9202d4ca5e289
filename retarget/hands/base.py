"""The layout every hand model shares, and the parts a hand description is made of.

Every hand model (:class:`retarget.hands.model.HandModel`, built by :mod:`retarget.hands.build`)
has the same layout:

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

The parts: :class:`ModelSource` (where the model comes from), :class:`SitePlacement`,
:class:`ActuatorSpec`, :class:`JointCoupling`, :class:`ContactParams`, :class:`WristAlignment`
(the robot root frame in MANO's wrist frame), :class:`WristOffset` and :class:`WristGains`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from dexcanvas_core.keypoints import FINGERS
from dexcanvas_core.rotations import aa_to_matrix
from retarget.errors import HandModelError

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


@dataclass(frozen=True)
class ContactParams:
    """Contact parameters given to every hand collision geom.

    ``friction`` (sliding, torsional [m], rolling [m]), ``solref``, ``solimp`` are MuJoCo's
    defaults (MuJoCo XML reference, ``geom``); condim 4 on fingertip geoms (torsional friction
    for pinches) and 3 elsewhere as in docs/design.md (conventions).
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


def wrist_qpos_from_mano(R_world_mano, p_world_wrist) -> np.ndarray:
    """The 6 wrist joint values (x, y, z [m], rx, ry, rz [rad]) for a MANO wrist pose.

    ``R_world_mano`` (..., 3, 3): MANO's global rotation; ``p_world_wrist`` (..., 3): the posed
    wrist joint J0 [m]. A batch (a whole trajectory at once) gives (..., 6).
    """
    R = np.asarray(R_world_mano, float)
    p = np.asarray(p_world_wrist, float)
    if R.shape[-2:] != (3, 3) or p.shape[-1:] != (3,) or R.shape[:-2] != p.shape[:-1]:
        raise ValueError(f"expected R (..., 3, 3) and p (..., 3), got {R.shape} and {p.shape}")
    euler = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_euler("XYZ").reshape(p.shape)
    return np.concatenate([p, euler], axis=-1)
