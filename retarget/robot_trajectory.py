"""A retargeted robot trajectory and what the solver measured along it."""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from dexcanvas_core.safe_io import atomic_path


@dataclass
class RobotTrajectory:
    """A retargeted trajectory and what the solver measured along it.

    >>> from dexcanvas_core import load_demonstration
    >>> from retarget import get_hand, retarget_keypoints
    >>> human = load_demonstration("cube2/tripod").slice(0, 10)
    >>> robot = retarget_keypoints(get_hand("leap"), human.hand.joint_pos, fps=120.0)
    >>> robot.joint_names[:3], robot.keypoint_err.shape
    (['wrist_tx', 'wrist_ty', 'wrist_tz'], (10,))
    """

    hand: str
    joint_names: list[str]
    q: np.ndarray
    """(T, nq) joint positions in MuJoCo ``qpos`` order; the first 6 are the floating wrist."""
    q_command: np.ndarray
    """(T, nq) position-servo targets: ``q`` plus the grip's offsets on contact frames."""
    timestamp: np.ndarray
    """(T,) [s]."""
    tip_sites: list[str]
    tip_pos_world: np.ndarray
    """(T, F, 3) robot fingertip sites [m]."""
    keypoint_err: np.ndarray
    """(T,) mean distance [m] between robot sites and their (scaled) human keypoint targets."""
    min_distance: np.ndarray
    """(T,) smallest signed hand–object distance [m] (negative: penetration); inf without object."""
    self_min_distance: np.ndarray
    """(T,) smallest signed distance [m] between collision geoms of different hand parts (the
    self-collision pairs; negative: penetration); inf when none is within the query distance."""
    contact_active: np.ndarray
    """(T, F) bool: the human fingertip mapped to this robot finger touches the object."""
    contact_err: np.ndarray
    """(T, F) [m] where active: distance from the robot finger's surface point nearest the object
    to the human's contact point; NaN elsewhere."""
    solve_time_s: float
    robot_force: np.ndarray | None = None
    """(T, F, 3) [N] the commanded contact force per robot finger (on the object): force
    matching's, or the weight-aware grip's (``grip.mode="wrench"``); ``None`` with
    ``grip.mode="depth"``."""
    human_force: np.ndarray | None = None
    """(T, F, 3) [N] the human force of the finger each robot finger stands for (force
    matching only)."""
    wrench_shortfall: np.ndarray | None = None
    """(T,) [N] how far the commanded forces fall short of the object force asked for (the
    human's with force matching; the weight and motion's with the weight-aware grip)."""
    meta: dict = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return self.q.shape[0]

    @property
    def ms_per_frame(self) -> float:
        return 1e3 * self.solve_time_s / max(self.num_frames, 1)

    @property
    def self_penetration_max_m(self) -> float:
        """Deepest penetration [m] between different hand parts over the trajectory (0: none)."""
        d = self.self_min_distance
        return float(max(0.0, -d.min())) if d.size else 0.0

    def save_npz(self, path, extra: dict[str, np.ndarray] | None = None) -> None:
        """Write every array (plus ``extra`` ones) to one ``.npz``, atomically (a unique
        temporary file, then rename: :func:`dexcanvas_core.safe_io.atomic_path`)."""
        with atomic_path(path) as tmp, open(tmp, "wb") as f:
            np.savez_compressed(
                f,
                q=self.q,
                q_command=self.q_command,
                wrist_pose=self.q[:, :6],
                timestamp=self.timestamp,
                joint_names=np.array(self.joint_names),
                tip_sites=np.array(self.tip_sites),
                tip_pos_world=self.tip_pos_world,
                keypoint_err=self.keypoint_err,
                min_distance=self.min_distance,
                self_min_distance=self.self_min_distance,
                contact_active=self.contact_active,
                contact_err=self.contact_err,
                meta=np.array(json.dumps({"hand": self.hand, **self.meta}, default=str)),
                **{
                    k: v
                    for k in ("robot_force", "human_force", "wrench_shortfall")
                    if (v := getattr(self, k)) is not None
                },
                **(extra or {}),
            )
