"""The physics refinement's scene and tracking problem (:mod:`retarget.refine`): the robot
hand with its actuators and the object free on the table, the reference the tracker follows
(the human object motion, the retargeted fingertips relative to the object), and the residual
action basis (wrist pose, per-finger offset scale and closing step)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from dexcanvas_core.rotations import aa_to_quat_wxyz
from dexcanvas_core.sim.scene import (
    OBJECT_ANCHOR,
    OBJECT_BODY,
    PhysicsSettings,
    SimScene,
    add_object,
    add_table,
)
from dexcanvas_core.sim.signal import moving_average
from dexcanvas_core.sim.tracker import TrackingEnv
from dexcanvas_core.table import DEFAULT_TABLE, Table, table_of
from dexcanvas_core.trajectory import CONTACT_PARTS
from retarget.errors import RetargetError
from retarget.hands.base import WRIST_BODY
from retarget.limits.coupling import CouplingLimit, servo_follower_map

if TYPE_CHECKING:
    from retarget.refine import RefineConfig


@dataclass
class _Plant:
    """The robot hand's ids in the refinement scene (the tracker's ``scene.hand``)."""

    qpos_adr: np.ndarray
    dof_adr: np.ndarray
    actuator: np.ndarray
    ctrl_low: np.ndarray
    ctrl_high: np.ndarray
    geom_part: dict
    tip_sites: np.ndarray
    palm_body: int


@dataclass
class _Reference:
    fps: float
    object_pos: np.ndarray
    object_quat: np.ndarray
    tips_object: np.ndarray

    @property
    def num_frames(self) -> int:
        return self.object_pos.shape[0]


def _part_of(human_finger: str | None) -> str:
    if human_finger is None:
        return "palm"
    return "thumb_ip" if human_finger == "thumb" else f"{human_finger}_dip"


def build_refine_scene(
    hand,
    geometry,
    fps: float,
    cfg: RefineConfig,
    tip_sites: list[str],
    table: Table = DEFAULT_TABLE,
):
    """The robot hand + free object + ``table``, a weld anchor, fingertip-in-object sensors."""
    spec = hand.build_spec()
    substeps = max(1, int(np.ceil(1.0 / (fps * cfg.max_timestep_s) - 1e-9)))
    spec.option.timestep = 1.0 / (fps * substeps)
    add_table(spec, table)
    add_object(spec, geometry, mocap=False)
    anchor = spec.worldbody.add_body(name=OBJECT_ANCHOR, mocap=True)
    anchor.add_site(name="object_anchor_site", size=[0.002, 0, 0])
    eq = spec.add_equality(
        name="object_hold", type=mujoco.mjtEq.mjEQ_WELD, objtype=mujoco.mjtObj.mjOBJ_BODY,
        name1=OBJECT_BODY, name2=OBJECT_ANCHOR,
    )  # fmt: skip
    eq.active = False
    first_sensor = len(spec.sensors)
    for i, s in enumerate(tip_sites):  # a gripper lists one robot finger for two human ones
        spec.add_sensor(
            name=f"refine_{i}_{s}", type=mujoco.mjtSensor.mjSENS_FRAMEPOS,
            objtype=mujoco.mjtObj.mjOBJ_SITE, objname=s,
            reftype=mujoco.mjtObj.mjOBJ_BODY, refname=OBJECT_BODY,
        )  # fmt: skip
    if cfg.contact_timeconst is not None:
        spec.option.enableflags |= mujoco.mjtEnableBit.mjENBL_OVERRIDE
        spec.option.o_solref = [cfg.contact_timeconst, 1.0]
        spec.option.o_margin = 0.0
    m = spec.compile()
    obj = m.body(OBJECT_BODY).id
    jnt = m.body_jntadr[obj]
    obj_q = int(m.jnt_qposadr[jnt])
    hand_joints = [j for j in range(m.njnt) if m.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE]
    parts = hand.hand_parts(m)
    robot_to_human = {r: h for h, r in hand.fingers.items() if r is not None}
    geom_part = {}
    for finger, bodies in parts.items():
        part = _part_of(robot_to_human.get(finger)) if finger != "palm" else "palm"
        assert part in CONTACT_PARTS
        ids = {m.body(b).id for b in bodies}
        for g in range(m.ngeom):
            if m.geom_bodyid[g] in ids and (m.geom_contype[g] or m.geom_conaffinity[g]):
                geom_part[g] = part
    lo = np.where(m.actuator_ctrllimited, m.actuator_ctrlrange[:, 0], -np.inf)
    hi = np.where(m.actuator_ctrllimited, m.actuator_ctrlrange[:, 1], np.inf)
    plant = _Plant(
        qpos_adr=np.array([m.jnt_qposadr[j] for j in hand_joints], dtype=np.int64),
        dof_adr=np.array([m.jnt_dofadr[j] for j in hand_joints], dtype=np.int64),
        actuator=np.arange(m.nu),
        ctrl_low=lo,
        ctrl_high=hi,
        geom_part=geom_part,
        tip_sites=np.array([m.site(s).id for s in tip_sites]),
        palm_body=m.body(WRIST_BODY).id,
    )
    scene = SimScene(
        model=m,
        data=mujoco.MjData(m),
        hand=plant,
        geometry=geometry,
        object_body=obj,
        object_qpos_adr=obj_q,
        object_dof_adr=int(m.jnt_dofadr[jnt]),
        object_geoms=np.flatnonzero(m.geom_bodyid == obj),
        table_geom=m.geom("table").id,
        anchor_mocap=int(m.body_mocapid[m.body(OBJECT_ANCHOR).id]),
        weld_eq=m.equality("object_hold").id,
        fps=fps,
        physics=PhysicsSettings(substeps=substeps, max_timestep_s=cfg.max_timestep_s),
        table=table,
    )
    return scene, int(m.sensor_adr[first_sensor]) if tip_sites else 0


def finger_forces(hand, m: mujoco.MjModel, fingers: list[str], contacts) -> np.ndarray:
    """(len(contacts), F + 1, 3) [N]: per frame, the summed force of each robot finger's
    bodies (``fingers`` order, then the palm) on the object, from the tracker's per-frame
    hand–object contact pairs (``FrameContacts``)."""
    parts = hand.hand_parts(m)
    body_part = np.full(m.nbody, -1)
    for i, f in enumerate([*fingers, "palm"]):
        for b in parts.get(f, []):
            body_part[m.body(b).id] = i
    out = np.zeros((len(contacts), len(fingers) + 1, 3))
    for t, fc in enumerate(contacts):
        part = body_part[m.geom_bodyid[fc.hand_geom]]
        keep = part >= 0
        np.add.at(out[t], part[keep], fc.force[keep])
    return out


def tracking_env(hand, geometry, human, robot, tip_sites, cfg: RefineConfig):
    """The tracker's environment for ``robot`` on ``human``: ``(env, act_q, ctrl_ref)``."""
    if not human.objects:
        raise RetargetError("refinement needs a demonstration with an object")
    scene, adr = build_refine_scene(hand, geometry, human.fps, cfg, tip_sites, table_of(human))
    m = scene.model
    act_q = np.array([m.jnt_qposadr[m.actuator_trnid[a, 0]] for a in range(m.nu)])
    if (m.actuator_trntype != mujoco.mjtTrn.mjTRN_JOINT).any():
        raise RetargetError(f"refinement supports joint-driven servos only ({hand.name})")
    T = human.num_frames
    ctrl_ref = robot.q_command[:, act_q]
    offsets = (robot.q_command - robot.q)[:, act_q]
    F = len(tip_sites)
    basis = np.zeros((T, m.nu, 6 + F))
    for a in range(m.nu):
        if act_q[a] < 6:
            basis[:, a, act_q[a]] = cfg.scale_pos_m if act_q[a] < 3 else cfg.scale_rot_rad
    parts = hand.hand_parts(m)
    finger_acts = []  # per tip site, the actuators of its robot finger
    for rf in (hand.fingers[f] for f in human_fingers(hand, tip_sites)):
        ids = {m.body(b).id for b in parts.get(rf, [])}
        finger_acts.append([a for a in range(m.nu) if m.jnt_bodyid[m.actuator_trnid[a, 0]] in ids])
    for i, acts in enumerate(finger_acts):
        basis[:, acts, 6 + i] = cfg.offset_gain * offsets[:, acts]
    R_o = np.stack([_rotm(q) for q in aa_to_quat_wxyz(human.object.rot_aa.astype(np.float64))])
    p_o = human.object.pos.astype(np.float64)
    if cfg.finger_close_m > 0:
        _add_closing(basis, m, robot, tip_sites, finger_acts, p_o, cfg.finger_close_m)
    tips_obj = np.einsum("tji,tfj->tfi", R_o, robot.tip_pos_world - p_o[:, None])
    w = moving_average(robot.contact_active.astype(np.float64), max(1, round(0.1 * human.fps)))
    ref = _Reference(
        fps=human.fps,
        object_pos=p_o,
        object_quat=aa_to_quat_wxyz(human.object.rot_aa.astype(np.float64)),
        tips_object=tips_obj,
    )
    env = TrackingEnv(
        scene, ref, cfg.tracking, ctrl_ref=ctrl_ref, basis=basis, tip_weight=w,
        qpos0=robot.q_command[0], tip_sensor_adr=adr,
    )  # fmt: skip
    return env, act_q, ctrl_ref


def _add_closing(basis, m, robot, tip_sites, finger_acts, p_o, close_m: float) -> None:
    """``finger_close_m``: add to each finger's action column ``basis[:, :, 6 + i]`` the joint
    step that moves its fingertip ``close_m`` [m] towards the object's origin ``p_o`` (T, 3),
    on the frames where its human finger touches: damped least squares over the finger's
    servoed joints (``finger_acts[i]``), ``Δq = Jᵀ (J Jᵀ + λ I)⁻¹ δ`` with ``λ = 10⁻⁴ m²`` (a
    finger's ``J Jᵀ`` is ~(5 cm)² along its reach; near a singular posture the step stays short
    instead of large). ``J`` is the fingertip's Jacobian through the joints the servos drive,
    their coupled joints included (``CouplingLimit.follower_map``, as the retargeter's
    squeeze). One kinematics pass per frame serves every finger."""
    d = mujoco.MjData(m)
    jacp = np.zeros((3, m.nv))
    nq = robot.q.shape[1]
    coupling = CouplingLimit.from_mjmodel(m)
    sites = [m.site(s).id for s in tip_sites]
    dofs = [[int(m.jnt_dofadr[m.actuator_trnid[a, 0]]) for a in acts] for acts in finger_acts]
    touching = robot.contact_active
    C = servo_follower_map(m, robot.q[0], nq, coupling)
    for t in np.flatnonzero(touching.any(axis=1)):
        d.qpos[:nq] = robot.q[t]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)  # (the Jacobians need cdof)
        if not coupling.linear:
            C = servo_follower_map(m, robot.q[t], nq, coupling)
        for i in np.flatnonzero(touching[t]):
            if not finger_acts[i]:
                continue
            mujoco.mj_jacSite(m, d, jacp, None, sites[i])
            J = (jacp[:, :nq] @ C)[:, dofs[i]]
            u = p_o[t] - d.site_xpos[sites[i]]
            u *= close_m / max(float(np.linalg.norm(u)), 1e-9)
            basis[t, finger_acts[i], 6 + i] += J.T @ np.linalg.solve(J @ J.T + 1e-4 * np.eye(3), u)


def human_fingers(hand, tip_sites: list[str]) -> list[str]:
    """The human finger of each tip site (``{robot_finger}_tip_site``), in order."""
    robot_to_human = {r: h for h, r in hand.fingers.items() if r is not None}
    out = []
    for s in tip_sites:
        rf = s.removesuffix("_tip_site")
        if rf not in robot_to_human:
            raise RetargetError(f"tip site {s!r} belongs to no mapped finger of {hand.name}")
        out.append(robot_to_human[rf])
    return out


def _rotm(q: np.ndarray) -> np.ndarray:
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, q)
    return R.reshape(3, 3)
