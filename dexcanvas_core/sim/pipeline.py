"""``simulate``: one demonstration through the force pipeline, and what it measured.

``simulate(traj)`` builds the scene from the subject's skeleton and the object's catalogue
geometry, tracks the demonstration with the chosen tracker (sampling MPC by default), and returns
a :class:`SimResult`: the input trajectory annotated with the simulated contacts (every
hand–object contact point with its full force, per-part totals in four frames), the object
wrench about its centre of mass, the solver settings, the simulated hand's joint positions and
targets in the public ``urdf_dof`` layout, and metrics:

* ``success`` (DexCanvas rule: every frame's object position error ≤ 5 cm, the whole clip
  tracked, and no solver blow-up), ``success_loose`` (mean < 10 cm and < 0.5 rad), mean/max
  errors;
* ``mujoco_warnings``: ``{type: {"count", "first_frame"}}`` of MuJoCo's warnings
  (:mod:`dexcanvas_core.sim.mj_warnings`; empty: none) — ``BADQACC``, ``BADQVEL`` or
  ``BADQPOS`` make the run a failure;
* ``compute_s_per_demo_s`` (CPU time of the tracking process — one core — per second of
  demonstration);
* physical consistency: ``newton_euler_sim`` — ‖F_hand + F_table + m·g − m·a_sim‖ / (m·g) per frame
  (the extraction checked against the simulator's own acceleration), ``newton_euler_capture`` —
  the same with the *captured* object acceleration (do the forces explain the observed motion?
  both sides moving-averaged over ``CAPTURE_SMOOTH_S``); medians over all frames, the frames
  with hand contact (``*_contact_median``) and the static hold,
  and ``hold_weight_ratio`` — mean vertical hand force / (m·g) over static-hold frames (object
  off the table, captured acceleration below 0.5 m/s²);
* per-finger mean force magnitude during the hold (``FORCE_GROUPS`` order): the force signature.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.mano.skeleton import HandSkeleton
from dexcanvas_core.objects.geometry import ObjectGeometry, object_geometry
from dexcanvas_core.sim.diagnosis import failure_diagnosis, wrist_rotations
from dexcanvas_core.sim.forces import contacts_from_frames, finger_force_series
from dexcanvas_core.sim.hand import FINGER_HINGES, urdf_dof_26
from dexcanvas_core.sim.mpc import MPCConfig, OpenLoop, ResidualTracker, SamplingMPC, track
from dexcanvas_core.sim.physics import GRAVITY, capture_acceleration, smoothed
from dexcanvas_core.sim.reference import (
    Reference,
    build_reference,
    keypoint_residual,
    lowpass_reference,
)
from dexcanvas_core.sim.resize import adapt_reference_to_size
from dexcanvas_core.sim.scene import PhysicsSettings, SimScene, build_scene
from dexcanvas_core.sim.support import hold_until_frame
from dexcanvas_core.sim.tracker import TrackingConfig, TrackingEnv
from dexcanvas_core.table import table_of
from dexcanvas_core.trajectory import FORCE_GROUPS, Trajectory

TRACKERS = ("mpc", "open_loop")


@dataclass(frozen=True)
class SimConfig:
    """Everything that decides a force-pipeline run (recorded with its output)."""

    tracker: str = "mpc"
    """``mpc`` (sampling MPC) or ``open_loop`` (reference + grip bias, no feedback)."""
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    mpc: MPCConfig = field(default_factory=MPCConfig)
    physics: PhysicsSettings = field(default_factory=PhysicsSettings)
    object_scale: float = 1.0
    """Object size factor (synthesis perturbs it); the hand reference follows the resized
    surface when ``adapt_reference_to_size`` is on."""
    adapt_reference_to_size: bool = True
    """When ``object_scale != 1``, move the hand reference so that the parts of the hand near
    the object keep their signed distance to the resized surface (``sim.resize``); ``False``
    tracks the reference captured around the original object."""
    mass_scale: float = 1.0
    friction_scale: float = 1.0
    hand_scale: float = 1.0
    """Scales the subject's skeleton (hand shape perturbation)."""
    object_id: str | None = None
    """Simulate with this catalogue object instead of the trajectory's (e.g. its heavy
    variant ``cube2h`` for ``cube2``)."""
    reference_lowpass_hz: float | None = 4.0
    """Zero-phase low-pass of the hand targets (``reference.lowpass_reference``): mocap fit
    noise makes held fingers open and close on the object; ``None`` tracks them as given."""

    def validate(self) -> SimConfig:
        if self.tracker not in TRACKERS:
            raise ValidationError(
                f"unknown tracker {self.tracker!r}; choose one of {', '.join(TRACKERS)}",
                field="tracker",
            )
        lp = self.reference_lowpass_hz
        if lp is not None and not (np.isfinite(lp) and lp > 0):
            raise ValidationError(
                f"reference_lowpass_hz must be positive or None, got {lp}",
                field="reference_lowpass_hz",
            )
        for name in ("object_scale", "mass_scale", "friction_scale", "hand_scale"):
            v = getattr(self, name)
            if not (np.isfinite(v) and 0.2 <= v <= 5.0):
                raise ValidationError(f"{name} must lie in [0.2, 5], got {v}", field=name)
        return self

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclass
class SimResult:
    """The annotated trajectory, the metrics, and the per-frame arrays behind them."""

    trajectory: Trajectory
    metrics: dict
    object_pos_err: np.ndarray  # (T_tracked,) [m]
    object_rot_err: np.ndarray  # (T_tracked,) [rad]
    finger_force: np.ndarray  # (T_tracked, 6, 3) [N] FORCE_GROUPS rows
    wrench: np.ndarray  # (T_tracked, 6) hand on object, about the COM
    hold: np.ndarray  # (T_tracked,) bool static-hold frames
    newton_euler_sim: np.ndarray  # (T_tracked,)
    newton_euler_capture: np.ndarray  # (T_tracked,)
    hand_qpos: np.ndarray  # (T_tracked, 51) simulated hand joints (HAND_JOINTS order)
    grip_force: np.ndarray  # (T, 5) commanded pad forces [N] of the grip offsets
    scene: SimScene | None = None
    reference: Reference | None = None

    @property
    def success(self) -> bool:
        return bool(self.metrics["success"])


def make_tracker(cfg: SimConfig) -> ResidualTracker:
    return SamplingMPC(cfg.mpc) if cfg.tracker == "mpc" else OpenLoop()


def prepare(traj: Trajectory, cfg: SimConfig) -> tuple[ObjectGeometry, Reference, SimScene]:
    """Geometry (perturbed), reference and compiled scene of one run."""
    cfg.validate()
    traj.validate()
    base = object_geometry(cfg.object_id or traj.object.name)
    geometry = base
    source_object_pos = traj.object.pos
    if cfg.object_scale != 1.0:
        # keep the object's clearance to the table at the first frame: a larger object is
        # lifted (a smaller one lowered) by the change of its lowest point
        geometry = base.scaled(cfg.object_scale)
        R0 = Rotation.from_rotvec(traj.object.rot_aa[0].astype(np.float64)).as_matrix()
        p0 = traj.object.pos[0].astype(np.float64)
        dz = float(base.lowest_z(R0, p0) - geometry.lowest_z(R0, p0))
        obj = dataclasses.replace(traj.object, pos=traj.object.pos + np.float32([0, 0, dz]))
        traj = dataclasses.replace(traj, objects=[obj])
    ref = build_reference(traj, geometry)
    skeleton = ref.skeleton
    if cfg.hand_scale != 1.0:
        skeleton = HandSkeleton(skeleton.rest_keypoints * cfg.hand_scale, "right")
        ref = build_reference(traj, geometry, skeleton=skeleton, R_base=ref.R_base)
    if cfg.object_scale != 1.0 and cfg.adapt_reference_to_size:
        ref, _ = adapt_reference_to_size(ref, base, geometry, source_object_pos, cfg.object_scale)
    ref = lowpass_reference(ref, cfg.reference_lowpass_hz)
    scene = build_scene(
        geometry,
        skeleton,
        fps=traj.fps,
        physics=cfg.physics,
        R_base=ref.R_base,
        mass_kg=base.mass_kg * cfg.mass_scale,
        friction_scale=cfg.friction_scale,
        table=table_of(traj),
    )
    return geometry, ref, scene


def simulate(
    traj: Trajectory, cfg: SimConfig | None = None, progress=None, keep_state: bool = False
) -> SimResult:
    """Track ``traj`` in physics and annotate it with contacts and forces (module docstring).

    ``progress``: optional callable ``(n_frames)`` called once per data frame with 1.
    ``keep_state``: keep the scene and reference on the result (for synthesis and plots).
    """
    cfg = SimConfig() if cfg is None else cfg
    geometry, ref, scene = prepare(traj, cfg)
    env = TrackingEnv(scene, ref, cfg.tracking)
    if scene.table is not None:
        env.hold_until = hold_until_frame(geometry, traj, scene.table.top_z_m)
    tracker = make_tracker(cfg)
    t0 = time.process_time()
    log = track(env, tracker, progress)
    cpu_s = time.process_time() - t0
    res = _result(traj, cfg, geometry, ref, scene, env, log, cpu_s)
    if keep_state:
        res.scene, res.reference = scene, ref
    return res


def _median_or_none(x: np.ndarray) -> float | None:
    return float(np.median(x)) if x.size else None


def _finger_means(finger: np.ndarray, hold: np.ndarray) -> dict | None:
    """Mean force magnitude [N] per ``FORCE_GROUPS`` row over the hold frames."""
    if not hold.any():
        return None
    mean = np.linalg.norm(finger[hold], axis=2).mean(axis=0)
    return {k: round(float(v), 4) for k, v in zip(FORCE_GROUPS, mean, strict=True)}


def _result(traj, cfg, geometry, ref, scene, env, log, cpu_s) -> SimResult:
    T = len(log.pos_err)
    fps = traj.fps
    m = scene.mass_kg
    mg = m * GRAVITY
    g = np.array([0.0, 0.0, -GRAVITY])
    pos_err = np.asarray(log.pos_err)
    rot_err = np.asarray(log.rot_err)
    wrench = np.array([fc.wrench for fc in log.contacts])
    table = np.array([fc.table_wrench for fc in log.contacts])
    a_sim = np.asarray(log.object_acc)
    a_cap = capture_acceleration(ref.object_pos, fps)[:T]
    F_ext = wrench[:, :3] + table[:, :3] + m * g
    ne_sim = np.linalg.norm(F_ext - m * a_sim, axis=1) / mg
    ne_cap = np.linalg.norm(smoothed(F_ext, fps) - m * a_cap, axis=1) / mg
    finger = finger_force_series(log.contacts, scene)
    gap = scene.support_gap(np.asarray(log.object_pos), np.asarray(log.object_quat))
    off_table = (gap > 0.01) & (np.linalg.norm(table[:, :3], axis=1) < 1e-6)
    hold = off_table & (np.linalg.norm(a_cap, axis=1) < 0.5)
    touch = np.linalg.norm(finger, axis=2).sum(axis=1) > 1e-3  # frames with hand contact
    success = (
        env.failed_at is None
        and T == ref.num_frames
        and bool(np.all(pos_err <= 0.05))
        and not env.warnings.blew_up
    )
    metrics = {
        "uuid": traj.uuid,
        "object": traj.object.name,
        "simulated_object": geometry.object_id,
        "manipulation_type": traj.gesture,
        "frames": ref.num_frames,
        "frames_tracked": T,
        "fps": fps,
        "success": success,
        "success_loose": bool(
            T == ref.num_frames and pos_err.mean() < 0.10 and rot_err.mean() < 0.5
        ),
        "failed_at_frame": env.failed_at,
        "object_pos_err_max_m": float(pos_err.max()),
        "object_pos_err_mean_m": float(pos_err.mean()),
        "object_rot_err_mean_rad": float(rot_err.mean()),
        "compute_s": cpu_s,
        "compute_s_per_demo_s": cpu_s / max(T / fps, 1e-9),
        "mass_kg": m,
        "approximate_object": bool(geometry.approximate),
        "newton_euler_sim_median": float(np.median(ne_sim)),
        "newton_euler_capture_median": float(np.median(ne_cap)),
        "newton_euler_capture_hold_median": float(np.median(ne_cap[hold])) if hold.any() else None,
        "newton_euler_sim_contact_median": _median_or_none(ne_sim[touch]),
        "newton_euler_capture_contact_median": _median_or_none(ne_cap[touch]),
        "hold_frames": int(hold.sum()),
        "hold_weight_ratio": float(wrench[hold, 2].mean() / mg) if hold.any() else None,
        "hold_finger_force_mean_n": _finger_means(finger, hold),
        "contact_frames": int((np.linalg.norm(finger, axis=2).sum(1) > 1e-3).sum()),
        "pose_residual_mean_m": float(keypoint_residual(scene, ref).mean()),
        "hinge_clip_max_rad": float(ref.hinge_clip.max()),
        "config": cfg.as_dict(),
        "object_held_until_frame": int(env.hold_until),
        "mujoco_warnings": env.warnings.to_dict(),
    }
    qpos = np.asarray(log.hand_qpos)
    metrics["failure"] = failure_diagnosis(
        env.failed_at, fps, qpos[:, :3], ref.wrist_pos[:T], wrist_rotations(qpos, ref.R_base),
        np.asarray(log.object_pos), ref.object_pos[:T], touch,
    )  # fmt: skip
    out = _annotate(traj, cfg, scene, ref, log, wrench, metrics)
    return SimResult(
        trajectory=out,
        metrics=metrics,
        object_pos_err=pos_err,
        object_rot_err=rot_err,
        finger_force=finger,
        wrench=wrench,
        hold=hold,
        newton_euler_sim=ne_sim,
        newton_euler_capture=ne_cap,
        hand_qpos=np.asarray(log.hand_qpos),
        grip_force=env.grip_force,
    )


def _annotate(traj, cfg, scene, ref, log, wrench, metrics) -> Trajectory:
    """The input trajectory (cut at the last tracked frame if the rollout failed) with the
    force pipeline's annotations."""
    T = len(log.pos_err)
    out = traj.slice(0, T) if T < traj.num_frames else dataclasses.replace(traj)
    contacts = contacts_from_frames(log.contacts, log.poses, scene, traj.object.name)
    qpos = np.asarray(log.hand_qpos)
    ctrl = np.asarray(log.ctrl)

    def to_urdf(q: np.ndarray) -> np.ndarray:
        R = np.einsum("ij,tjk->tik", ref.R_base, Rotation.from_euler("XYZ", q[:, 3:6]).as_matrix())
        eul = Rotation.from_matrix(R).as_euler("XYZ")
        return urdf_dof_26(q[:, :3], eul, q[:, 6 : 6 + len(FINGER_HINGES)]).astype(np.float32)

    hand = dataclasses.replace(out.hand, urdf_dof=to_urdf(qpos), urdf_dof_target=to_urdf(ctrl))
    obj_pos = np.asarray(log.object_pos)
    obj_aa = Rotation.from_quat(np.asarray(log.object_quat), scalar_first=True).as_rotvec()
    extras = dict(out.extras)
    extras["sim_object_pos"] = obj_pos.astype(np.float32).tolist()
    extras["sim_object_rot_aa"] = obj_aa.astype(np.float32).tolist()
    extras["approximate_object"] = bool(metrics["approximate_object"])
    extras["sim_metrics"] = json.dumps(
        {
            k: v
            for k, v in metrics.items()
            if k != "config" and not (k == "mujoco_warnings" and not v)
        },
        sort_keys=True,
        default=float,
    )
    solver = cfg.physics.as_dict(traj.fps)
    solver["tracker"] = cfg.tracker
    solver["object_scale"] = cfg.object_scale
    solver["mass_kg"] = metrics["mass_kg"]
    solver["friction_scale"] = cfg.friction_scale
    solver["hand_scale"] = cfg.hand_scale
    return dataclasses.replace(
        out,
        hands=[hand],
        contacts=contacts,
        object_wrench_world=wrench.astype(np.float32),
        solver_settings=solver,
        extras=extras,
    )
