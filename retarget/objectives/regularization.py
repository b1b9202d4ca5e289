"""Posture and temporal smoothness."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget._checks import check_range
from retarget.objectives._kernels import add_diagonal
from retarget.objectives.base import Objective
from retarget.state import RobotState


@dataclass(frozen=True, kw_only=True)
class PostureConfig:
    """The posture term (``PostureObjective``): finger joints near the hand's default posture."""

    weight: float = 1e-4
    """Weight [per rad² or m²]. Default 1e-4; docs/method.md#objectives."""

    def __post_init__(self):
        check_range(self, "weight")


@dataclass(frozen=True, kw_only=True)
class SmoothnessConfig:
    """The smoothness term (``SmoothnessObjective``): near the previous frame's solution."""

    weight: float = 0.05
    """Weight [per rad² or m²]. Default 0.05; docs/method.md#objectives."""

    def __post_init__(self):
        check_range(self, "weight")


class PostureObjective(Objective):
    """Joints near a reference posture: ``e = S (q − q_ref)`` (``S`` selects joints)."""

    name = "posture"

    def __init__(self, q_ref: np.ndarray, weight: float | np.ndarray = 1e-3, mask=None):
        super().__init__(weight)
        self.q_ref = np.asarray(q_ref, dtype=np.float64)
        self.mask = np.ones_like(self.q_ref, bool) if mask is None else np.asarray(mask, bool)

    def error(self, state: RobotState) -> np.ndarray:
        return (state.q - self.q_ref)[self.mask]

    def jacobian(self, state: RobotState) -> np.ndarray:
        return np.eye(state.nv)[self.mask]

    def qp_terms(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        # J = S (a row selection): JᵀWJ is diagonal and JᵀWe scatters W e; no matrix products.
        H, w = _diagonal(self, self._weight_vector(np.count_nonzero(self.mask)), self.mask)
        return H, w * (state.q - self.q_ref)

    def accumulate(self, state: RobotState, P: np.ndarray, c: np.ndarray) -> None:
        _, w = _diagonal(self, self._weight_vector(np.count_nonzero(self.mask)), self.mask)
        add_diagonal(P, c, w, state.q - self.q_ref)


class SmoothnessObjective(Objective):
    """Stay near the previous frame's solution: ``e = q − q_prev`` (temporal smoothness)."""

    name = "smoothness"

    def __init__(self, weight: float | np.ndarray = 1e-2):
        super().__init__(weight)
        self.q_prev: np.ndarray | None = None

    def set_previous(self, q_prev: np.ndarray | None) -> None:
        self.q_prev = None if q_prev is None else np.asarray(q_prev, dtype=np.float64).copy()

    def error(self, state: RobotState) -> np.ndarray:
        if self.q_prev is None:
            return np.zeros(0)
        return state.q - self.q_prev

    def jacobian(self, state: RobotState) -> np.ndarray:
        if self.q_prev is None:
            return np.zeros((0, state.nv))
        return np.eye(state.nv)

    def qp_terms(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        if self.q_prev is None:
            return np.zeros((state.nv, state.nv)), np.zeros(state.nv)
        H, w = _diagonal(self, self._weight_vector(state.nv), None)  # J = I
        return H, w * (state.q - self.q_prev)

    def accumulate(self, state: RobotState, P: np.ndarray, c: np.ndarray) -> None:
        if self.q_prev is not None:
            _, w = _diagonal(self, self._weight_vector(state.nv), None)
            add_diagonal(P, c, w, state.q - self.q_prev)


def _diagonal(obj: Objective, weights: np.ndarray, mask: np.ndarray | None):
    """``(JᵀWJ, diag)`` of a row-selection Jacobian ``J = S`` (``mask``; ``None``: all
    rows): the diagonal matrix is built once per weight vector (``_weight_vector``'s memo
    returns the same array while the weights stay) and shared, read-only."""
    key = None if mask is None else mask.tobytes()
    memo = obj.__dict__.get("_diag_memo")
    if memo is None or memo[0] is not weights or memo[3] != key:
        w = weights.copy() if mask is None else np.zeros(mask.shape[0])
        if mask is not None:
            w[mask] = weights
        H = np.diag(w)
        H.flags.writeable = False
        w.flags.writeable = False
        memo = obj.__dict__["_diag_memo"] = (weights, H, w, key)
    return memo[1], memo[2]
