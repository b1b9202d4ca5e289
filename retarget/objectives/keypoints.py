"""Keypoint positions and fingertip-to-fingertip vectors."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from retarget._checks import check_choice, check_range
from retarget.errors import RetargetError
from retarget.kinematics import PinocchioKinematics
from retarget.objectives._kernels import site_gram
from retarget.objectives.base import Objective
from retarget.state import RobotState

_NO_ROWS = np.zeros(0, dtype=np.int64)  # site_gram's rows_b for absolute targets

KeypointScaling = Literal["surface", "uniform"]


@dataclass(frozen=True, kw_only=True)
class KeypointsConfig:
    """The keypoint term (``KeypointObjective``) and how the human keypoints are scaled to the
    robot hand's size (``Retargeter._scaled_keypoints``). Chosen on the retargeting benchmark;
    docs/method.md#objectives."""

    tip_weight: float = 1.0
    """Weight of a fingertip keypoint's error [per m²]. Default 1."""
    joint_weight: float = 1.0
    """Weight of another keypoint's error [per m²]. Default 1."""
    scaling: KeypointScaling = "surface"
    """``uniform``: about the object's centre by the hand scale; ``surface``: the same, but a
    keypoint's distance to the object's surface is a robot-sized finger radius plus the human's
    gap near the object (touching keypoints stay touching), scaled fully from
    ``scale_blend_m`` out. Default ``surface``."""
    finger_radius_m: float = 0.008
    """``scaling="surface"``: the human finger's radius [m] about its keypoints (a keypoint
    this close to the surface touches it). Default 0.008."""
    scale_blend_m: float = 0.05
    """``scaling="surface"``: gap [m] between a human finger and the object's surface from
    which the gap gets the full hand scale. Default 0.05."""

    def __post_init__(self):
        check_range(self, "tip_weight")
        check_range(self, "joint_weight")
        check_choice(self, "scaling", KeypointScaling)
        check_range(self, "scale_blend_m", positive=True, unit="m")


@dataclass(frozen=True, kw_only=True)
class VectorsConfig:
    """The fingertip-to-thumb vector term (``VectorObjective``), which keeps pinches closed."""

    weight: float = 1.0
    """Weight [per m²]. Default 1; docs/method.md#objectives."""

    def __post_init__(self):
        check_range(self, "weight")


class KeypointObjective(Objective):
    """Robot sites at target positions: ``e = p_site(q) − p_target`` (world, [m])."""

    name = "keypoints"

    def __init__(self, sites: Sequence[str], weight: float | np.ndarray = 1.0):
        super().__init__(weight)
        self.sites = list(sites)
        self._sites = tuple(self.sites)
        self.targets = np.zeros((len(self.sites), 3))

    def set_targets(self, targets_world: np.ndarray) -> None:
        t = np.asarray(targets_world, dtype=np.float64)
        if t.shape != (len(self.sites), 3):
            raise RetargetError(
                f"{self.name}: targets must have shape ({len(self.sites)}, 3), got {t.shape}"
            )
        if not np.all(np.isfinite(t)):
            raise RetargetError(f"{self.name}: targets contain NaN or inf")
        self.targets = t

    def weights(self, m: int) -> np.ndarray:
        w = np.asarray(self.weight, dtype=np.float64)
        if w.ndim == 1 and w.shape[0] == len(self.sites):  # one weight per site
            return np.repeat(w, 3)
        return np.broadcast_to(w, (m,))

    def error(self, state: RobotState) -> np.ndarray:
        if not self.sites:
            return np.zeros(0)
        return (state.kin.site_positions(self._sites) - self.targets).reshape(-1)

    def jacobian(self, state: RobotState) -> np.ndarray:
        if not self.sites:
            return np.zeros((0, state.nv))
        return state.kin.site_jacobians(self._sites)[:, :3].reshape(-1, state.nv)

    def accumulate(self, state: RobotState, P: np.ndarray, c: np.ndarray) -> None:
        kin = state.kin
        if not self.sites or not isinstance(kin, PinocchioKinematics):
            return super().accumulate(state, P, c)
        J, p = kin.site_arrays()
        rows = kin.site_rows(self._sites)
        w = self._weight_vector(3 * len(self.sites))
        site_gram(J, p, rows, _NO_ROWS, self.targets, w, P, c)


class VectorObjective(Objective):
    """Vectors between site pairs match targets: ``e = (p_a − p_b) − v_target``.

    Keeps pinches closed: the thumb-to-index vector of the robot follows the human's even when
    absolute positions cannot both be reached.
    """

    name = "vectors"

    def __init__(self, pairs: Sequence[tuple[str, str]], weight: float | np.ndarray = 1.0):
        super().__init__(weight)
        self.pairs = list(pairs)
        self._a = tuple(a for a, _ in self.pairs)
        self._b = tuple(b for _, b in self.pairs)
        self.targets = np.zeros((len(self.pairs), 3))

    def set_targets(self, vectors_world: np.ndarray) -> None:
        v = np.asarray(vectors_world, dtype=np.float64)
        if v.shape != (len(self.pairs), 3) or not np.all(np.isfinite(v)):
            raise RetargetError(
                f"vectors: targets must be finite ({len(self.pairs)}, 3), got {v.shape}"
            )
        self.targets = v

    def weights(self, m: int) -> np.ndarray:
        w = np.asarray(self.weight, dtype=np.float64)
        if w.ndim == 1 and w.shape[0] == len(self.pairs):
            return np.repeat(w, 3)
        return np.broadcast_to(w, (m,))

    def error(self, state: RobotState) -> np.ndarray:
        if not self.pairs:
            return np.zeros(0)
        k = state.kin
        d = k.site_positions(self._a) - k.site_positions(self._b)
        return (d - self.targets).reshape(-1)

    def jacobian(self, state: RobotState) -> np.ndarray:
        if not self.pairs:
            return np.zeros((0, state.nv))
        k = state.kin
        J = k.site_jacobians(self._a)[:, :3] - k.site_jacobians(self._b)[:, :3]
        return J.reshape(-1, state.nv)

    def accumulate(self, state: RobotState, P: np.ndarray, c: np.ndarray) -> None:
        kin = state.kin
        if not self.pairs or not isinstance(kin, PinocchioKinematics):
            return super().accumulate(state, P, c)
        J, p = kin.site_arrays()
        w = self._weight_vector(3 * len(self.pairs))
        site_gram(J, p, kin.site_rows(self._a), kin.site_rows(self._b), self.targets, w, P, c)
