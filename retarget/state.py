"""What objectives and limits read: the robot configuration and its kinematics at one iterate."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


class Kinematics(Protocol):
    """The kinematic queries objectives need; implemented for Pinocchio and MuJoCo (mink)."""

    @property
    def nq(self) -> int: ...

    def forward(self, q: np.ndarray) -> None: ...

    def site_position(self, site: str) -> np.ndarray: ...

    def site_rotation(self, site: str) -> np.ndarray: ...

    def site_jacobian(self, site: str) -> np.ndarray:
        """(6, nv): linear then angular, world axes."""
        ...

    def point_jacobian(self, body: str, p_world: np.ndarray) -> np.ndarray:
        """(3, nv): a point fixed to ``body``, given in world coordinates."""
        ...

    # Batched forms (one call per objective instead of one per site: the per-iterate Python
    # overhead is what the solver's speed depends on).
    def site_positions(self, sites: tuple[str, ...]) -> np.ndarray:
        """(k, 3) [m] world positions."""
        ...

    def site_jacobians(self, sites: tuple[str, ...]) -> np.ndarray:
        """(k, 6, nv): :meth:`site_jacobian` of each site."""
        ...

    def point_jacobians(self, bodies: tuple[str, ...], p_world: np.ndarray) -> np.ndarray:
        """(k, 3, nv): :meth:`point_jacobian` of points (k, 3), one body each."""
        ...


@dataclass
class RobotState:
    """One iterate of the solver: configuration ``q`` (MuJoCo qpos order) with its kinematics
    already evaluated (``kin.forward(q)`` has been called)."""

    q: np.ndarray
    kin: Kinematics
    dt: float = 1.0 / 120.0
    """Data frame interval [s] (velocity limits)."""

    @property
    def nv(self) -> int:
        return self.q.shape[0]
