"""Synthesis: perturbed re-tracking of demonstrations, keeping only the rollouts that succeed.

The DexCanvas paper expands its captured demonstrations 100× this way. Each generated rollout
perturbs (uniformly, seeded, per source row and index):

* object size × U(1 − size, 1 + size) (default ±20 %),
* object mass × U(1 ± mass) and friction × U(1 ± friction) (±20 %, ±30 %),
* hand shape: the subject's skeleton × U(1 ± hand) (±5 %),
* initial pose: the whole demonstration moved rigidly on the table (±5 cm, ±30° about the
  vertical through the object's start), and the object alone offset from the hand by up to
  ±5 mm / ±5° (the tracker must adapt the grasp).

A kept rollout is a new trajectory whose hand and object tracks are the *simulated* ones (MANO
pose recovered from the simulated hand, keypoints from its kinematics), with the contacts and
forces of that rollout, ``is_generated = True``, ``seed_uuid`` = the source's uuid, a
deterministic new ``uuid``, and the perturbation in the ``synthesis`` extra (JSON).
"""

from __future__ import annotations

import dataclasses
import json
import uuid as uuidlib
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import MANO21
from dexcanvas_core.sim.hand import FINGER_HINGES, joint_angles_to_mano
from dexcanvas_core.sim.pipeline import simulate
from dexcanvas_core.sim.reference import body_keypoints
from dexcanvas_core.trajectory import HandTrack, ObjectTrack, Trajectory

_NS = uuidlib.UUID("6f1c3d52-2b7e-4a51-9a0e-5d1f3c7e8b90")


@dataclass(frozen=True)
class Perturbation:
    """One rollout's perturbation (factors multiply the nominal values)."""

    object_scale: float = 1.0
    mass_scale: float = 1.0
    friction_scale: float = 1.0
    hand_scale: float = 1.0
    shift_xy_m: tuple[float, float] = (0.0, 0.0)
    yaw_rad: float = 0.0
    object_offset_xy_m: tuple[float, float] = (0.0, 0.0)
    object_offset_yaw_rad: float = 0.0

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class PerturbationRanges:
    """Half-widths of the uniform perturbations (see the module docstring)."""

    size: float = 0.2
    mass: float = 0.2
    friction: float = 0.3
    hand: float = 0.05
    shift_m: float = 0.05
    yaw_rad: float = np.deg2rad(30.0)
    object_offset_m: float = 0.005
    object_offset_yaw_rad: float = np.deg2rad(5.0)

    def sample(self, rng: np.random.Generator) -> Perturbation:
        u = rng.uniform
        return Perturbation(
            object_scale=float(u(1 - self.size, 1 + self.size)),
            mass_scale=float(u(1 - self.mass, 1 + self.mass)),
            friction_scale=float(u(1 - self.friction, 1 + self.friction)),
            hand_scale=float(u(1 - self.hand, 1 + self.hand)),
            shift_xy_m=(
                float(u(-self.shift_m, self.shift_m)),
                float(u(-self.shift_m, self.shift_m)),
            ),
            yaw_rad=float(u(-self.yaw_rad, self.yaw_rad)),
            object_offset_xy_m=(
                float(u(-self.object_offset_m, self.object_offset_m)),
                float(u(-self.object_offset_m, self.object_offset_m)),
            ),
            object_offset_yaw_rad=float(u(-self.object_offset_yaw_rad, self.object_offset_yaw_rad)),
        )


def perturbation_for(source_uuid: str, index: int, seed: int, ranges: PerturbationRanges):
    """The deterministic perturbation of rollout ``index`` of a source row."""
    key = uuidlib.uuid5(_NS, f"{source_uuid}/{seed}/{index}").int % (2**63)
    return ranges.sample(np.random.default_rng(key))


def generated_uuid(source_uuid: str, index: int, seed: int) -> str:
    return str(uuidlib.uuid5(_NS, f"generated/{source_uuid}/{seed}/{index}"))


def _rigid(points: np.ndarray, R: np.ndarray, pivot: np.ndarray, shift: np.ndarray) -> np.ndarray:
    return (points - pivot) @ R.T + pivot + shift


def apply_pose_perturbation(traj: Trajectory, p: Perturbation) -> Trajectory:
    """The demonstration moved rigidly on the table, and its object offset from the hand."""
    pivot = traj.object.pos[0].astype(np.float64).copy()
    R = Rotation.from_rotvec([0.0, 0.0, p.yaw_rad]).as_matrix()
    shift = np.array([*p.shift_xy_m, 0.0])
    hand = traj.hand
    R_g = Rotation.from_rotvec(hand.global_rot_aa.astype(np.float64)).as_matrix()
    j0 = (
        hand.joint_pos[:, 0].astype(np.float64)
        if hand.joint_pos is not None
        else hand.global_pos.astype(np.float64)
    )
    offset = j0 - hand.global_pos  # J0 rest location (constant)
    j0_new = _rigid(j0, R, pivot, shift)
    rot_new = Rotation.from_matrix(R @ R_g).as_rotvec()
    pose = hand.hand_pose.astype(np.float64).copy()
    pose[:, :3] = rot_new
    new_hand = dataclasses.replace(
        hand,
        global_pos=(j0_new - offset).astype(np.float32),
        global_rot_aa=rot_new.astype(np.float32),
        hand_pose=pose.astype(np.float32),
        joint_pos=None
        if hand.joint_pos is None
        else _rigid(hand.joint_pos.astype(np.float64), R, pivot, shift).astype(np.float32),
    )
    # object: the same rigid move, then the object-only offset about its own start
    R_off = Rotation.from_rotvec([0.0, 0.0, p.object_offset_yaw_rad]).as_matrix()
    off = np.array([*p.object_offset_xy_m, 0.0])
    obj = traj.object
    pos = _rigid(obj.pos.astype(np.float64), R, pivot, shift)
    pos0 = pos[0].copy()
    pos = _rigid(pos, R_off, pos0, off)
    R_o = R_off @ R @ Rotation.from_rotvec(obj.rot_aa.astype(np.float64)).as_matrix()
    new_obj = ObjectTrack(obj.name, pos.astype(np.float32), Rotation.from_matrix(R_o).as_rotvec())
    return dataclasses.replace(traj, hands=[new_hand], objects=[new_obj], contacts=None)


def simulated_tracks(result, scene, ref) -> tuple[HandTrack, ObjectTrack]:
    """Hand and object tracks of a rollout, from the simulation (module docstring)."""
    tr = result.trajectory
    qpos = np.asarray(result.hand_qpos)
    T = qpos.shape[0]
    m = scene.model
    d = mujoco.MjData(m)
    kp = np.zeros((T, len(MANO21), 3))
    R_w = np.zeros((T, 3, 3))
    bodies = body_keypoints(m)
    for t in range(T):
        d.qpos[scene.hand.qpos_adr] = qpos[t]
        mujoco.mj_kinematics(m, d)
        kp[t] = np.concatenate([d.xpos[bodies], d.site_xpos[scene.hand.tip_sites]])
        R_w[t] = d.xmat[scene.hand.palm_body].reshape(3, 3)
    rot = Rotation.from_matrix(R_w).as_rotvec()
    fingers = joint_angles_to_mano(qpos[:, 6 : 6 + len(FINGER_HINGES)])
    j0_rest = ref.skeleton.rest_keypoints[0]
    hand = dataclasses.replace(
        tr.hand,
        global_pos=(kp[:, 0] - j0_rest).astype(np.float32),
        global_rot_aa=rot.astype(np.float32),
        hand_pose=np.concatenate([rot, fingers], axis=1).astype(np.float32),
        joint_pos=kp.astype(np.float32),
    )
    pos = np.asarray(tr.extras["sim_object_pos"], dtype=np.float32)
    aa = np.asarray(tr.extras["sim_object_rot_aa"], dtype=np.float32)
    return hand, ObjectTrack(tr.object.name, pos, aa)


def synthesize_one(traj: Trajectory, index: int, seed: int, cfg, ranges: PerturbationRanges):
    """One perturbed rollout of ``traj``: ``(trajectory or None, metrics)``; the trajectory is
    ``None`` when the rollout failed (it is not kept)."""
    if traj.is_generated and traj.seed_uuid and traj.extras.get("synthesis"):
        raise ValidationError(
            f"row {traj.uuid} is itself a synthesized rollout; synthesize from source rows",
            field="is_generated",
        )
    p = perturbation_for(traj.uuid, index, seed, ranges)
    moved = apply_pose_perturbation(traj, p)
    run_cfg = dataclasses.replace(
        cfg,
        object_scale=p.object_scale,
        mass_scale=p.mass_scale,
        friction_scale=p.friction_scale,
        hand_scale=p.hand_scale,
    )
    res = simulate(moved, run_cfg, keep_state=True)
    metrics = {**res.metrics, "perturbation": p.to_dict(), "index": index}
    metrics.pop("config", None)
    if not res.success:
        return None, metrics
    hand, obj = simulated_tracks(res, res.scene, res.reference)
    extras = {k: v for k, v in res.trajectory.extras.items() if not k.startswith("sim_object")}
    extras["synthesis"] = json.dumps(
        {"perturbation": p.to_dict(), "seed": seed, "index": index}, sort_keys=True
    )
    out = dataclasses.replace(
        res.trajectory,
        uuid=generated_uuid(traj.uuid, index, seed),
        hands=[hand],
        objects=[obj],
        is_generated=True,
        seed_uuid=traj.uuid,
        extras=extras,
    )
    return out, metrics
