"""Physics refinement: the force pipeline's sampling MPC run on the robot hand itself.

For pairs whose open-loop replay fails (the object slips or falls), the retargeted servo
commands become the *reference* of the tracker of :mod:`dexcanvas_core.sim.tracker`, in the
robot's own scene (its actuators, the object free on the table, the re-simulation's contact
settings). The residual action is the wrist pose (3 × 3 cm, 3 × 0.15 rad) plus one action per
robot finger: a scale on its force-matching / squeeze offset (``u_f = +1`` presses three times
as hard, ``−½`` not at all: ``RefineConfig.offset_gain``) plus, on the frames where its human
finger touches, a joint step moving its fingertip ``finger_close_m`` towards the object's
origin (``−1``: away). The reward is the tracker's (object pose, the robot fingertips staying
where the retargeting put them relative to the object on contact frames, action and residual
size).

The refined commands are what the rollout executed; :class:`RefineResult` says how far they
moved from the retargeted ones (joint deviation), so users see what physics cost.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, fields, replace

import mujoco
import numpy as np

from dexcanvas_core.rotations import aa_to_quat_wxyz
from dexcanvas_core.sim.mpc import MPCConfig, OpenLoop, SamplingMPC, track
from dexcanvas_core.sim.scene import (
    OBJECT_ANCHOR,
    OBJECT_BODY,
    PhysicsSettings,
    SimScene,
    add_object,
    add_table,
)
from dexcanvas_core.sim.signal import moving_average
from dexcanvas_core.sim.tracker import TrackingConfig, TrackingEnv
from dexcanvas_core.table import DEFAULT_TABLE, Table, table_of
from dexcanvas_core.trajectory import CONTACT_PARTS
from retarget.errors import RetargetError
from retarget.hands.base import WRIST_BODY


@dataclass(frozen=True)
class RefineConfig:
    tracker: str = "mpc"
    """``mpc``, or ``open_loop`` (the retargeted commands replayed in the same scene: the
    baseline the refinement is measured against)."""
    mpc: MPCConfig = field(default_factory=MPCConfig)
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    scale_pos_m: float = 0.03
    scale_rot_rad: float = 0.15
    contact_timeconst: float | None = 0.005
    """Contact solref time constant [s] (the force-matching re-simulation's); None: defaults."""
    max_timestep_s: float = 0.0025
    retries: int = 4
    """``mpc``: when the object is lost, go back ``backtrack_s`` × the attempt number before
    the failure (to the last checkpoint there) and track again from that physics state with a
    new random stream and ``retry_samples`` × as many samples as the last attempt; up to this
    many times (0: one attempt, no backtracking). Measured on the force-preservation
    benchmark's cached human simulations (five-finger hands and LEAP, the 69 runs whose (d)
    replay fails): 0 retries rescue 17 (6.3 s per refinement), 2 retries with 1.5× samples 24
    (13.1 s); one attempt with 48 samples 22 (20.4 s), with a 0.4 s horizon and 4 knots 22
    (14.0 s), with 2× the sampling noise 13. 4 retries (2026-12-04, the 41 such runs whose
    refinement still failed at 2): 4 more rescued, 38 s of CPU per refinement on those runs
    instead of 12 s (README, force preservation). With ``finger_close_m`` (2026-12-04, the
    five-finger hands and LEAP, ``--variants e`` on the cached human simulations), 2 → 4
    retries: five-finger (e) strict success 83.0 → 87.5 %, LEAP 78.6 → 82.1 %, CPU per
    refinement 14.8 → 24.2 s on average (13.4 → 39.1 s on those that still fail); so 4.
    6 retries (2026-12-06, five-finger hands, the same runs): 2 of the 8 that failed at 4
    rescued (92.6 → 94.4 %; paired heavy / light 86.1 / 100 → 88.9 / 100 %), CPU per
    refinement 23.8 → 40.8 s on average (40.0 → 130.9 s on the 6 that still fail, their last
    attempts losing the object at frames 305–397 as at 4); kept at 4."""
    finger_close_m: float = 0.04
    """Each finger's action also moves its fingertip this far [m] towards the object's origin
    (its frame's; the centre of a primitive) at ``u_f = 1`` (away at ``−1``; first order,
    damped least squares over the finger's servoed joints) on the frames where its human
    finger touches. With the force offset
    alone (0) a finger the plan presses lightly, or one the re-simulation leaves short of the
    object, cannot be brought onto it. Measured on the force-preservation benchmark's cached
    human simulations (Shadow, Ability, Inspire, SVH and LEAP, ``--variants e``; (d) replays
    unchanged), five-finger (e) strict success at 0 / 0.5 / 1 / 2 / 4 / 8 cm: 70.5 / 72.3 /
    75.0 / 81.2 / 83.0 / 83.9 %; at 4 cm 13.2 → 14.8 s of CPU per refinement, the fingers'
    commands 0.002 → 0.012 rad from the retargeted ones on average (8 cm: 0.020 rad, one more
    lift; README, force preservation)."""
    offset_gain: float = 2.0
    """Each finger's action scales its force-matching / squeeze offset by ``1 + offset_gain ·
    u_f`` (at 2, ``u_f = +1`` presses three times as hard, ``−½`` not at all). The sampled
    residual seldom reaches ±1 (smoothed, ``τ`` = 0.9), so this sets how far the search
    reaches. Measured 2026-12-05 on the force-preservation benchmark's cached human
    simulations (``--hands shadow ability inspire svh leap --variants d e --refine-set
    offset_gain=G``; the same 58 refined runs): five-finger (e) strict success at 1 / 2 / 3:
    89 / 92 / 91 % (n = 108; 5 gained and 1 lost at 2, 4 and 1 at 3), paired heavy / light
    81 / 94 → 83 / 97 %, the fingers' commands 0.0097 / 0.0133 / 0.0152 rad from the
    retargeted ones on average; so 2."""
    backtrack_s: float = 0.5
    retry_samples: float = 1.5
    checkpoint_s: float = 0.1
    """Checkpoint spacing [s] of the backtracking (physics state, residual, plan)."""


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


@dataclass
class RefineResult:
    success: bool
    failed_at_frame: int | None
    object_pos_err: np.ndarray
    object_rot_err: np.ndarray
    ctrl: np.ndarray
    """(T, nu) the refined servo commands (actuator order)."""
    ctrl_reference: np.ndarray
    finger_ctrl_deviation_rad: float
    wrist_pos_deviation_m: float
    wrist_rot_deviation_rad: float
    compute_s: float
    attempts: int = 1
    """Tracking attempts (1 + the backtracking retries used)."""
    calibration: dict | None = None
    """:func:`calibrate_refined`'s ``ForceCalibrationResult.metrics()`` when the refined
    commands were force-calibrated (``ctrl`` and the errors and forces are then the chosen
    iterate's)."""
    finger_force_world: np.ndarray | None = None
    """(T_tracked, F + 1, 3) [N]: force of each robot finger (``fingers`` order) and the palm
    on the object in the refined simulation, world frame, averaged over the frame's physics
    steps (the re-simulation's ``ValidationResult.finger_force_world`` layout)."""
    fingers: list[str] = field(default_factory=list)

    def metrics(self) -> dict:
        return {
            "success": self.success,
            "failed_at_frame": self.failed_at_frame,
            "frames_tracked": int(self.object_pos_err.shape[0]),
            "object_pos_err_max_m": float(self.object_pos_err.max()),
            "object_pos_err_mean_m": float(self.object_pos_err.mean()),
            "object_rot_err_mean_rad": float(self.object_rot_err.mean()),
            "finger_ctrl_deviation_mean_rad": self.finger_ctrl_deviation_rad,
            "wrist_pos_deviation_mean_m": self.wrist_pos_deviation_m,
            "wrist_rot_deviation_mean_rad": self.wrist_rot_deviation_rad,
            "compute_s": self.compute_s,
            "attempts": self.attempts,
            **({} if self.calibration is None else {"calibration": self.calibration}),
            **(
                {}
                if self.finger_force_world is None
                else {
                    "finger_force_mean_n": {
                        f: float(np.linalg.norm(self.finger_force_world[:, i], axis=1).mean())
                        for i, f in enumerate([*self.fingers, "palm"])
                    }
                }
            ),
        }


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


def refine(hand, geometry, human, robot, tip_sites: list[str], cfg: RefineConfig | None = None):
    """Refine ``robot`` (a ``RobotTrajectory`` of ``human``) by sampling MPC (module doc)."""
    cfg = RefineConfig() if cfg is None else cfg
    if cfg.tracker not in ("mpc", "open_loop"):
        raise RetargetError(f"unknown refinement tracker {cfg.tracker!r}; use mpc or open_loop")
    if not (
        cfg.retries >= 0 and cfg.backtrack_s > 0 and cfg.retry_samples >= 1 and cfg.checkpoint_s > 0
    ):
        raise RetargetError(
            "refinement backtracking: retries must be >= 0, backtrack_s and checkpoint_s > 0 "
            f"[s], retry_samples >= 1 (got {cfg.retries}, {cfg.backtrack_s}, "
            f"{cfg.checkpoint_s}, {cfg.retry_samples})"
        )
    env, act_q, ctrl_ref = _tracking_env(hand, geometry, human, robot, tip_sites, cfg)
    m, T = env.scene.model, human.num_frames
    t0 = time.process_time()
    if cfg.tracker == "mpc":
        log, attempts = _track_backtracking(env, cfg)
    else:
        log, attempts = track(env, OpenLoop()), 1
    cpu = time.process_time() - t0
    ctrl = np.asarray(log.ctrl)
    Tt = ctrl.shape[0]
    dev = np.abs(ctrl - ctrl_ref[:Tt])
    wrist_pos = [a for a in range(m.nu) if act_q[a] < 3]
    wrist_rot = [a for a in range(m.nu) if 3 <= act_q[a] < 6]
    fingers = [a for a in range(m.nu) if act_q[a] >= 6]
    pos_err = np.asarray(log.pos_err)
    robot_fingers = list(hand.robot_fingers)
    return RefineResult(
        success=env.failed_at is None and Tt == T and bool((pos_err <= 0.05).all()),
        failed_at_frame=env.failed_at,
        object_pos_err=pos_err,
        object_rot_err=np.asarray(log.rot_err),
        ctrl=ctrl,
        ctrl_reference=ctrl_ref,
        finger_ctrl_deviation_rad=float(dev[:, fingers].mean()) if fingers else 0.0,
        wrist_pos_deviation_m=float(np.linalg.norm(dev[:, wrist_pos], axis=1).mean()),
        wrist_rot_deviation_rad=float(np.linalg.norm(dev[:, wrist_rot], axis=1).mean()),
        compute_s=cpu,
        attempts=attempts,
        finger_force_world=_finger_forces(hand, m, robot_fingers, log.contacts),
        fingers=robot_fingers,
    )


def calibrate_refined(
    hand, geometry, human, robot, tip_sites: list[str], refined: RefineResult,
    cfg: RefineConfig | None = None, calibration=None, force_scale: float = 1.0,
) -> RefineResult:  # fmt: skip
    """Force calibration (:mod:`retarget.force_calibration`) of a refinement's servo targets in
    its own scene: the refined targets ``refined.ctrl`` replayed open loop (the tracker with no
    residual), each robot finger's force compared with the human's (``robot.human_force`` ×
    ``force_matching.scale``), each finger's targets corrected, ``calibration.iterations`` times
    (a ``ForceCalibrationConfig``). Iterate 0 is the refinement's own rollout; the result is
    ``refined`` with the chosen iterate's targets, errors and forces, and ``calibration`` set
    (its ``compute_s`` added). ``cfg``: the refinement's configuration (its scene)."""
    from types import SimpleNamespace

    from retarget.force_calibration import (
        ForceCalibrationConfig,
        calibrate,
        correction,
        human_target,
    )

    cfg = RefineConfig() if cfg is None else cfg
    ccfg = (calibration or ForceCalibrationConfig()).validate()
    target = human_target(robot, force_scale)
    env, act_q, _ = _tracking_env(hand, geometry, human, robot, tip_sites, cfg)
    m, T, nq = env.scene.model, human.num_frames, robot.q.shape[1]
    fingers = list(hand.robot_fingers)
    col = [fingers.index(hand.fingers[f]) for f in _human_fingers(hand, tip_sites)]
    n_smooth = max(1, round(ccfg.smooth_s * human.fps))

    def simulate(ctrl):
        env.ctrl_ref = ctrl
        log = track(env, OpenLoop())
        pe = np.asarray(log.pos_err)
        return SimpleNamespace(
            success=env.failed_at is None and pe.shape[0] == T and bool((pe <= 0.05).all()),
            first_failure_frame=env.failed_at,
            object_pos_err=pe,
            object_rot_err=np.asarray(log.rot_err),
            finger_force_world=_finger_forces(hand, m, fingers, log.contacts),
        )

    def step(ctrl, realized, frames):
        dq = correction(
            m, nq, robot.q, tip_sites, target, realized, ccfg.gain, n_smooth, ccfg.tolerance_n,
            frames,
        )  # fmt: skip
        return np.clip(ctrl + dq[:, act_q], env.ctrl_low, env.ctrl_high)

    rollout = SimpleNamespace(  # iterate 0: the refinement's own rollout
        success=refined.success, first_failure_frame=refined.failed_at_frame,
        object_pos_err=refined.object_pos_err, object_rot_err=refined.object_rot_err,
        finger_force_world=refined.finger_force_world,
    )  # fmt: skip
    finger_acts = act_q >= 6
    n = ccfg.iterations
    cal = calibrate(simulate, step, refined.ctrl, rollout, target, col, n, finger_acts)
    s = cal.sim
    ref_dev = np.abs(cal.commands - refined.ctrl_reference[: len(cal.commands)])[:, finger_acts]
    return replace(
        refined,
        finger_ctrl_deviation_rad=float(ref_dev.mean()) if ref_dev.size else 0.0,
        success=cal.success,
        failed_at_frame=s.first_failure_frame,
        object_pos_err=np.asarray(s.object_pos_err),
        object_rot_err=np.asarray(s.object_rot_err),
        ctrl=np.asarray(cal.commands),
        finger_force_world=s.finger_force_world,
        compute_s=refined.compute_s + cal.compute_s,
        calibration=cal.metrics(),
    )


def _finger_forces(hand, m: mujoco.MjModel, fingers: list[str], contacts) -> np.ndarray:
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


def _tracking_env(hand, geometry, human, robot, tip_sites, cfg: RefineConfig):
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
    for rf in (hand.fingers[f] for f in _human_fingers(hand, tip_sites)):
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
    from retarget.limits.coupling import CouplingLimit, servo_follower_map

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


@dataclass
class _Checkpoint:
    """What :func:`_restore` needs to resume tracking at frame ``t``."""

    t: int
    state: np.ndarray  # mjSTATE_FULLPHYSICS
    warmstart: np.ndarray
    ctrl: np.ndarray
    u: np.ndarray
    log_len: int
    plan: np.ndarray
    plan_t: int


def _checkpoint(env: TrackingEnv, mpc: SamplingMPC) -> _Checkpoint:
    d = env.scene.data
    return _Checkpoint(
        t=env.t, state=env.state(), warmstart=d.qacc_warmstart.copy(), ctrl=d.ctrl.copy(),
        u=env.u.copy(), log_len=len(env.log.pos_err), plan=mpc.plan.copy(), plan_t=mpc.plan_t,
    )  # fmt: skip


def _restore(env: TrackingEnv, mpc: SamplingMPC, c: _Checkpoint) -> None:
    """Put ``env`` (physics, residual, frame, log) and ``mpc``'s plan back to ``c``."""
    m, d = env.scene.model, env.scene.data
    mujoco.mj_setState(m, d, c.state, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    d.qacc_warmstart[:] = c.warmstart
    d.ctrl[:] = c.ctrl
    mujoco.mj_forward(m, d)
    d.qacc_warmstart[:] = c.warmstart  # mj_forward's solve overwrote it
    env.t, env.u, env.failed_at = c.t, c.u.copy(), None
    for f in fields(env.log):
        del getattr(env.log, f.name)[c.log_len :]
    mpc.plan, mpc.plan_t = c.plan.copy(), c.plan_t


def _track_backtracking(env: TrackingEnv, cfg: RefineConfig) -> tuple[object, int]:
    """The sampling MPC (the core's ``track`` loop) with backtracking
    (``RefineConfig.retries``; 0: plain tracking): ``(log, attempts)``.

    Failing (d) replays mostly lose the object 0.15–0.3 s after the human's lift-off (README,
    force preservation), so attempt ``k`` resumes from the last checkpoint ``k · backtrack_s``
    before the failure, with a new random stream and ``retry_samples^k`` × the samples."""
    mpc = SamplingMPC(cfg.mpc)
    env.reset()
    mpc.reset(env)
    every = max(1, round(cfg.checkpoint_s * env.ref.fps))
    snaps: dict[int, _Checkpoint] = {}
    attempts = 1
    while True:
        while not env.done:
            if cfg.retries and env.t % every == 0:
                snaps[env.t] = _checkpoint(env, mpc)
            env.step(mpc.act(env))
        if env.failed_at is None or attempts > cfg.retries:
            return env.log, attempts
        back = env.failed_at - round(attempts * cfg.backtrack_s * env.ref.fps)
        t_back = max((t for t in snaps if t <= back), default=0)  # frame 0 is always kept
        _restore(env, mpc, snaps[t_back])
        for t in [t for t in snaps if t > t_back]:
            del snaps[t]
        mpc.cfg = replace(
            cfg.mpc, samples=max(2, round(cfg.mpc.samples * cfg.retry_samples**attempts))
        )
        mpc.rng = np.random.default_rng([cfg.mpc.seed, attempts, t_back])
        attempts += 1


def _human_fingers(hand, tip_sites: list[str]) -> list[str]:
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
