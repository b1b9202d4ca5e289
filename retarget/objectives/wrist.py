"""Wrist (robot base) pose."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from retarget.errors import RetargetError
from retarget.objectives.base import Objective
from retarget.state import RobotState


def rotation_log(R: np.ndarray) -> np.ndarray:
    """(3,) rotation vector [rad] of a rotation matrix (angle in [0, π]), via its quaternion
    (``mju_mat2Quat`` is robust near π, where the matrix formula loses precision)."""
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(R, dtype=np.float64).reshape(9))
    w, x, y, z = quat.tolist()
    if w < 0:  # the short way round
        w, x, y, z = -w, -x, -y, -z
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-12:
        return np.array([2.0 * x, 2.0 * y, 2.0 * z])  # first order: 2 sin(θ/2) axis ≈ θ axis
    f = 2.0 * math.atan2(s, w) / s
    return np.array([f * x, f * y, f * z])


class WristPoseObjective(Objective):
    """A site's pose at a target: ``e = [p − p*; log(R R*ᵀ)]`` (world axes, [m] and [rad]).

    The rotation error is the rotation vector of ``R R*ᵀ`` (world frame); its Jacobian is the
    site's angular Jacobian, exact at ``R = R*`` and a damped-Newton approximation elsewhere.
    ``weight`` may be ``(w_position, w_rotation)``.
    """

    name = "wrist"

    def __init__(self, site: str, weight: float | tuple[float, float] = (1.0, 0.1)):
        super().__init__(weight)
        self.site = site
        self.p_target = np.zeros(3)
        self.R_target = np.eye(3)

    def set_target(self, p_world: np.ndarray, R_world: np.ndarray) -> None:
        p = np.asarray(p_world, dtype=np.float64)
        R = np.asarray(R_world, dtype=np.float64)
        if (
            p.shape != (3,)
            or R.shape != (3, 3)
            or not (np.isfinite(p).all() and np.isfinite(R).all())
        ):
            raise RetargetError(
                f"wrist target must be finite (3,), (3, 3); got {p.shape}, {R.shape}"
            )
        self.p_target, self.R_target = p, R

    def weights(self, m: int) -> np.ndarray:
        w = np.asarray(self.weight, dtype=np.float64)
        if w.shape == (2,):
            return np.repeat(w, 3)
        return np.broadcast_to(w, (m,))

    def error(self, state: RobotState) -> np.ndarray:
        p = state.kin.site_position(self.site)
        R = state.kin.site_rotation(self.site)
        return np.concatenate([p - self.p_target, rotation_log(R @ self.R_target.T)])

    def jacobian(self, state: RobotState) -> np.ndarray:
        return state.kin.site_jacobian(self.site)
