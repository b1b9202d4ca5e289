"""Wrist (robot base) pose."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget._checks import check_range
from retarget.errors import RetargetError
from retarget.kinematics import PinocchioKinematics
from retarget.objectives._kernels import pose_error, pose_gram
from retarget.objectives.base import Objective
from retarget.state import RobotState


@dataclass(frozen=True, kw_only=True)
class WristConfig:
    """The wrist pose term (``WristPoseObjective``). Both weights are multiplied by the hand's
    ``HandModel.wrist_weight``. Chosen on the retargeting benchmark; docs/method.md#objectives."""

    position_weight: float = 0.15
    """Weight of the wrist's position error [per m²]. Default 0.15."""
    rotation_weight: float = 0.15
    """Weight of the wrist's rotation error [per rad²]. Default 0.15."""
    use_offset: bool = True
    """Aim the wrist at the human wrist pose composed with the hand's calibrated
    ``HandModel.wrist_offset`` (``retarget calibrate-wrist``) instead of the pose itself (a hand
    without an offset: the pose itself). Default True."""

    def __post_init__(self):
        check_range(self, "position_weight")
        check_range(self, "rotation_weight")


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
        kin = state.kin
        e = np.empty(6)
        R = np.ascontiguousarray(kin.site_rotation(self.site)).reshape(9)
        pose_error(kin.site_position(self.site), R, self.p_target, self.R_target, e)
        return e

    def jacobian(self, state: RobotState) -> np.ndarray:
        return state.kin.site_jacobian(self.site)

    def accumulate(self, state: RobotState, P: np.ndarray, c: np.ndarray) -> None:
        """One compiled pass from the kinematics' all-sites arrays (:func:`pose_gram`: the
        error, its rotation vector included, and ``JᵀWJ``); the base class's otherwise."""
        kin = state.kin
        if not isinstance(kin, PinocchioKinematics):
            return super().accumulate(state, P, c)
        J, p = kin.site_arrays()
        pose_gram(J, p, kin.site_rotation_array(), int(kin.site_rows((self.site,))[0]),
                  self.p_target, self.R_target, self._weight_vector(6), P, c)  # fmt: skip
