"""Joint position and velocity limits."""

from __future__ import annotations

import numpy as np

from retarget.errors import RetargetError
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


class FrameSpeedLimit(Limit):
    """``|q + Δq − q_prev| ≤ v_max · dt`` per joint: a bound on the motion from the previous
    frame's solution ``q_prev``, however many iterations the frame takes (``v_max`` [m/s or
    rad/s] per joint, ``inf`` for none; box bounds on the step).

    ``VelocityLimit`` bounds each iterate's step; a frame of several iterations (and its
    predicted starting point) can still move a joint several times that far. A start already
    outside the band may step back towards it but not further out (the bounds always admit
    ``Δq = 0``, so the QP stays feasible).
    """

    name = "frame_speed"

    def __init__(self, q_prev: np.ndarray, v_max: np.ndarray):
        self.q_prev = np.asarray(q_prev, dtype=np.float64)
        self.v_max = np.asarray(v_max, dtype=np.float64)
        if self.q_prev.shape != self.v_max.shape:
            raise RetargetError(
                f"q_prev has shape {self.q_prev.shape}, v_max {self.v_max.shape}: one per joint"
            )

    def bounds(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        band = self.v_max * state.dt
        off = self.q_prev - state.q
        lb = np.full(state.nv, -np.inf)
        ub = np.full(state.nv, np.inf)
        idx = np.flatnonzero(np.isfinite(band))
        lb[idx] = np.minimum(off[idx] - band[idx], 0.0)
        ub[idx] = np.maximum(off[idx] + band[idx], 0.0)
        return lb, ub
