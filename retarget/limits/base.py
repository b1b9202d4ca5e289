"""Limit base: linear constraints on the step, ``G Δq ≤ h`` and ``A Δq = b``."""

from __future__ import annotations

import numpy as np

from retarget.state import RobotState


class Limit:
    """Base of the QP limits; override any of the methods.

    ``inequalities`` returns rows ``(G, h)`` with ``G Δq ≤ h``; ``equalities`` returns ``(A, b)``
    with ``A Δq = b``; ``bounds`` returns ``(lb, ub)`` with ``lb ≤ Δq ≤ ub`` (per joint, ±inf for
    none), which the solver handles as simple bounds. The defaults add nothing.
    """

    name: str = "limit"

    def bounds(self, state: RobotState) -> tuple[np.ndarray, np.ndarray] | None:
        return None

    def inequalities(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros((0, state.nv)), np.zeros(0)

    def equalities(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros((0, state.nv)), np.zeros(0)
