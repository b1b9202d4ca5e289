"""The kinematic reference the simulated hand tracks: actuator targets per data frame.

From a human :class:`~dexcanvas_core.trajectory.Trajectory` (right hand, one object):

* the subject's skeleton from the measured bone lengths of its keypoints (``joint_pos``), else
  MANO's mean hand;
* wrist targets: the position of J0 (``joint_pos[:, 0]`` when present, else
  ``global_pos + J0_rest``) and intrinsic XYZ Euler angles of the wrist orientation in the
  scene's wrist base frame ``R_base`` (the mean wrist orientation of the demonstration),
  unwrapped over time;
* finger targets: the 45 hinge angles of each MANO pose (exact Euler decomposition, then the
  joint limits; the residual in keypoints is reported);
* per-finger proximity of the reference fingertip to the object surface (for the grip bias).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import FINGERS, FINGERTIPS_MANO21, MANO21
from dexcanvas_core.mano.skeleton import HandSkeleton, measure_bone_lengths
from dexcanvas_core.rotations import aa_to_matrix
from dexcanvas_core.sim.hand import clip_to_limits, mano_to_joint_angles
from dexcanvas_core.trajectory import Trajectory


@dataclass
class Reference:
    """Per-frame targets of one demonstration (``T`` frames at ``fps``).

    Attributes:
        wrist_pos: ``(T, 3)`` J0 position [m], world.
        wrist_rot: ``(T, 3, 3)`` wrist orientation, world.
        wrist_euler: ``(T, 3)`` intrinsic XYZ Euler angles [rad] in ``R_base``.
        hinges: ``(T, 45)`` finger hinge targets [rad], within the joint ranges.
        hinge_clip: ``(T,)`` largest angle [rad] removed by the joint limits per frame.
        object_pos: ``(T, 3)`` [m]; object_quat: ``(T, 4)`` (w, x, y, z).
        keypoints: ``(T, 21, 3)`` the human keypoints [m] (MANO21), for residuals and grip.
        tip_distance: ``(T, 5)`` signed distance [m] of each reference fingertip (thumb …
            pinky) to the object surface.
        tips_object: ``(T, 5, 3)`` reference fingertips in the object frame [m] (NaN when the
            trajectory has no keypoints).
    """

    fps: float
    skeleton: HandSkeleton
    R_base: np.ndarray
    wrist_pos: np.ndarray
    wrist_rot: np.ndarray
    wrist_euler: np.ndarray
    hinges: np.ndarray
    hinge_clip: np.ndarray
    object_pos: np.ndarray
    object_quat: np.ndarray
    keypoints: np.ndarray | None
    tip_distance: np.ndarray
    tips_object: np.ndarray

    @property
    def num_frames(self) -> int:
        return self.wrist_pos.shape[0]

    def ctrl(self) -> np.ndarray:
        """``(T, 51)`` actuator targets in ``HAND_JOINTS`` order."""
        return np.concatenate([self.wrist_pos, self.wrist_euler, self.hinges], axis=1)


def subject_skeleton(traj: Trajectory) -> HandSkeleton:
    """The subject's skeleton: bone lengths measured from the keypoints (median over frames)."""
    hand = traj.hand
    if hand.joint_pos is None:
        return HandSkeleton.default("right")
    return HandSkeleton.from_bone_lengths(measure_bone_lengths(hand.joint_pos), side="right")


def mean_rotation(R: np.ndarray) -> np.ndarray:
    """Chordal mean of rotation matrices ``(T, 3, 3)``."""
    return Rotation.from_matrix(R).mean().as_matrix()


def build_reference(
    traj: Trajectory,
    geometry,
    skeleton: HandSkeleton | None = None,
    R_base: np.ndarray | None = None,
) -> Reference:
    """The tracking reference of ``traj`` (see the module docstring)."""
    if len(traj.hands) != 1 or len(traj.objects) != 1:
        raise ValidationError(
            f"the force pipeline tracks one hand and one object; trajectory {traj.uuid} has "
            f"{len(traj.hands)} hands and {len(traj.objects)} objects",
            field="hands",
        )
    hand = traj.hand
    if hand.name not in ("right", "r", "rh"):
        raise ValidationError(
            f"the simulated hand is a right hand; trajectory {traj.uuid} has a {hand.name!r} "
            "hand (mirror left-hand data to the right first)",
            field="hands.name",
        )
    skeleton = subject_skeleton(traj) if skeleton is None else skeleton
    R_w = aa_to_matrix(hand.global_rot_aa.astype(np.float64))
    if hand.joint_pos is not None:
        p_w = hand.joint_pos[:, 0].astype(np.float64)
    else:
        p_w = hand.global_pos.astype(np.float64) + skeleton.rest_keypoints[0]
    R_base = mean_rotation(R_w) if R_base is None else np.asarray(R_base, dtype=np.float64)
    eul = Rotation.from_matrix(np.einsum("ji,tjk->tik", R_base, R_w)).as_euler("XYZ")
    eul = np.unwrap(eul, axis=0)
    raw = mano_to_joint_angles(hand.finger_pose.astype(np.float64))
    hinges = clip_to_limits(raw)
    obj = traj.object
    obj_quat = Rotation.from_rotvec(obj.rot_aa.astype(np.float64)).as_quat(scalar_first=True)
    kp = None if hand.joint_pos is None else hand.joint_pos.astype(np.float64)
    if kp is not None:
        R_o = aa_to_matrix(obj.rot_aa.astype(np.float64))
        tips_obj = np.einsum("tji,tkj->tki", R_o, kp[:, FINGERTIPS_MANO21] - obj.pos[:, None, :])
        tip_d = geometry.signed_distance(tips_obj.reshape(-1, 3)).reshape(-1, len(FINGERS))
    else:
        tip_d = np.full((traj.num_frames, len(FINGERS)), np.inf)
        tips_obj = np.full((traj.num_frames, len(FINGERS), 3), np.nan)
    return Reference(
        fps=traj.fps,
        skeleton=skeleton,
        R_base=R_base,
        wrist_pos=p_w,
        wrist_rot=R_w,
        wrist_euler=eul,
        hinges=hinges,
        hinge_clip=np.abs(raw - hinges).max(axis=1),
        object_pos=obj.pos.astype(np.float64),
        object_quat=obj_quat,
        keypoints=kp,
        tip_distance=tip_d,
        tips_object=tips_obj,
    )


def body_keypoints(model: mujoco.MjModel) -> list[int]:
    """Body ids of the simulated hand's 16 MANO joints (MANO21 order; the palm is J0)."""
    return [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "mano_palm")] + [
        mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"mano_{n}") for n in MANO21[1:16]
    ]


def keypoint_residual(scene, ref: Reference) -> np.ndarray:
    """``(T,)`` mean distance [m] between the simulated hand's kinematics at the reference
    targets and the human keypoints (joints and tips): the pose conversion's residual."""
    if ref.keypoints is None:
        return np.zeros(ref.num_frames)
    m = scene.model
    d = mujoco.MjData(m)
    hand = scene.hand
    ctrl = ref.ctrl()
    bodies = body_keypoints(m)
    out = np.zeros(ref.num_frames)
    for t in range(ref.num_frames):
        d.qpos[hand.qpos_adr] = ctrl[t]
        mujoco.mj_kinematics(m, d)
        sim = np.concatenate([d.xpos[bodies], d.site_xpos[hand.tip_sites]])
        out[t] = np.linalg.norm(sim - ref.keypoints[t], axis=1).mean()
    return out


def lowpass_reference(ref: Reference, cutoff_hz: float | None) -> Reference:
    """``ref`` with its hand targets (wrist position, wrist Euler angles, finger hinges)
    low-passed at ``cutoff_hz`` (zero-phase 2nd-order Butterworth, run forwards and backwards);
    ``None`` returns ``ref`` unchanged.

    Mocap-fitted hands carry the fit's noise into the targets: with 1 mm marker noise the
    fingertip–surface distance of a held object wanders by 1–2 mm (std) at a few hertz, so the
    fingers open and close on the object and it slips. Hand motion in grasping lies below
    ~2–3 Hz; the scripted (minimum-jerk) demonstrations pass a 4 Hz filter almost unchanged.
    The object track and the keypoints (rewards, grip weights) are left as captured.
    """
    if cutoff_hz is None:
        return ref
    from scipy.signal import butter, filtfilt

    nyq = 0.5 * ref.fps
    if not (np.isfinite(cutoff_hz) and 0 < cutoff_hz < nyq):
        raise ValidationError(
            f"reference low-pass cutoff must lie in (0, {nyq:g}) Hz, got {cutoff_hz}",
            field="reference_lowpass_hz",
        )
    b, a = butter(2, cutoff_hz / nyq)
    if ref.num_frames <= 3 * max(len(a), len(b)):  # too short for the filter's padding
        return ref

    def lp(x: np.ndarray) -> np.ndarray:
        return filtfilt(b, a, x, axis=0)

    eul = lp(np.unwrap(ref.wrist_euler, axis=0))
    R_w = np.einsum("ij,tjk->tik", ref.R_base, Rotation.from_euler("XYZ", eul).as_matrix())
    return dataclasses.replace(
        ref,
        wrist_pos=lp(ref.wrist_pos),
        wrist_rot=R_w,
        wrist_euler=eul,
        hinges=clip_to_limits(lp(ref.hinges)),
    )
