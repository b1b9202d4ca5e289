"""Joint position and velocity limits."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget._checks import check_range
from retarget.errors import RetargetError
from retarget.limits._kernels import band_box, joint_box
from retarget.limits.base import Limit
from retarget.state import RobotState


@dataclass(frozen=True, kw_only=True)
class JointLimitsConfig:
    """The joint range limit (``JointLimit``) of the kinematic solution."""

    margin: float | None = None
    """How far [rad or m] the kinematic solution keeps each finger joint inside its range (at
    most a quarter of the range; 0: the whole range; None: the hand's own,
    ``HandModel.joint_limit_margin``). The servo commands keep the whole range. Default None;
    docs/method.md#limits."""

    def __post_init__(self):
        check_range(self, "margin", optional=True)


@dataclass(frozen=True, kw_only=True)
class VelocityConfig:
    """The velocity limits: per QP iterate (``VelocityLimit``) and the wrist's per frame
    (``FrameSpeedLimit``)."""

    max_joint_speed: float = 20.0
    """Velocity bound [rad/s or m/s] per joint and QP iterate. Default 20."""
    max_wrist_speed: float = 1.5
    """Bound [m/s] per axis on the wrist's translation from one frame's solution to the next,
    over all of the frame's iterations (``inf``: none). Default 1.5;
    docs/method.md#limits."""

    def __post_init__(self):
        check_range(self, "max_wrist_speed", positive=True, finite=False, unit="m/s")


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
        # Unlimited joints get ∓inf (their range read as ∓inf: max(inf − q, 0) = inf), and a
        # start slightly outside the range still gives a feasible QP (_kernels.joint_box).
        lo, hi = self._ranges()
        return joint_box(np.asarray(state.q, dtype=np.float64), lo, hi)

    def _ranges(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` with ∓inf for unlimited joints, memoised on the attributes."""
        key = (self.lower.tobytes(), self.upper.tobytes(), self.limited.tobytes())
        if getattr(self, "_key", None) != key:
            self._key = key
            self._lo = np.where(self.limited, self.lower, -np.inf)
            self._hi = np.where(self.limited, self.upper, np.inf)
        return self._lo, self._hi


class VelocityLimit(Limit):
    """``|Δq| ≤ v_max · dt`` per joint (``v_max`` [rad/s] or [m/s]; box bounds on the step)."""

    name = "velocity"

    def __init__(self, v_max: np.ndarray | float):
        self.v_max = v_max
        self._memo_key: tuple | None = None  # (nv, dt, v_max) of a scalar v_max's bounds
        self._memo: tuple[np.ndarray, np.ndarray] = (np.zeros(0), np.zeros(0))

    def bounds(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        v_max = self.v_max
        scalar = isinstance(v_max, (int, float)) or np.ndim(v_max) == 0
        key = (state.nv, state.dt, float(v_max)) if scalar else None
        if key is not None and key == self._memo_key:
            return self._memo  # (read-only arrays: build_qp never writes them)
        if scalar:
            v = np.full(state.nv, float(v_max) * state.dt)
        else:
            v = np.broadcast_to(np.asarray(v_max, dtype=np.float64), (state.nv,)) * state.dt
        box = (-v, v)
        if key is not None:
            for x in box:
                x.flags.writeable = False
            self._memo_key, self._memo = key, box
        return box


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
        # Unbounded joints: band inf, bounds ∓inf (_kernels.band_box).
        q = np.asarray(state.q, dtype=np.float64)
        return band_box(q, self.q_prev, self.v_max, float(state.dt))
