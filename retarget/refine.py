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

import copy
import time
from dataclasses import dataclass, field, fields, replace
from types import SimpleNamespace

import mujoco
import numpy as np

from dexcanvas_core.checks import check_fields
from dexcanvas_core.sim.mj_warnings import WarningCounter
from dexcanvas_core.sim.mpc import MPCConfig, OpenLoop, SamplingMPC, track
from dexcanvas_core.sim.tracker import TrackingConfig, TrackingEnv
from retarget.errors import RetargetError
from retarget.force_calibration import ForceCalibrationConfig, calibrate, correction, human_target
from retarget.refine_scene import finger_forces, human_fingers, tracking_env


@dataclass(frozen=True)
class RefineConfig:
    """Settings of the physics refinement (module doc).

    >>> RefineConfig(retries=2).retries
    2
    """

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
    many times (0: one attempt, no backtracking). Default 4 (``docs/method.md``,
    refinement)."""
    finger_close_m: float = 0.04
    """Each finger's action also moves its fingertip this far [m] towards the object's origin
    (its frame's; the centre of a primitive) at ``u_f = 1`` (away at ``−1``; first order,
    damped least squares over the finger's servoed joints) on the frames where its human
    finger touches: with the force offset alone a finger the plan presses lightly, or one the
    re-simulation leaves short of the object, cannot be brought onto it. Default 4 cm
    (``docs/method.md``, refinement)."""
    offset_gain: float = 2.0
    """Each finger's action scales its force-matching / squeeze offset by ``1 + offset_gain ·
    u_f`` (at 2, ``u_f = +1`` presses three times as hard, ``−½`` not at all). The sampled
    residual seldom reaches ±1 (smoothed, ``τ`` = 0.9), so this sets how far the search
    reaches. Default 2 (``docs/method.md``, refinement)."""
    backtrack_s: float = 0.5
    retry_samples: float = 1.5
    checkpoint_s: float = 0.1
    """Checkpoint spacing [s] of the backtracking (physics state, residual, plan)."""

    def __post_init__(self) -> None:
        check_fields(self, error=RetargetError)


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
    mujoco_warnings: dict = field(default_factory=dict)
    """MuJoCo's warnings in the refined simulation (the attempt kept, and for a calibrated
    refinement the chosen iterate's), ``{type: {"count", "first_frame"}}``; a blow-up makes
    ``success`` False (``dexcanvas_core.sim.mj_warnings``)."""

    def metrics(self) -> dict:
        return {
            "success": self.success,
            "failed_at_frame": self.failed_at_frame,
            "mujoco_warnings": dict(self.mujoco_warnings),
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


def refine(hand, geometry, human, robot, tip_sites: list[str], cfg: RefineConfig | None = None):
    """Refine ``robot`` (a ``RobotTrajectory`` of ``human``) by sampling MPC (module doc).

    >>> from dexcanvas_core import load_demonstration, object_geometry
    >>> from retarget import Retargeter, get_hand
    >>> human = load_demonstration("cube2/tripod").slice(0, 20)
    >>> hand, obj = get_hand("shadow"), object_geometry("cube2")
    >>> rt = Retargeter(hand, obj)
    >>> robot = rt.retarget(human)
    >>> replayed = refine(hand, obj, human, robot, rt.tip_sites, RefineConfig(tracker="open_loop"))
    >>> replayed.success, replayed.ctrl.shape[0]
    (True, 20)
    """
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
    env, act_q, ctrl_ref = tracking_env(hand, geometry, human, robot, tip_sites, cfg)
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
        success=env.failed_at is None
        and Tt == T
        and bool((pos_err <= 0.05).all())
        and not env.warnings.blew_up,
        failed_at_frame=env.failed_at,
        mujoco_warnings=env.warnings.to_dict(),
        object_pos_err=pos_err,
        object_rot_err=np.asarray(log.rot_err),
        ctrl=ctrl,
        ctrl_reference=ctrl_ref,
        finger_ctrl_deviation_rad=float(dev[:, fingers].mean()) if fingers else 0.0,
        wrist_pos_deviation_m=float(np.linalg.norm(dev[:, wrist_pos], axis=1).mean()),
        wrist_rot_deviation_rad=float(np.linalg.norm(dev[:, wrist_rot], axis=1).mean()),
        compute_s=cpu,
        attempts=attempts,
        finger_force_world=finger_forces(hand, m, robot_fingers, log.contacts),
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
    cfg = RefineConfig() if cfg is None else cfg
    ccfg = (calibration or ForceCalibrationConfig()).validate()
    target = human_target(robot, force_scale)
    env, act_q, _ = tracking_env(hand, geometry, human, robot, tip_sites, cfg)
    m, T, nq = env.scene.model, human.num_frames, robot.q.shape[1]
    fingers = list(hand.robot_fingers)
    col = [fingers.index(hand.fingers[f]) for f in human_fingers(hand, tip_sites)]
    n_smooth = max(1, round(ccfg.smooth_s * human.fps))

    def simulate(ctrl):
        env.ctrl_ref = ctrl
        log = track(env, OpenLoop())
        pe = np.asarray(log.pos_err)
        return SimpleNamespace(
            success=env.failed_at is None
            and pe.shape[0] == T
            and bool((pe <= 0.05).all())
            and not env.warnings.blew_up,
            first_failure_frame=env.failed_at,
            mujoco_warnings=env.warnings.to_dict(),
            object_pos_err=pe,
            object_rot_err=np.asarray(log.rot_err),
            finger_force_world=finger_forces(hand, m, fingers, log.contacts),
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
        finger_force_world=refined.finger_force_world, mujoco_warnings=refined.mujoco_warnings,
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
        mujoco_warnings=s.mujoco_warnings,
        compute_s=refined.compute_s + cal.compute_s,
        calibration=cal.metrics(),
    )


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
    warnings: WarningCounter


def _checkpoint(env: TrackingEnv, mpc: SamplingMPC) -> _Checkpoint:
    d = env.scene.data
    return _Checkpoint(
        t=env.t, state=env.state(), warmstart=d.qacc_warmstart.copy(), ctrl=d.ctrl.copy(),
        u=env.u.copy(), log_len=len(env.log.pos_err), plan=mpc.plan.copy(), plan_t=mpc.plan_t,
        warnings=copy.deepcopy(env.warnings),
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
    env.warnings = c.warnings.resumed(d)  # the abandoned attempt's warnings are dropped
    for f in fields(env.log):
        del getattr(env.log, f.name)[c.log_len :]
    mpc.plan, mpc.plan_t = c.plan.copy(), c.plan_t


def _track_backtracking(env: TrackingEnv, cfg: RefineConfig) -> tuple[object, int]:
    """The sampling MPC (the core's ``track`` loop) with backtracking
    (``RefineConfig.retries``; 0: plain tracking): ``(log, attempts)``.

    Failing force-matched replays mostly lose the object 0.15–0.3 s after the human's lift-off
    (``docs/method.md``), so attempt ``k`` resumes from the last checkpoint ``k · backtrack_s``
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
