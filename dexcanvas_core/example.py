"""A small synthetic example dataset in the public DexCanvas layout.

The public DexCanvas data cannot be downloaded everywhere, and a new user should see the tools
work first. This module scripts pick-and-place demonstrations kinematically: the right hand
reaches over a catalogue object palm-down, closes the fingers of the manipulation type, lifts the
object 8 cm, puts it back and retreats. Keypoints (``mano_joint_pos``) come from the built-in
MANO-compatible skeleton, hand size from the operator, object size from the catalogue. It is a
kinematic script, not a capture: it has no contacts or forces, and fingers only approximately
meet the object surface. ``urdf_dof`` is left empty (the anatomical-joint conversion belongs to
the force pipeline).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from dexcanvas_core.io import write_dataset
from dexcanvas_core.keypoints import MANO_FINGER_ORDER
from dexcanvas_core.mano import HandSkeleton, ManoLayer
from dexcanvas_core.rotations import aa_to_matrix, matrix_to_aa
from dexcanvas_core.safe_io import check_output
from dexcanvas_core.taxonomy import Pair
from dexcanvas_core.trajectory import HandTrack, ObjectMove, ObjectTrack, Trajectory

log = logging.getLogger(__name__)

EXAMPLE_VERSION = 2
"""Bumped whenever the generated content changes (invalidates the cached built-in copy)."""

EXAMPLE_PAIRS: tuple[str, ...] = (
    "cube2/tripod",
    "cuboid3/palmar_pinch",
    "sphere1/precision_sphere",
    "cylinder1/large_diameter",
    "cuboid2/quadpod",
    "cube2h/tripod",
)
OPERATORS: dict[str, float] = {"operator1": 0.94, "operator2": 1.0, "operator3": 1.07}
"""Operator → hand size relative to the default skeleton (scales every bone)."""

FPS = 120
# Phase boundaries [s]: reach, descend+close, lift, place, open, retreat.
PHASES = (0.0, 0.6, 1.1, 1.7, 2.3, 2.7, 3.1)

# Template frame of the skeleton (see dexcanvas_core.mano.skeleton): fingers point along -x,
# the palm faces -y, the thumb is on +z. R_DOWN turns it palm-down with fingers along world +x.
R_DOWN = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])


def _min_jerk(s: np.ndarray) -> np.ndarray:
    s = np.clip(s, 0.0, 1.0)
    return s**3 * (10 - 15 * s + 6 * s**2)


def _phase(t: np.ndarray, a: float, b: float) -> np.ndarray:
    return _min_jerk((t - a) / (b - a))


def _object_half_height(spec) -> float:
    if spec.shape == "cube":
        return spec.size_m[0] / 2
    if spec.shape == "sphere":
        return spec.size_m[0] / 2
    if spec.shape == "cylinder":
        return spec.size_m[1] / 2
    return spec.size_m[2] / 2


def _object_half_width(spec) -> float:
    return 0.5 * min(spec.size_m[:2]) if len(spec.size_m) > 1 else 0.5 * spec.size_m[0]


def _grasp_pose(mtype, half_width: float, rng: np.random.Generator) -> np.ndarray:
    """45-D finger pose (MANO order) closing the type's fingers around an object of that width."""
    # Flexion about the template +z axis curls a finger toward the palm (-y). Smaller objects
    # need more flexion; the participating fingers flex, the others fold loosely away.
    flex = float(np.clip(1.2 - 6.0 * half_width, 0.35, 1.0))
    pose = np.zeros((15, 3))
    for k, finger in enumerate(MANO_FINGER_ORDER):
        active = finger in mtype.fingers
        for j in range(3):
            if finger == "thumb":
                # Thumb: oppose (rotate about template x toward the palm) and flex its chain.
                pose[3 * k + j] = (
                    [0.9 * (j == 0), -0.25, 0.35 + 0.25 * j] if active else [0.2, 0, 0.2]
                )
                pose[3 * k + j] *= 1.0 + 0.05 * rng.normal()
            else:
                angle = (flex * (1.0 if j == 0 else 0.8)) if active else 0.3 + 0.5 * j
                pose[3 * k + j] = [0.0, 0.0, angle * (1.0 + 0.05 * rng.normal())]
    return pose.reshape(45)


def example_trajectories(seed: int = 0, reps: int = 1) -> Iterator[Trajectory]:
    """Yield the example demonstrations: every pair × operator × ``reps``, deterministic in seed."""
    import torch

    T = round(PHASES[-1] * FPS) + 1
    t = np.arange(T) / FPS
    for p_idx, pair_name in enumerate(EXAMPLE_PAIRS):
        pair = Pair.parse(pair_name)
        spec, mtype = pair.object, pair.manipulation_type
        for o_idx, (operator, scale) in enumerate(OPERATORS.items()):
            base = HandSkeleton.default("right")
            layer = ManoLayer("right", bone_lengths=base.bone_lengths() * scale)
            for rep in range(reps):
                rng = np.random.default_rng([seed, p_idx, o_idx, rep])
                yaw = rng.uniform(-0.4, 0.4)
                R_yaw = aa_to_matrix(np.array([0.0, 0.0, yaw]))
                R_hand = R_yaw @ R_DOWN
                hh = _object_half_height(spec)
                p_obj0 = np.array([0.45 + rng.uniform(-0.03, 0.03), rng.uniform(-0.05, 0.05), hh])
                rest = layer.forward_numpy(hand_pose=np.zeros((1, 45))).keypoints[0]
                # Palm centre: mean of the wrist and the four finger MCPs, in the template frame.
                palm_tpl = rest[[0, 1, 4, 7, 10]].mean(axis=0)
                j0 = rest[0]
                # Where the palm centre goes at the grasp: above the object top by a palm
                # thickness, shifted a little toward the wrist so the fingers wrap forward.
                palm_grasp = p_obj0 + np.array([0, 0, hh + 0.012 * scale])
                palm_pre = palm_grasp + np.array([0, 0, 0.05])
                palm_start = palm_grasp + R_yaw @ np.array([-0.15, 0.0, 0.15])

                a_reach = _phase(t, PHASES[0], PHASES[1])[:, None]
                a_desc = _phase(t, PHASES[1], PHASES[2])[:, None]
                a_lift = _phase(t, PHASES[2], PHASES[3])[:, None]
                a_place = _phase(t, PHASES[3], PHASES[4])[:, None]
                a_open = _phase(t, PHASES[4], PHASES[5])[:, None]
                a_back = _phase(t, PHASES[5], PHASES[6])[:, None]
                lift = np.array([0, 0, 0.08])
                palm = (
                    palm_start
                    + a_reach * (palm_pre - palm_start)
                    + a_desc * (palm_grasp - palm_pre)
                    + (a_lift - a_place) * lift
                    + a_back * np.array([0, 0, 0.12])
                )
                wobble = 0.05 * np.sin(2 * np.pi * t / PHASES[-1])[:, None] * np.array([1, 0, 0])
                R_t = np.einsum("ij,tjk->tik", R_hand, aa_to_matrix(wobble * (1 - a_desc + a_open)))
                rot_aa = matrix_to_aa(R_t)
                # wrist = J0 + transl, and palm = R (palm_tpl - J0) + wrist.
                wrist = palm - np.einsum("tij,j->ti", R_t, palm_tpl - j0)
                transl = wrist - j0
                grasp = _grasp_pose(mtype, _object_half_width(spec), rng)
                close = (a_desc - a_open)[:, 0]
                finger_pose = close[:, None] * grasp[None]
                hand_pose = np.concatenate([rot_aa, finger_pose], axis=1)
                with torch.no_grad():
                    kp = layer.forward_numpy(
                        global_orient=rot_aa, hand_pose=finger_pose, transl=transl
                    ).keypoints
                obj_pos = p_obj0 + (a_lift - a_place) * lift
                obj_rot = np.tile(np.array([0.0, 0.0, yaw + rng.uniform(-0.2, 0.2)]), (T, 1))
                start = int(np.searchsorted(t, PHASES[2]))
                end = int(np.searchsorted(t, PHASES[4]))
                uid = f"example-{spec.id}-{mtype.name}-{operator}-{seed}-{rep}"
                yield Trajectory(
                    uuid=uid,
                    timestamp=t,
                    fps=float(FPS),
                    hands=[
                        HandTrack(
                            name="right",
                            global_pos=transl,
                            global_rot_aa=rot_aa,
                            hand_pose=hand_pose,
                            joint_pos=kp,
                            betas=np.zeros(10),
                        )
                    ],
                    objects=[ObjectTrack(spec.id, obj_pos, obj_rot)],
                    gesture=mtype.name,
                    operator=operator,
                    scene=spec.id,
                    cap_machine="dexcanvas-example",
                    is_generated=True,
                    object_move=[ObjectMove(spec.id, start, end)],
                )


def build_example_dataset(
    out: str | os.PathLike,
    *,
    seed: int = 0,
    reps: int = 1,
    overwrite: bool = False,
    progress: bool = False,
) -> Path:
    """Write the example dataset (Lance, public layout) to ``out``; returns the path.

    Raises:
        dexcanvas_core.safe_io.OutputError: ``out`` exists and ``overwrite`` is false, or
            cannot be written (checked first).
    """
    check_output(out, overwrite=overwrite, kind="dir")
    n = len(EXAMPLE_PAIRS) * len(OPERATORS) * reps
    trajs = example_trajectories(seed=seed, reps=reps)
    if progress:
        from rich.progress import track

        trajs = track(trajs, total=n, description="building example demonstrations")
    return write_dataset(trajs, out, mode="overwrite" if overwrite else "create")
