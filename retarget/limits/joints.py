"""Joint position and velocity limits."""

from __future__ import annotations

import numpy as np

from retarget.limits.base import Limit
from retarget.state import RobotState


class JointLimit(Limit):
    """``lower ≤ q + Δq ≤ upper`` for limited joints (box bounds on the step)."""

    name = "joint_limits"

    def __init__(self, lower: np.ndarray, upper: np.ndarray, limited: np.ndarray | None = None):
        self.lower = np.asarray(lower, dtype=np.float64)
        self.upper = np.asarray(upper, dtype=np.float64)
        self.limited = (
            np.ones_like(self.lower, bool) if limited is None else np.asarray(limited, bool)
        )

    def bounds(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        idx = np.flatnonzero(self.limited)
        q = state.q[idx]
        lb = np.full(state.nv, -np.inf)
        ub = np.full(state.nv, np.inf)
        # Clip so that a start slightly outside the range still gives a feasible QP.
        ub[idx] = np.maximum(self.upper[idx] - q, 0.0)
        lb[idx] = -np.maximum(q - self.lower[idx], 0.0)
        return lb, ub


class VelocityLimit(Limit):
    """``|Δq| ≤ v_max · dt`` per joint (``v_max`` [rad/s] or [m/s]; box bounds on the step)."""

    name = "velocity"

    def __init__(self, v_max: np.ndarray | float):
        self.v_max = v_max

    def bounds(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        v = np.broadcast_to(np.asarray(self.v_max, dtype=np.float64), (state.nv,)) * state.dt
        return -v, v.copy()
