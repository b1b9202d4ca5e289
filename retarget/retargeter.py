"""Retargeting a human demonstration onto a robot hand: a QP per frame, warm-started in time.

Per frame the human targets are

* the wrist: MANO's wrist frame (``R = exp(global_rot_aa)``, origin at keypoint 0) is the robot's
  ``wrist`` body frame by construction of the hand models (``retarget.hands.base``);
* keypoints: every MANO21 keypoint the robot can match (``hand.keypoint_map``);

positions (wrist and keypoints) are scaled by the hand's size ratio ``hand.scale`` about the
object's centre (about the wrist when there is no object): the robot hand is the human hand
enlarged around the object, so its fingertips land just outside the surface and the contact
terms below close them onto it, instead of the wrist pinning a larger hand into the object;
* fingertip-to-fingertip vectors from the thumb (scaled), which keep pinches closed;
* contacts: where the human fingertip touches the object (a fingertip within
  ``contacts.threshold_m`` of the object surface, or a phalanx, by default; the force pipeline's
  contact records with ``contacts.source="records"``), the robot fingertip site goes to the same
  surface point (unscaled, in the object's frame);

and the limits are the joint ranges, velocity bounds, the model's couplings, non-penetration
of the hand's collision geoms and the object, and no self-collision between the collision geoms
of different fingers (and of fingers and palm; ``HandModel.self_collision_pairs``). The same
objectives run on the Pinocchio backend (default; our QP through ``qpsolvers``) or the mink
backend (``mink.solve_ik`` with the objectives as mink tasks, mink's configuration limit and
self-collision limit, and our hand–object, coupling and wrist-speed rows: mink's collision limit
has one minimum distance for all pairs, no table clearance or per-link clearance). The
warm-start prediction and the end-of-step penetration re-steps are the Pinocchio backend's.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import mujoco
import numpy as np

from dexcanvas_core.checks import check_type
from dexcanvas_core.keypoints import MANO21
from dexcanvas_core.rotations import aa_to_quat_wxyz
from dexcanvas_core.table import DEFAULT_TABLE, Table
from dexcanvas_core.trajectory import Trajectory
from retarget.config import RetargetConfig
from retarget.errors import RetargetError
from retarget.grip import GripAssembly
from retarget.hands.base import WRIST_SITE, wrist_qpos_from_mano
from retarget.hands.model import HandModel
from retarget.kinematics import MujocoKinematics, PinocchioKinematics
from retarget.limits import (
    CollisionLimit,
    ContactSweep,
    CouplingLimit,
    JointLimit,
    VelocityLimit,
)
from retarget.mink_backend import MinkSolver
from retarget.objectives import (
    KeypointObjective,
    PostureObjective,
    SmoothnessObjective,
    SurfaceContactObjective,
    VectorObjective,
    WristPoseObjective,
)
from retarget.robot_trajectory import RobotTrajectory
from retarget.scene import Scene, build_retarget_scene, check_table
from retarget.solve import FrameSolver
from retarget.targets import HumanTargets, contact_ramp

log = logging.getLogger(__name__)


class Retargeter(HumanTargets, GripAssembly, FrameSolver):
    """Retarget human trajectories onto one robot hand (and optionally one object).

    The per-frame targets are :class:`retarget.targets.HumanTargets`', the per-frame solve
    :class:`retarget.solve.FrameSolver`'s, the position command's grip and force matching
    :class:`retarget.grip.GripAssembly`'s; the configuration is :mod:`retarget.config`.

    Args:
        hand: a ``retarget.hands.HandModel`` (see ``retarget.hands.get_hand``).
        geometry: the object's ``ObjectGeometry``
            (``dexcanvas_core.objects.geometry.object_geometry``); ``None`` retargets the hand
            alone (keypoint-only use).
        config: weights and switches (default ``RetargetConfig()``).
        table: the table of the trajectories it will retarget (``table_of(trajectory)``;
            default the default table): the hand keeps ``collision.table_clearance`` above its
            top, and only there. :meth:`retarget` refuses a trajectory on another table.

    >>> from dexcanvas_core import load_demonstration, object_geometry
    >>> from retarget import get_hand
    >>> human = load_demonstration("cube2/tripod").slice(0, 30)
    >>> robot = Retargeter(get_hand("shadow"), object_geometry("cube2")).retarget(human)
    >>> robot.q.shape, robot.q_command.shape   # (T, nq): floating wrist + hand joints
    ((30, 30), (30, 30))
    """

    def __init__(
        self,
        hand,
        geometry=None,
        config: RetargetConfig | None = None,
        table: Table | None = None,
    ):
        check_type(
            "hand",
            hand,
            HandModel,
            hint="; get one with retarget.get_hand(NAME)",
            error=RetargetError,
        )
        check_type("config", config, RetargetConfig, optional=True, error=RetargetError)
        self.hand = hand
        self.geometry = geometry
        self.cfg = config or RetargetConfig()
        # The hand's self-collision variant, whatever use_self_collision says: its contact
        # filters are those of the self-collision pairs, which the metrics always measure (the
        # scene is kinematic: contact settings change nothing else).
        self.scene: Scene = build_retarget_scene(
            hand, geometry, DEFAULT_TABLE if table is None else table, self_collision=True
        )
        self.table = self.scene.table
        m = self.scene.model
        self.nq = self.scene.hand_nq
        if self.cfg.solver.backend == "pinocchio":
            self.kin = PinocchioKinematics(m)
        else:
            self.kin = MujocoKinematics(m, self.scene.data, nq=self.nq)
        self.keypoint_map = dict(hand.keypoint_map)
        self.keypoint_map.pop("wrist", None)
        self.kp_names = list(self.keypoint_map)
        self.kp_index = np.array([MANO21.index(k) for k in self.kp_names])
        self.kp_sites = [self.keypoint_map[k] for k in self.kp_names]
        tip_human = list(hand.mapped_human_fingers)
        self.tip_human = tip_human
        self.tip_index = np.array([MANO21.index(f"{f}_tip") for f in tip_human])
        self.tip_sites = [f"{hand.fingers[f]}_tip_site" for f in tip_human]
        self.scale = float(hand.scale)
        c = self.cfg
        is_tip = np.array([k.endswith("_tip") for k in self.kp_names])
        self.keypoints = KeypointObjective(
            self.kp_sites, np.where(is_tip, c.keypoints.tip_weight, c.keypoints.joint_weight)
        )
        ww = hand.wrist_weight  # the hand's factor on the wrist weights
        self.wrist = WristPoseObjective(
            WRIST_SITE, (ww * c.wrist.position_weight, ww * c.wrist.rotation_weight)
        )
        thumb_site = self.tip_sites[0] if tip_human and tip_human[0] == "thumb" else None
        pairs = [(s, thumb_site) for s in self.tip_sites[1:]] if thumb_site else []
        # A gripper's two "fingers" both take several human fingers: no vectors among them.
        pairs = [(a, b) for a, b in pairs if a != b]
        self.vec_human = (
            [(self.tip_index[i + 1], self.tip_index[0]) for i, (a, _) in enumerate(pairs)]
            if pairs
            else []
        )
        self.vectors = VectorObjective(pairs, c.vectors.weight)
        self.contacts = None
        if geometry is not None:
            part_geoms = self._contact_links(hand, m)
            if not c.contacts.link_contacts:
                part_geoms = [p[:1] for p in part_geoms]
            self.contacts = SurfaceContactObjective(
                m,
                self.scene.data,
                [p[0] for p in part_geoms],
                self.scene.object_geoms,
                self.nq,
                c.contacts.weight,
                part_geoms=part_geoms,
                tangent_weight=(
                    c.force_matching.tangent_weight
                    if c.force_matching.enabled
                    else c.contacts.tangent_weight
                ),
                hover=c.contacts.hover_m,
                closing_weight=c.closing.weight,
                closing_slack=c.closing.slack_m,
            )
        q0 = hand.default_qpos(m)[: self.nq]
        self.q_default = q0
        finger_mask = np.ones(self.nq, bool)
        finger_mask[:6] = False
        self.posture = PostureObjective(q0, c.posture.weight, mask=finger_mask)
        self.smooth = SmoothnessObjective(c.smoothness.weight)
        lower = np.where(m.jnt_limited[: self.nq], m.jnt_range[: self.nq, 0], -np.inf)
        upper = np.where(m.jnt_limited[: self.nq], m.jnt_range[: self.nq, 1], np.inf)
        self.lower, self.upper = lower, upper
        # The kinematic solution keeps the finger joints joint_limit_margin inside their ranges
        # (at most a quarter of a range); the servo commands (the grip's squeeze) keep the whole
        # range, so a finger resting near a limit can still press.
        margin = hand.joint_limit_margin if c.joint_limits.margin is None else c.joint_limits.margin
        inner = np.minimum(margin, 0.25 * (upper - lower))
        inner[:6] = 0.0  # the wrist's coordinates
        self._solve_lower, self._solve_upper = lower + inner, upper - inner
        limited = m.jnt_limited[: self.nq].astype(bool)
        self.limits = [JointLimit(self._solve_lower, self._solve_upper, limited)]
        coupling = CouplingLimit.from_mjmodel(m)
        if coupling:
            self.limits.append(coupling)
        self._coupling = coupling
        self._servo_map = None  # (nq, nq) servoed joints → all (``_servo_follower_map``)
        # One mj_collision sweep per iterate finds the hand–object and hand–hand pairs within
        # their query distances, for both limits and the metrics (ContactSweep).
        # Hand–hand pairs are reported as far as the self pairs need, hand–object and
        # hand–table pairs as far as the collision limit needs (ContactSweep.set_margins).
        self.sweep = ContactSweep(m, self.scene.data, self.nq)
        self.sweep.set_margins(
            self.scene.hand_geoms,
            c.self_collision.distmax,
            self.scene.object_geoms + self.scene.table_geoms,
            c.collision.distmax,
        )
        self.collision = None  # the non-penetration limit (when use_collision)
        self.distance_query = None  # the same query, for metrics, whatever use_collision says
        if geometry is not None and self.scene.object_geoms:
            obstacles = self.scene.object_geoms + self.scene.table_geoms
            pairs_geom = [(a, b) for a in self.scene.hand_geoms for b in obstacles]
            table = set(self.scene.table_geoms)
            self.distance_query = CollisionLimit(
                m,
                self.scene.data,
                pairs_geom,
                hand_nq=self.nq,
                margin=c.collision.penetration_margin,
                distmax=c.collision.distmax,
                sweep=self.sweep,
                pair_margins=[
                    -c.collision.table_clearance if b in table else c.collision.penetration_margin
                    for _, b in pairs_geom
                ],
            )
            if self.cfg.collision.enabled:
                self.collision = self.distance_query
                self.limits.append(self.collision)
        if self.contacts is not None:
            # The iterate's contact points read the sweep's configuration (no second
            # mj_kinematics on the scene), other configurations a posed copy.
            self.contacts.kinematics = self.sweep.kinematics
        self._pair_parts = None  # (pairs, F·3): which finger part each hand-object pair's geom is
        if self.distance_query is not None and self.contacts is not None:
            F = len(self.contacts.part_geoms)
            part_of = {}
            for f, parts in enumerate(self.contacts.part_geoms):
                for k, geoms in enumerate(parts):
                    for g in geoms:
                        part_of.setdefault(g, []).append(f * 3 + k)
            obj = set(self.scene.object_geoms)
            mask = np.zeros((len(self.distance_query.pairs), F * 3), bool)
            for i, (a, b) in enumerate(self.distance_query.pairs):
                if b in obj:
                    mask[i, part_of.get(a, [])] = True
            self._pair_parts = mask
            self._base_margins = self.distance_query.pair_margins.copy()
        self._wrist_speed = np.full(self.nq, np.inf)  # FrameSpeedLimit's v_max [m/s or rad/s]
        self._wrist_speed[:3] = c.velocity.max_wrist_speed
        # Self-collision: the same query for metrics, the limit when use_self_collision.
        self.self_pairs = _geom_pairs(m, hand.self_collision_pairs())
        self.self_collision = None
        self.self_distance_query = None
        if self.self_pairs:
            self.self_distance_query = CollisionLimit(
                m,
                self.scene.data,
                self.self_pairs,
                hand_nq=self.nq,
                margin=c.self_collision.margin,
                distmax=c.self_collision.distmax,
                self_collision=True,
                max_recovery=c.self_collision.margin,
                sweep=self.sweep,
            )
            if self.cfg.self_collision.enabled:
                self.self_collision = self.self_distance_query
                self.limits.append(self.self_collision)
        # The iterates' velocity limit (_solve_frame; one object, which memoises its box).
        self._velocity = VelocityLimit(c.velocity.max_joint_speed)
        self._mink = None
        if self.cfg.solver.backend == "mink":
            self._mink = MinkSolver(self)

    def retarget(
        self, traj: Trajectory, progress: Callable[[int, int], None] | None = None
    ) -> RobotTrajectory:
        """Retarget every frame of ``traj``; ``progress(done, total)`` is called per frame."""
        traj.validate()
        check_table(self.table, traj, "Retargeter")
        tg = self.human_targets(traj)
        T = traj.num_frames
        q = self.q_default.copy()
        q[:6] = wrist_qpos_from_mano(tg["wrist_R"][0], tg["wrist_p"][0])
        Q = np.zeros((T, self.nq))
        Qc = np.zeros((T, self.nq))
        has_obj = self.geometry is not None and bool(traj.objects)
        solve_s = 0.0
        self.smooth.set_previous(None)
        fm = None
        if self.cfg.force_matching.enabled and has_obj:
            fm = self._force_targets(traj)
        elif (
            self.cfg.grip.mode == "wrench"
            and has_obj
            and self.cfg.contacts.enabled
            and self.contacts is not None
        ):
            fm = self._grip_targets(traj)
        ramp = contact_ramp(tg["contact_active"], self.cfg.contacts.ramp_s * traj.fps)
        wq = wrist_qpos_from_mano(tg["wrist_R"], tg["wrist_p"])  # (T, 6)
        obj_quat = aa_to_quat_wxyz(traj.object.rot_aa) if has_obj else None
        clearance = self.collision is not None and self._pair_parts is not None
        margins = self._frame_margins(tg["contact_by_part"]) if clearance else None  # (T, pairs)
        closing = self._closing_parts(tg, traj.fps)
        try:
            for t in range(T):
                if has_obj:
                    self.scene.set_object_pose(traj.object.pos[t], quat_wxyz=obj_quat[t])
                self.wrist.set_target(tg["wrist_p"][t], tg["wrist_R"][t])
                self.keypoints.set_targets(tg["keypoints"][t])
                if self.vec_human:
                    self.vectors.set_targets(tg["vectors"][t])
                if self.contacts is not None:
                    active = tg["contact_active"][t] & self.cfg.contacts.enabled
                    self.contacts.set_contacts(
                        active,
                        tg["contact_points"][t],
                        tg["contact_part"][t],
                        ramp[t],
                        normals=tg["contact_normals"][t],
                        closing=None if closing is None else closing[t],
                    )
                if margins is not None:
                    self.collision.pair_margins = margins[t]
                n_it = (
                    self.cfg.solver.first_frame_iterations if t == 0 else self.cfg.solver.iterations
                )
                t0 = time.perf_counter()
                q0 = q
                if t >= 2 and self.cfg.solver.warm_start_extrapolate:
                    q0 = self._warm_start(Q[t - 2 : t], wq[t - 1 : t + 1], tg["contact_active"], t)
                q = self._solve_frame(q0, n_it, traj.timestamp, t, q_prev=q if t > 0 else None)
                if fm is not None:
                    Qc[t] = q + self._force_squeeze(q, t, tg, fm)
                else:
                    Qc[t] = q + self._squeeze(q, tg["contact_active"][t], tg["contact_normals"][t])
                solve_s += time.perf_counter() - t0
                self.smooth.set_previous(q)
                Q[t] = q
                if progress is not None:
                    progress(t + 1, T)
        finally:  # the limit is shared with the metrics: leave it as it was, also on errors
            if clearance:
                self.collision.pair_margins = self._base_margins.copy()
        m = self.measure(traj, Q, tg)
        return RobotTrajectory(
            hand=self.hand.name,
            joint_names=[
                mujoco.mj_id2name(self.scene.model, mujoco.mjtObj.mjOBJ_JOINT, j)
                for j in range(self.nq)
            ],
            q=Q,
            q_command=Qc,
            timestamp=traj.timestamp.copy(),
            tip_sites=list(self.tip_sites),
            tip_pos_world=m["tip_pos_world"],
            keypoint_err=m["keypoint_err"],
            min_distance=m["min_distance"],
            self_min_distance=m["self_min_distance"],
            contact_active=m["contact_active"],
            contact_err=m["contact_err"],
            solve_time_s=solve_s,
            robot_force=None if fm is None else fm["robot_force"],
            human_force=None if fm is None else fm["human_force"],
            wrench_shortfall=None if fm is None else fm["shortfall"],
            meta={
                "backend": self.cfg.solver.backend,
                "uuid": traj.uuid,
                "scale": self.scale,
                "config": self.cfg.flat(),
            },
        )

    def measure(self, traj: Trajectory, Q: np.ndarray, targets: dict | None = None) -> dict:
        """Kinematic metrics of any joint trajectory ``Q`` (T, nq) against ``traj``'s targets.

        Returns ``tip_pos_world (T, F, 3)``, ``keypoint_err (T,)`` (mean robot-site distance to
        the scaled human keypoints [m]), ``min_distance (T,)`` (smallest hand–object signed
        distance [m], inf without object), ``self_min_distance (T,)`` (smallest signed distance
        between different hand parts [m], inf when none is near), ``contact_active (T, F)`` and
        ``contact_err (T, F)`` (distance from the finger surface nearest the object to the human
        contact point [m], NaN where inactive). The retargeter's own output and baselines are
        measured alike.
        """
        tg = self.human_targets(traj) if targets is None else targets
        T, F = traj.num_frames, len(self.tip_sites)
        Q = np.asarray(Q, dtype=np.float64)
        if Q.shape != (T, self.nq):
            raise RetargetError(f"joint trajectory has shape {Q.shape}, expected ({T}, {self.nq})")
        tips = np.zeros((T, F, 3))
        kp_err = np.zeros(T)
        min_d = np.full(T, np.inf)
        self_d = np.full(T, np.inf)
        c_err = np.full((T, F), np.nan)
        active_all = np.asarray(tg["contact_active"], bool)
        has_obj = self.geometry is not None and bool(traj.objects)
        obj_geoms = set(self.scene.object_geoms)
        obj_quat = aa_to_quat_wxyz(traj.object.rot_aa) if has_obj else None
        tip_sites, kp_sites = tuple(self.tip_sites), tuple(self.kp_sites)
        for t in range(T):
            q = Q[t]
            if has_obj:
                self.scene.set_object_pose(traj.object.pos[t], quat_wxyz=obj_quat[t])
            self.kin.forward(q)
            tips[t] = self.kin.site_positions(tip_sites)
            robot_kp = self.kin.site_positions(kp_sites)
            kp_err[t] = float(np.mean(np.linalg.norm(robot_kp - tg["keypoints"][t], axis=1)))
            if self.distance_query is not None:
                d = self.distance_query.distances(q)
                min_d[t] = min((x[2] for x in d if x[1] in obj_geoms), default=np.inf)
            if self.self_distance_query is not None:
                self_d[t] = self.self_distance_query.min_distance(q)
            if self.contacts is not None and active_all[t].any():
                self.contacts.set_contacts(
                    active_all[t], tg["contact_points"][t], tg["contact_part"][t]
                )
                d_c = self.contacts.distances_to_targets(q)
                c_err[t, active_all[t]] = d_c[active_all[t]]
        return {
            "tip_pos_world": tips,
            "keypoint_err": kp_err,
            "min_distance": min_d,
            "self_min_distance": self_d,
            "contact_active": active_all.copy(),
            "contact_err": c_err,
        }


def _geom_pairs(m: mujoco.MjModel, names: list[tuple[str, str]]) -> list[tuple[int, int]]:
    """Geom ids of named pairs in ``m`` (the retargeting scene shares the hand's geom names)."""
    out = []
    for a, b in names:
        ia = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, a)
        ib = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, b)
        if ia < 0 or ib < 0:
            raise RetargetError(f"self-collision pair ({a!r}, {b!r}) is not in the scene")
        out.append((ia, ib))
    return out
