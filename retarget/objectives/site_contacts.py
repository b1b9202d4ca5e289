"""Site contacts: robot contact sites at the object-surface points the human touched."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from retarget.errors import RetargetError
from retarget.objectives.base import Objective
from retarget.state import RobotState


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


class ContactObjective(Objective):
    """Active contacts: each robot contact site at its object-surface target point, and (with a
    ``pad_axis``) its pad normal opposing the surface normal.

    ``e = [p_site − p_surface]`` per active contact, plus ``R_site a + n_surface`` when the site's
    pad axis ``a`` (site frame) is known. Sites without an active contact this frame contribute
    nothing; ``set_contacts`` is called per frame with the human's contacts mapped to the robot.
    """

    name = "contacts"
    memo_weights = False  # its weights also depend on normal_weight and pad_axis

    def __init__(
        self,
        sites: Sequence[str],
        weight: float = 1.0,
        normal_weight: float = 0.05,
        pad_axis: np.ndarray | None = None,
    ):
        super().__init__(weight)
        self.sites = list(sites)
        self.normal_weight = normal_weight
        self.pad_axis = None if pad_axis is None else np.asarray(pad_axis, dtype=np.float64)
        self.active = np.zeros(len(self.sites), bool)
        self.points = np.zeros((len(self.sites), 3))
        self.normals = np.zeros((len(self.sites), 3))

    def set_contacts(
        self, active: np.ndarray, points_world: np.ndarray, normals_world: np.ndarray
    ) -> None:
        a = np.asarray(active, bool)
        p = np.asarray(points_world, dtype=np.float64)
        n = np.asarray(normals_world, dtype=np.float64)
        k = len(self.sites)
        if a.shape != (k,) or p.shape != (k, 3) or n.shape != (k, 3):
            raise RetargetError(
                f"contacts: expected shapes ({k},), ({k}, 3), ({k}, 3); "
                f"got {a.shape}, {p.shape}, {n.shape}"
            )
        if not (np.isfinite(p[a]).all() and np.isfinite(n[a]).all()):
            raise RetargetError("contacts: active contact points or normals contain NaN")
        self.active, self.points, self.normals = a, p, n

    def _rows(self) -> list[int]:
        return [i for i in range(len(self.sites)) if self.active[i]]

    def weights(self, m: int) -> np.ndarray:
        per = [self.weight] * 3 + ([self.normal_weight] * 3 if self.pad_axis is not None else [])
        return np.tile(np.asarray(per, dtype=np.float64), len(self._rows()))

    def error(self, state: RobotState) -> np.ndarray:
        out = []
        for i in self._rows():
            s = self.sites[i]
            out.append(state.kin.site_position(s) - self.points[i])
            if self.pad_axis is not None:
                out.append(state.kin.site_rotation(s) @ self.pad_axis + self.normals[i])
        return np.concatenate(out) if out else np.zeros(0)

    def jacobian(self, state: RobotState) -> np.ndarray:
        out = []
        for i in self._rows():
            J = state.kin.site_jacobian(self.sites[i])
            out.append(J[:3])
            if self.pad_axis is not None:
                v = state.kin.site_rotation(self.sites[i]) @ self.pad_axis
                out.append(-_skew(v) @ J[3:])  # d(R a)/dt = ω × (R a)
        return np.concatenate(out, axis=0) if out else np.zeros((0, state.nv))
