"""Peer retargeting methods run on our robot models, and the measurements shared with ours.

* :mod:`retarget.baselines.dex_retargeting` — dex-retargeting's position retargeting (PyPI,
  the ``bench`` extra) on a URDF exported from a hand's ``MjModel``
  (:class:`DexRetargetingBaseline`; the URDF: :func:`retarget.urdf_export.export_urdf`).
* :func:`measure_trajectory` — the per-frame numbers a :class:`~retarget.retargeter.
  RobotTrajectory` carries (keypoint error, hand–object and finger–finger distances, contact
  error), computed with the same definitions and the same scene for *any* joint trajectory, so
  a baseline is measured exactly like our retargeter.

The baselines' own packages are imported only when a baseline is built.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.baselines.dex_retargeting import (
    BaselineTrajectory,
    DexRetargetingBaseline,
    DexRetargetingConfig,
)
from retarget.errors import RetargetError


@dataclass
class KinematicMetrics:
    """Per-frame kinematic quality of a joint trajectory (``RobotTrajectory``'s definitions)."""

    keypoint_err: np.ndarray
    """(T,) [m] mean distance of the robot keypoint sites to their scaled human targets."""
    min_distance: np.ndarray
    """(T,) [m] smallest signed hand–object distance (negative: penetration); inf when no
    hand–object pair is within the collision query distance, or without object."""
    contact_active: np.ndarray
    """(T, F) bool: the human fingertip mapped to this robot finger touches the object."""
    contact_err: np.ndarray
    """(T, F) [m] where active: distance from the robot finger's surface point nearest the object
    to the human's contact point; NaN elsewhere."""
    self_min_distance: np.ndarray | None = None
    """(T,) [m] smallest signed distance between collision geoms of different hand parts
    (negative: self-penetration); inf when none is near; None: not measured."""

    @classmethod
    def of(cls, robot) -> KinematicMetrics:
        """The metrics a ``RobotTrajectory`` measured while it was solved."""
        return cls(
            robot.keypoint_err,
            robot.min_distance,
            robot.contact_active,
            robot.contact_err,
            robot.self_min_distance,
        )

    def summary(self) -> dict:
        """Scalars: mean keypoint error, deepest hand–object and finger–finger penetration, mean
        contact error [m]."""
        finite = self.min_distance[np.isfinite(self.min_distance)]
        ce = self.contact_err[np.isfinite(self.contact_err)]
        selfd = self.self_min_distance
        return {
            "keypoint_err_mean_m": float(self.keypoint_err.mean()),
            "penetration_max_m": float(max(0.0, -finite.min())) if finite.size else 0.0,
            "self_penetration_max_m": (
                None if selfd is None else float(max(0.0, -selfd.min())) if selfd.size else 0.0
            ),
            "contact_err_mean_m": float(ce.mean()) if ce.size else None,
            "contact_frames": int(self.contact_active.any(axis=1).sum()),
        }


def measure_trajectory(retargeter, traj, q: np.ndarray, targets: dict | None = None):
    """Measure a joint trajectory ``q`` (T, nq; MuJoCo ``qpos`` order) of ``retargeter``'s hand.

    Uses the retargeter's own kinematics, scene, collision query and contact objective, frame by
    frame with the object at its human pose, i.e. the numbers ``Retargeter.retarget`` records.
    ``targets``: ``retargeter.human_targets(traj)`` if already computed. Changes the
    retargeter's per-frame objective state (targets, object pose), not its configuration.
    """
    q = np.asarray(q, dtype=np.float64)
    if not np.all(np.isfinite(q)):
        raise RetargetError("joint trajectory contains NaN or inf")
    m = retargeter.measure(traj, q, targets)
    return KinematicMetrics(
        m["keypoint_err"],
        m["min_distance"],
        m["contact_active"],
        m["contact_err"],
        m["self_min_distance"],
    )


__all__ = [
    "BaselineTrajectory",
    "DexRetargetingBaseline",
    "DexRetargetingConfig",
    "KinematicMetrics",
    "measure_trajectory",
]
