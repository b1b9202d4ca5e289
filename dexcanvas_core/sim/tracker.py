"""Tracking a demonstration in physics: the environment, the residual action, the trackers.

The simulated hand's actuator targets are the human reference plus a *residual*:

    ctrl_t = ref_t + grip_t + M · u_t,      u_t = clip(τ · u_{t-1} + a_t, -1, 1)

``a_t`` (11-D: wrist x, y, z [×0.03 m], wrist Euler x, y, z [×0.15 rad], one flexion offset
per finger [×0.4 rad, added to all flexion hinges of that finger]) is what a tracker chooses
each data frame; ``u`` is the paper's exponentially smoothed residual. ``grip_t`` is the
contact-aware grip bias of :mod:`dexcanvas_core.sim.grip`: fingers whose reference pad is within
``grip_far_m`` of the object surface get joint-target offsets that press the pad into the
surface with a contact-keeping force plus, while the reference object is off the table (and
from shortly before it leaves it), a force sized to carry the object's weight, so position
actuators grip instead of resting on it.

The reward (the DexCanvas paper's) per frame is ``exp(-60·pos_err) + exp(-10·rot_err) −
‖a‖²``; a rollout fails at the first frame whose object position error exceeds 5 cm.

**Trackers** (:mod:`dexcanvas_core.sim.mpc`) implement ``ResidualTracker`` (``reset(env)``,
``act(env) -> a``): the zero-residual ``OpenLoop``, and ``SamplingMPC`` (predictive sampling
with a softmax over the best samples, parallel rollouts with ``mujoco.rollout``). A learned
residual policy (the paper's per-pair PPO) plugs in the same way: it reads ``env.observation()``
and returns ``a``; the scene, the reference and the force code do not change.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import FINGERS
from dexcanvas_core.sim.forces import (
    FrameAccumulator,
    FrameContacts,
    FramePoses,
    finish_frame,
    read_contacts,
)
from dexcanvas_core.sim.grip import contact_keeping_force, squeeze_offsets
from dexcanvas_core.sim.hand import FINGER_HINGES, HAND_JOINTS
from dexcanvas_core.sim.mj_warnings import WarningCounter
from dexcanvas_core.sim.physics import carried_load
from dexcanvas_core.sim.reference import Reference
from dexcanvas_core.sim.signal import moving_average
from dexcanvas_core.table import DEFAULT_TABLE

ACTION_NAMES: tuple[str, ...] = (
    "wrist_x", "wrist_y", "wrist_z", "wrist_rx", "wrist_ry", "wrist_rz",
    *(f"{f}_flex" for f in FINGERS),
)  # fmt: skip
ACTION_DIM = len(ACTION_NAMES)


@dataclass(frozen=True)
class TrackingConfig:
    """The residual action, grip bias, warm-up and success rule."""

    tau: float = 0.9
    """Action smoothing ``u_t = τ·u_{t-1} + a_t`` (per data frame)."""
    scale_pos_m: float = 0.03
    scale_rot_rad: float = 0.15
    scale_finger_rad: float = 0.4
    grip: bool = True
    """Contact-aware grip offsets (:mod:`dexcanvas_core.sim.grip`)."""
    grip_force_min_n: float = 4.0
    """Contact-keeping pad force [N] (before the weight-carrying share), for objects heavy
    enough; lighter ones get less (``grip_force_floor_n``)."""
    grip_force_floor_n: float | None = 1.0
    """Light objects: the contact-keeping force is ``grip_force_weight_k`` times the object's
    weight, clipped to [``grip_force_floor_n``, ``grip_force_min_n``] [N] (people grip a light
    object more gently, grip force following the load;
    :func:`~dexcanvas_core.sim.grip.contact_keeping_force`). ``None``: ``grip_force_min_n``
    for every object. How the value was chosen: ``CHANGELOG.md``."""
    grip_force_weight_k: float = 2.7
    """Light objects' contact-keeping force in object weights (2.7 · m·g reaches the 4 N of
    ``grip_force_min_n`` at 150 g, the lightest object 4 N was measured to hold)."""
    grip_safety: float = 3.0
    """Grip force per finger: carry this many times the object's weight by friction."""
    grip_load_lead_s: float | None = 0.2
    """Grip force–load coupling (:func:`~dexcanvas_core.sim.physics.carried_load`): the
    weight-sized part of the grip force applies only while the reference object is off the
    table, built up this long [s] before lift-off (``F_min`` alone while it rests there);
    ``None``: the weight-sized force whenever a finger is near the object (the earlier model,
    which let the first finger to arrive push a resting heavy object away)."""
    grip_additive: bool = True
    """Pad force ``grip_force_min_n`` + the weight-carrying share (``True``) or the larger of
    the two (``False``, the earlier model: a heavy object got barely more grip than a light
    one, and slipped out of the grasp while held)."""
    grip_load_clear_m: tuple[float, float] = (0.001, 0.004)
    """Clearance [m] of the reference object's lowest point over the table at which the
    carried share of its weight ramps from 0 to 1."""
    grip_near_m: float = 0.002
    grip_far_m: float = 0.02
    """The grip ramps from 0 (pad ``grip_far_m`` from the surface) to full (``grip_near_m``)."""
    grip_smooth_s: float = 0.1
    settle_s: float = 0.1
    """Physics time before frame 0 with the targets of frame 0 (contacts settle)."""
    warmup_s: float = 0.3
    """If the object starts off the table (a clip that begins mid-grasp), it is held at its
    first pose by a weld while the hand settles into the grasp for this long."""
    fail_pos_m: float = 0.05
    """Early termination: object position error above this fails the rollout [m]."""
    reward_pos_k: float = 60.0
    reward_rot_k: float = 10.0
    reward_rot_w: float = 0.3
    """Weight of the rotation term in the planning reward (the paper weighs both terms 1;
    DESIGN.md's sources weigh position far above orientation, and so does planning here)."""
    action_penalty: float = 1.0
    contact_reward: float = 2.0
    """Weight of the contact-keeping term ``mean_f w_f · exp(-k·‖tip_f − tip_f^ref‖)`` (tips in
    the object frame, ``w_f`` the grip proximity of finger f): makes planning keep the fingers
    the human had on the object on it, which a short horizon would otherwise trade for a
    momentarily stiller object. Also an addition to the paper's reward."""
    contact_k: float = 100.0
    residual_penalty: float = 0.3
    """Weight of ``‖u‖²`` in the planning reward (an addition to the paper's reward: keeps the
    hand on the human reference unless leaving it helps the object)."""


def _finger_flex_rows() -> list[list[int]]:
    rows = []
    for f in FINGERS:
        names = [n for n in FINGER_HINGES if n.startswith(f) and n.endswith("_flex")]
        rows.append([HAND_JOINTS.index(n) for n in names])
    return rows


def action_matrix(cfg: TrackingConfig) -> np.ndarray:
    """``(51, 11)``: actuator-target offsets per unit of residual ``u``."""
    M = np.zeros((len(HAND_JOINTS), ACTION_DIM))
    for i in range(3):
        M[i, i] = cfg.scale_pos_m
        M[3 + i, 3 + i] = cfg.scale_rot_rad
    for k, rows in enumerate(_finger_flex_rows()):
        M[rows, 6 + k] = cfg.scale_finger_rad
    return M


def grip_weights(ref: Reference, cfg: TrackingConfig, tip_radius: np.ndarray) -> np.ndarray:
    """``(T, 5)`` in [0, 1]: how close each reference fingertip pad is to the object surface,
    moving-averaged over ``grip_smooth_s``."""
    if not np.isfinite(ref.tip_distance).all():
        return np.zeros_like(ref.tip_distance)
    gap = ref.tip_distance - tip_radius[None, :]
    w = np.clip((cfg.grip_far_m - gap) / (cfg.grip_far_m - cfg.grip_near_m), 0.0, 1.0)
    return moving_average(w, max(1, round(cfg.grip_smooth_s * ref.fps)))


def quat_angle(q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Rotation angle [rad] between unit quaternions ``(..., 4)`` (any convention)."""
    dot = np.abs(np.sum(q1 * q2, axis=-1))
    return 2.0 * np.arccos(np.clip(dot, 0.0, 1.0))


class TrackingEnv:
    """One demonstration being tracked in one scene (see the module docstring).

    ``t`` is the data frame the physics state corresponds to; :meth:`step` advances one frame.
    Everything recorded per frame (object pose, hand state, controls, contacts) is in the
    lists of :attr:`log`.
    """

    def __init__(
        self,
        scene,
        ref: Reference,
        cfg: TrackingConfig | None = None,
        *,
        ctrl_ref: np.ndarray | None = None,
        basis: np.ndarray | None = None,
        tip_weight: np.ndarray | None = None,
        qpos0: np.ndarray | None = None,
        tip_sensor_adr: int = 0,
    ):
        self.scene = scene
        self.ref = ref
        self.cfg = TrackingConfig() if cfg is None else cfg
        if abs(ref.fps - scene.fps) > 1e-6:
            raise ValidationError(f"scene built for {scene.fps} fps, reference has {ref.fps}")
        m = scene.model
        self.tip_sensor_adr = tip_sensor_adr
        self.n_tips = ref.tips_object.shape[1]
        self.rollout_data = mujoco.MjData(m)
        self.hold_until = 0
        """Frames before this one hold the object at its first pose (an object that does not
        rest by itself there, ``dexcanvas_core.sim.support``); 0: never held."""
        self._holding = False
        self._state_spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        self._state = np.zeros(mujoco.mj_stateSize(m, self._state_spec))
        self.ctrl_low = scene.hand.ctrl_low
        self.ctrl_high = scene.hand.ctrl_high
        if ctrl_ref is not None:
            # another plant (e.g. a robot hand): targets, residual basis and contact weights
            # come from the caller; nothing MANO-specific below applies
            if basis is None or tip_weight is None:
                raise ValidationError("ctrl_ref needs basis and tip_weight too")
            self.ctrl_ref = np.asarray(ctrl_ref, dtype=np.float64)
            self.M = np.asarray(basis, dtype=np.float64)
            self.tip_weight = np.asarray(tip_weight, dtype=np.float64)
            self.grip_force = np.zeros_like(self.tip_weight)
            self.load = np.ones(ref.num_frames)
            self.qpos0 = self.ctrl_ref[0] if qpos0 is None else np.asarray(qpos0)
            self.action_dim = self.M.shape[-1]
            self.reset()
            return
        self.M = action_matrix(self.cfg)
        self.action_dim = ACTION_DIM
        tip_geoms = [g for g, p in scene.hand.geom_part.items() if p.endswith(("_dip", "_ip"))]
        tip_radius = np.array(
            [
                m.geom_size[g, 0]
                for f in FINGERS
                for g in tip_geoms
                if scene.hand.geom_part[g].startswith(f)
            ]
        )
        self.tip_weight = grip_weights(ref, self.cfg, tip_radius)
        self.ctrl_ref = ref.ctrl()
        self.grip_force = np.zeros_like(self.tip_weight)
        self.load = np.ones(ref.num_frames)
        if self.cfg.grip_load_lead_s is not None:
            self.load = carried_load(
                scene.geometry, ref.object_pos, ref.object_quat, ref.fps,
                clear_m=self.cfg.grip_load_clear_m, lead_s=self.cfg.grip_load_lead_s,
                table=scene.table if scene.table is not None else DEFAULT_TABLE,
            )  # fmt: skip
        if self.cfg.grip:
            offsets, self.grip_force = squeeze_offsets(
                scene, self.ctrl_ref, ref.object_pos, ref.object_quat, self.tip_weight,
                force_min_n=contact_keeping_force(
                    scene.mass_kg, self.cfg.grip_force_min_n, self.cfg.grip_force_floor_n,
                    self.cfg.grip_force_weight_k,
                ),
                safety=self.cfg.grip_safety,
                friction=float(m.geom_friction[scene.object_geoms, 0].max()), load=self.load,
                additive=self.cfg.grip_additive,
            )  # fmt: skip
            self.ctrl_ref = self.ctrl_ref + offsets
        if not np.isfinite(ref.tips_object).all():
            self.tip_weight[:] = 0.0
        self.qpos0 = self.ctrl_ref[0]
        self.reset()

    def offset(self, t: int, u: np.ndarray) -> np.ndarray:
        """Actuator-target offsets of residuals ``u`` (``(A,)`` or ``(K, A)``) at frame ``t``."""
        M = self.M if self.M.ndim == 2 else self.M[min(t, self.M.shape[0] - 1)]
        return u @ M.T

    # -- state ----------------------------------------------------------------------------

    def reset(self) -> None:
        sc, ref, cfg = self.scene, self.ref, self.cfg
        m, d = sc.model, sc.data
        mujoco.mj_resetData(m, d)
        self.warnings = WarningCounter()  # MuJoCo's, this episode's (settling: frame 0)
        d.qpos[sc.hand.qpos_adr] = self.qpos0
        a = sc.object_qpos_adr
        d.qpos[a : a + 3] = ref.object_pos[0]
        d.qpos[a + 3 : a + 7] = ref.object_quat[0]
        d.ctrl[sc.hand.actuator] = self._clip(self.ctrl_ref[0])
        mujoco.mj_forward(m, d)
        self.u = np.zeros(self.action_dim)
        self.t = 0
        self.failed_at: int | None = None
        self.log = TrackLog()
        airborne = float(sc.support_gap(ref.object_pos[0], ref.object_quat[0])) > 0.005
        n_settle = round((cfg.warmup_s if airborne else cfg.settle_s) / m.opt.timestep)
        self._set_hold(airborne or self.hold_until > 0)
        for _ in range(n_settle):
            mujoco.mj_step(m, d)
        if self.hold_until <= 0:
            self._set_hold(False)
        d.qvel[sc.object_dof_adr : sc.object_dof_adr + 6] = 0.0
        mujoco.mj_forward(m, d)
        self.warnings.update(d, 0)
        acc = FrameAccumulator(1)
        acc.add(read_contacts(sc, d), d.xipos[sc.object_body].copy())
        self._record(finish_frame(acc), self.ctrl_ref[0], np.zeros(self.action_dim))

    def _set_hold(self, on: bool) -> None:
        """Hold the object at its first reference pose by the weld (in the scene's data and the
        rollouts'), or let it go."""
        sc = self.scene
        for d in (sc.data, self.rollout_data):
            if on:
                d.mocap_pos[sc.anchor_mocap] = self.ref.object_pos[0]
                d.mocap_quat[sc.anchor_mocap] = self.ref.object_quat[0]
            d.eq_active[sc.weld_eq] = int(on)
        self._holding = on

    def state(self) -> np.ndarray:
        mujoco.mj_getState(self.scene.model, self.scene.data, self._state, self._state_spec)
        return self._state.copy()

    def observation(self) -> dict[str, np.ndarray]:
        """What a learned policy sees: hand and object state, the next reference frames."""
        sc, d = self.scene, self.scene.data
        t1 = min(self.t + 1, self.ref.num_frames - 1)
        p, q = sc.object_pose()
        return {
            "hand_qpos": d.qpos[sc.hand.qpos_adr].copy(),
            "hand_qvel": d.qvel[sc.hand.dof_adr].copy(),
            "object_pos": p,
            "object_quat": q,
            "object_vel": d.qvel[sc.object_dof_adr : sc.object_dof_adr + 6].copy(),
            "ref_ctrl_next": self.ctrl_ref[t1].copy(),
            "ref_object_pos_next": self.ref.object_pos[t1].copy(),
            "ref_object_quat_next": self.ref.object_quat[t1].copy(),
            "residual": self.u.copy(),
        }

    @property
    def done(self) -> bool:
        return self.failed_at is not None or self.t >= self.ref.num_frames - 1

    # -- controls -------------------------------------------------------------------------

    def _clip(self, ctrl: np.ndarray) -> np.ndarray:
        return np.clip(ctrl, self.ctrl_low, self.ctrl_high)

    def plan_controls(self, actions: np.ndarray) -> np.ndarray:
        """Per-physics-step controls ``(K, H·substeps, nu)`` for action plans ``(K, H, 11)``
        starting at the current frame and residual."""
        K, H, _ = actions.shape
        T = self.ref.num_frames
        u = np.broadcast_to(self.u, (K, self.action_dim)).copy()
        tau = self.cfg.tau
        ctrl = np.empty((K, H, self.scene.model.nu))
        act_ids = self.scene.hand.actuator
        for h in range(H):
            u = np.clip(tau * u + actions[:, h], -1.0, 1.0)
            f = min(self.t + 1 + h, T - 1)
            target = self.ctrl_ref[f] + self.offset(f, u)
            ctrl[:, h][:, act_ids] = self._clip(target)
        return np.repeat(ctrl, self.scene.substeps, axis=1)

    def rollout_object_poses(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Object position and quaternion ``(K, H, 7)`` and fingertips in the object frame
        ``(K, H, 5, 3)`` at the end of each planned frame."""
        sc = self.scene
        ctrl = self.plan_controls(actions)
        state, sens = mj_rollout.rollout(
            sc.model,
            self.rollout_data,
            self.state()[None],
            ctrl,
            initial_warmstart=sc.data.qacc_warmstart[None].copy(),
        )
        a = 1 + sc.object_qpos_adr  # state = [time, qpos, qvel, ...]
        k = slice(sc.substeps - 1, None, sc.substeps)
        a0 = self.tip_sensor_adr
        tips = sens[:, k, a0 : a0 + 3 * self.n_tips].reshape(*sens[:, k].shape[:2], self.n_tips, 3)
        return state[:, k, a : a + 7], tips

    def rewards(self, poses: np.ndarray, tips: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """``(K, H)`` per-frame rewards of rollouts (from :meth:`rollout_object_poses`)."""
        H = poses.shape[1]
        T = self.ref.num_frames
        idx = np.minimum(self.t + 1 + np.arange(H), T - 1)
        e_p = np.linalg.norm(poses[..., :3] - self.ref.object_pos[idx], axis=-1)
        e_r = quat_angle(poses[..., 3:], self.ref.object_quat[idx])
        c = self.cfg
        r = np.exp(-c.reward_pos_k * e_p) + c.reward_rot_w * np.exp(-c.reward_rot_k * e_r)
        r -= c.action_penalty * np.sum(actions**2, axis=-1)
        if c.contact_reward:
            w = self.tip_weight[idx]  # (H, 5)
            dist = np.linalg.norm(tips - self.ref.tips_object[idx], axis=-1)  # (K, H, 5)
            r += c.contact_reward * np.sum(w * np.exp(-c.contact_k * dist), axis=-1) / self.n_tips
        if c.residual_penalty:
            u = np.broadcast_to(self.u, actions[:, 0].shape).copy()
            for h in range(H):
                u = np.clip(c.tau * u + actions[:, h], -1.0, 1.0)
                r[:, h] -= c.residual_penalty * np.sum(u * u, axis=-1)
        # a rollout that loses the object earns nothing afterwards
        lost = np.cumsum(e_p > c.fail_pos_m, axis=1) > 0
        return np.where(lost, -1.0, r)

    # -- stepping -------------------------------------------------------------------------

    def step(self, a: np.ndarray) -> float:
        """Advance one data frame with residual action ``a (11,)``; returns the reward."""
        if self.done:
            raise ValidationError("the tracking episode is over; call reset()")
        a = np.asarray(a, dtype=np.float64).reshape(self.action_dim)
        if not np.isfinite(a).all():
            raise ValidationError("tracker returned a non-finite action", field="action")
        sc = self.scene
        m, d = sc.model, sc.data
        self.u = np.clip(self.cfg.tau * self.u + a, -1.0, 1.0)
        if self._holding and self.t + 1 >= self.hold_until:
            self._set_hold(False)  # the demonstration starts moving the object
        target = self.ctrl_ref[self.t + 1] + self.offset(self.t + 1, self.u)
        d.ctrl[sc.hand.actuator] = self._clip(target)
        acc = FrameAccumulator(sc.substeps)
        for _ in range(sc.substeps):
            com = d.xipos[sc.object_body].copy()
            mujoco.mj_step(m, d)
            acc.add(read_contacts(sc, d), com)
        self.t += 1
        self.warnings.update(d, self.t)
        err = self._record(finish_frame(acc), target, a)
        if err > self.cfg.fail_pos_m and self.failed_at is None:
            self.failed_at = self.t
        c = self.cfg
        return float(
            np.exp(-c.reward_pos_k * err)
            + np.exp(-c.reward_rot_k * self.log.rot_err[-1])
            - c.action_penalty * a @ a
        )

    def _record(self, fc: FrameContacts, target: np.ndarray, a: np.ndarray) -> float:
        sc, d = self.scene, self.scene.data
        p, q = sc.object_pose()
        err = float(np.linalg.norm(p - self.ref.object_pos[self.t]))
        log = self.log
        log.object_pos.append(p)
        log.object_quat.append(q)
        log.pos_err.append(err)
        log.rot_err.append(float(quat_angle(q, self.ref.object_quat[self.t])))
        log.hand_qpos.append(d.qpos[sc.hand.qpos_adr].copy())
        log.ctrl.append(target.copy())
        log.action.append(a.copy())
        log.contacts.append(fc)
        log.object_acc.append(_com_acceleration(sc, d))
        log.poses.append(_frame_poses(sc, d, fc))
        return err


@dataclass
class TrackLog:
    """Per-frame records of a tracking episode."""

    object_pos: list = field(default_factory=list)
    object_quat: list = field(default_factory=list)
    pos_err: list = field(default_factory=list)
    rot_err: list = field(default_factory=list)
    hand_qpos: list = field(default_factory=list)
    ctrl: list = field(default_factory=list)
    action: list = field(default_factory=list)
    contacts: list = field(default_factory=list)
    object_acc: list = field(default_factory=list)
    poses: list = field(default_factory=list)


def _quat_to_R(q: np.ndarray) -> np.ndarray:
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, np.asarray(q, dtype=np.float64))
    return R.reshape(3, 3)


def _com_acceleration(sc, d: mujoco.MjData) -> np.ndarray:
    """Linear acceleration [m/s²] of the object's COM from the last step's ``qacc``."""
    v = sc.object_dof_adr
    a_o = d.qacc[v : v + 3]
    R = d.xmat[sc.object_body].reshape(3, 3)
    w = R @ d.qvel[v + 3 : v + 6]  # free joint angular velocity/acceleration are body-local
    alpha = R @ d.qacc[v + 3 : v + 6]
    r = d.xipos[sc.object_body] - d.xpos[sc.object_body]
    return a_o + np.cross(alpha, r) + np.cross(w, np.cross(w, r))


def _frame_poses(sc, d: mujoco.MjData, fc: FrameContacts) -> FramePoses:
    m = sc.model
    R_body, p_body = {}, {}
    for g in fc.hand_geom:
        b = m.geom_bodyid[g]
        R_body[int(g)] = d.xmat[b].reshape(3, 3).copy()
        p_body[int(g)] = d.xpos[b].copy()
    return FramePoses(
        R_wrist=d.xmat[sc.hand.palm_body].reshape(3, 3).copy(),
        p_wrist=d.xpos[sc.hand.palm_body].copy(),
        R_obj=d.xmat[sc.object_body].reshape(3, 3).copy(),
        p_obj=d.xpos[sc.object_body].copy(),
        R_body=R_body,
        p_body=p_body,
    )
