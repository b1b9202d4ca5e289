"""What a re-simulation measured (:class:`ValidationResult`, made by
:class:`retarget.validate.Resimulator`) and the metrics written from it."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ValidationResult:
    """What the re-simulation measured (arrays are per data frame)."""

    success: bool
    success_loose: bool
    object_pos_err: np.ndarray
    """(T,) [m]."""
    object_rot_err: np.ndarray
    """(T,) [rad]."""
    object_pos_sim: np.ndarray
    """(T, 3) [m] simulated object position."""
    object_rot_sim: np.ndarray
    """(T, 3) [rad] simulated object orientation (axis-angle)."""
    finger_force_world: np.ndarray
    """(T, F + 1, 3) [N]: force of each robot finger (``fingers`` order) and the palm on the
    object, world frame, averaged over the physics steps of the frame."""
    fingers: list[str]
    penetration_max_m: float
    """Deepest hand–object penetration seen [m] (0 if none)."""
    first_failure_frame: int | None
    timestep: float
    meta: dict = field(default_factory=dict)
    object_held_until_frame: int = 0
    """Frames before this one held the object at its first pose (it does not rest there by
    itself, ``dexcanvas_core.sim.support``); 0: never held."""
    q_sim: np.ndarray | None = None
    """(T, hand_nq) simulated hand joint positions at the end of each frame."""
    finger_servo_err: np.ndarray | None = None
    """(T, F) [rad] per robot finger (``fingers`` order), the largest ``|q_sim − q_command|``
    over its actuated joints at the end of each frame: how far its servos trail the command (a
    finger the object blocks trails it by design, by its force offset)."""
    wrist_pos_err: np.ndarray | None = None
    """(T,) [m] distance of the simulated wrist (its three slide joints) from the command."""
    wrist_rot_err: np.ndarray | None = None
    """(T,) [rad] rotation angle between the simulated and the commanded wrist orientation."""
    wrist_force_peak: np.ndarray | None = None
    """(T,) [N] largest norm, over the frame's physics steps, of the force the arm applies to
    the wrist (its slide joints' actuator forces plus their gravity compensation); frame 0:
    the last settling step's."""
    wrist_torque_peak: np.ndarray | None = None
    """(T,) [N·m] the same for the largest of the three hinge torques."""
    mujoco_warnings: dict = field(default_factory=dict)
    """MuJoCo's warnings in the re-simulation, ``{type: {"count", "first_frame"}}``
    (``dexcanvas_core.sim.mj_warnings``; empty: none). A blow-up (``BADQACC``, ``BADQVEL``,
    ``BADQPOS``) makes ``success`` False."""

    @property
    def object_pos_err_max_m(self) -> float:
        return float(self.object_pos_err.max())

    @property
    def object_pos_err_mean_m(self) -> float:
        return float(self.object_pos_err.mean())

    @property
    def object_rot_err_mean_rad(self) -> float:
        return float(self.object_rot_err.mean())

    def servo_metrics(self) -> dict:
        """Servo tracking errors (empty when the rollout did not record them) and, when
        recorded, the wrist driver's name, force and torque limits, peaks and saturation
        (``meta``: ``wrist_driver``, ``wrist_force_limit_n``, ``wrist_torque_limit_nm``,
        ``wrist_force_saturation_fraction``, ``wrist_torque_saturation_fraction``: the share of
        the clip's physics steps in which the limit bound)."""
        if self.finger_servo_err is None or self.wrist_pos_err is None:
            return {}
        out = {
            "finger_servo_err_mean_deg": {
                f: float(np.degrees(self.finger_servo_err[:, i].mean()))
                for i, f in enumerate(self.fingers)
            },
            "wrist_pos_tracking_err_mean_m": float(self.wrist_pos_err.mean()),
            "wrist_pos_tracking_err_max_m": float(self.wrist_pos_err.max()),
            "wrist_rot_tracking_err_mean_deg": float(np.degrees(self.wrist_rot_err.mean())),
            "wrist_rot_tracking_err_max_deg": float(np.degrees(self.wrist_rot_err.max())),
        }
        if self.wrist_force_peak is not None:
            out["wrist_force_max_n"] = float(self.wrist_force_peak.max())
            out["wrist_torque_max_nm"] = float(self.wrist_torque_peak.max())
        for k in _WRIST_META:
            if k in self.meta:
                out[k] = self.meta[k]
        return out

    def metrics(self) -> dict:
        return {
            "success": bool(self.success),
            "success_loose": bool(self.success_loose),
            "object_pos_err_max_m": self.object_pos_err_max_m,
            "object_pos_err_mean_m": self.object_pos_err_mean_m,
            "object_rot_err_mean_rad": self.object_rot_err_mean_rad,
            "penetration_max_m": float(self.penetration_max_m),
            "first_failure_frame": self.first_failure_frame,
            "object_held_until_frame": int(self.object_held_until_frame),
            "mujoco_warnings": dict(self.mujoco_warnings),
            "finger_force_mean_n": {
                f: float(np.linalg.norm(self.finger_force_world[:, i], axis=1).mean())
                for i, f in enumerate([*self.fingers, "palm"])
            },
            **self.servo_metrics(),
        }


_WRIST_META = (
    "wrist_driver",
    "wrist_force_limit_n",
    "wrist_torque_limit_nm",
    "wrist_force_saturation_fraction",
    "wrist_torque_saturation_fraction",
)
