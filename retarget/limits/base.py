"""Limit base: linear constraints on the step, ``G Δq ≤ h`` and ``A Δq = b``."""

from __future__ import annotations

import numpy as np

from retarget.state import RobotState


class Limit:
    """Base of the QP limits (override one or both methods). Returns inequality rows ``(G, h)`` with ``G Δq ≤ h`` and/or equality rows ``(A, b)``."""

    name: str = "limit"

    def inequalities(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros((0, state.nv)), np.zeros(0)

    def equalities(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros((0, state.nv)), np.zeros(0)
