"""Non-penetration: linearised signed distances from MuJoCo's collision queries.

For each geom pair closer than ``distmax``, ``mj_geomDistance`` gives the signed distance ``d``
[m] and the nearest points ``p₁`` (hand geom) and ``p₂``. With ``n`` the unit direction from
``p₁`` to ``p₂`` (flipped when penetrating), moving the hand by ``Δq`` changes the distance by
``−nᵀ(J₁ − J₂)Δq`` to first order, so ``d − nᵀ(J₁ − J₂)Δq ≥ −margin`` becomes the row
``nᵀ(J₁ − J₂) Δq ≤ d + margin``. ``J₂`` is zero for the object (it is kinematic in the
retargeting scene), and the other hand body's point Jacobian for self-collision pairs.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from retarget.limits.base import Limit
from retarget.state import RobotState


class CollisionLimit(Limit):
    """Keep geom pairs apart (hand–object, or hand–hand for self-collision).

    Args:
        model, data: the MuJoCo scene (hand + object); ``data.qpos[:nq_hand]`` is synchronised
            with the solver's ``q`` and the object pose is set by the caller (mocap body).
        pairs: ``(geom_a, geom_b)`` ids; ``geom_a`` must belong to the hand.
        hand_nq: number of hand joints (the first ``hand_nq`` entries of ``qpos``).
        margin: allowed penetration [m] (e.g. 0.002).
        distmax: pairs farther than this [m] are ignored this iterate.
    """

    name = "collision"

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        pairs: Sequence[tuple[int, int]],
        hand_nq: int,
        margin: float = 0.0,
        distmax: float = 0.02,
        self_collision: bool = False,
    ):
        self.model, self.data = model, data
        self.pairs = list(pairs)
        self.hand_nq = hand_nq
        self.margin = margin
        self.distmax = distmax
        self.self_collision = self_collision
        self.last_min_distance = np.inf
        self._body_names = [
            mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(model.nbody)
        ]

    def distances(self, q: np.ndarray) -> list[tuple[int, int, float, np.ndarray, np.ndarray]]:
        """``(geom_a, geom_b, d, p_a, p_b)`` for every pair within ``distmax`` at ``q``."""
        m, d = self.model, self.data
        d.qpos[: self.hand_nq] = q
        mujoco.mj_kinematics(m, d)
        out = []
        fromto = np.zeros(6)
        for ga, gb in self.pairs:
            dist = mujoco.mj_geomDistance(m, d, ga, gb, self.distmax, fromto)
            if dist < self.distmax:
                out.append((ga, gb, float(dist), fromto[:3].copy(), fromto[3:].copy()))
        return out

    def inequalities(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        rows, rhs = [], []
        self.last_min_distance = np.inf
        for ga, gb, dist, pa, pb in self.distances(state.q):
            self.last_min_distance = min(self.last_min_distance, dist)
            v = pb - pa
            norm = np.linalg.norm(v)
            if norm > 1e-9:
                n = v / norm * (1.0 if dist >= 0 else -1.0)
            else:
                # Touching exactly: the nearest points coincide. Use the direction from the hand
                # geom's centre to the contact point instead (exact for spheres and capsules).
                c = pb - self.data.geom_xpos[ga]
                if np.linalg.norm(c) < 1e-12:
                    continue
                n = c / np.linalg.norm(c)
            Ja = state.kin.point_jacobian(self._body_names[self.model.geom_bodyid[ga]], pa)
            J = Ja
            if self.self_collision:
                J = Ja - state.kin.point_jacobian(self._body_names[self.model.geom_bodyid[gb]], pb)
            rows.append(n @ J)
            rhs.append(dist + self.margin)
        if not rows:
            return np.zeros((0, state.nv)), np.zeros(0)
        return np.array(rows), np.array(rhs)
