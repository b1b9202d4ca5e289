"""Contact preservation: robot links touch the object where the human touched it."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from retarget.errors import RetargetError
from retarget.objectives._kernels import surface_gram
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


class SurfaceContactObjective(Objective):
    """Active contacts: the robot finger's surface point nearest the object goes to the target.

    For each robot finger with an active contact, MuJoCo's ``mj_geomDistance`` between the
    finger's distal collision geoms and the object gives the finger surface point ``p_f`` closest
    to the object; ``e = p_f − p_target`` with ``p_f`` treated as fixed to its body for the
    Jacobian. Unlike a site-based target this does not depend on where a hand model puts its
    fingertip site: whatever part of the distal link meets the object, meets it at the human's
    contact point. ``pad_axis`` normal matching is not used here.

    Args:
        model, data: the retargeting scene; ``data.qpos[:hand_nq]`` is synchronised with ``q``.
        finger_geoms: per robot finger, its distal link's collision geom ids.
        object_geoms: the object's geom ids.
        part_geoms: per robot finger, the geom ids of each link that may hold its contact
            (``[0]`` is ``finger_geoms[f]``, then links towards the palm); :meth:`set_contacts`
            picks one per frame (a lateral pinch holds the object on the index finger's
            middle phalanx, not its tip). Default: the distal link only.
    """

    name = "contacts"
    memo_weights = False  # its weights follow the frame's contacts and ramps

    def __init__(
        self,
        model,
        data,
        finger_geoms,
        object_geoms,
        hand_nq: int,
        weight: float = 1.0,
        part_geoms=None,
        tangent_weight: float = 1.0,
    ):
        super().__init__(weight)
        import mujoco

        if not (np.isfinite(tangent_weight) and tangent_weight >= 0):
            raise RetargetError(f"contacts: tangent_weight must be >= 0, got {tangent_weight}")

        self._mj = mujoco
        self.model, self.data = model, data
        self.finger_geoms = [list(g) for g in finger_geoms]
        F = len(self.finger_geoms)
        self.part_geoms = (
            [[list(g)] for g in self.finger_geoms]
            if part_geoms is None
            else [[list(g) for g in parts] for parts in part_geoms]
        )
        """Per finger, the collision geoms of each of its links that can hold a contact: part 0
        is the distal link (``finger_geoms``), then the next links towards the palm."""
        if len(self.part_geoms) != F or any(
            not parts or parts[0] != f
            for parts, f in zip(self.part_geoms, self.finger_geoms, strict=True)
        ):
            raise RetargetError("contacts: part_geoms[f][0] must be finger_geoms[f]")
        self.object_geoms = list(object_geoms)
        self.hand_nq = hand_nq
        self.active = np.zeros(F, bool)
        self.points = np.zeros((F, 3))
        self.parts = np.zeros(F, int)
        self.ramp = np.ones(F)
        self.tangent_weight = tangent_weight
        """Weight factor of the error's tangential part (along the object surface at the
        target) relative to its normal part; 1: isotropic. Needs :meth:`set_contacts`'
        ``normals``."""
        self._split = False  # this frame's errors are in the targets' surface frames
        self._frames = np.zeros((F, 3, 3))  # per finger rows n, t1, t2 (when split)
        self._cache_q: bytes | None = None  # q of the cached finger points (_nearest)
        self.kinematics = None
        """Optional ``q → MjData`` with the scene's kinematics at hand configuration ``q``
        (the retargeter's ``ContactSweep.kinematics``: the sweep's own data when it is at
        ``q``); ``None``: ``mj_kinematics`` on ``data``."""
        self._bodies = [
            mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(model.nbody)
        ]

    def set_contacts(
        self,
        active: np.ndarray,
        points_world: np.ndarray,
        parts: np.ndarray | None = None,
        ramp: np.ndarray | None = None,
        normals: np.ndarray | None = None,
    ) -> None:
        """This frame's contacts: per finger, whether it touches, the surface point [m],
        (``parts``) which of its links touches (index into ``part_geoms[f]``; default 0, the
        distal link), (``ramp``, in [0, 1]) a factor on its weight (default 1) and
        (``normals``) the object's outward unit normals at the points, which split the error
        into its normal and tangential parts for :attr:`tangent_weight`."""
        a = np.asarray(active, bool)
        p = np.asarray(points_world, dtype=np.float64)
        F = len(self.finger_geoms)
        if a.shape != (F,) or p.shape != (F, 3):
            raise RetargetError(f"contacts: expected ({F},), ({F}, 3); got {a.shape}, {p.shape}")
        if not np.isfinite(p[a]).all():
            raise RetargetError("contacts: active contact points contain NaN")
        k = np.zeros(F, int) if parts is None else np.asarray(parts, dtype=int)
        if k.shape != (F,) or any(
            not 0 <= j < len(g) for j, g in zip(k.tolist(), self.part_geoms, strict=True)
        ):
            raise RetargetError(f"contacts: parts must be ({F},) link indices, got {k}")
        r = np.ones(F) if ramp is None else np.asarray(ramp, dtype=np.float64)
        if r.shape != (F,) or not (np.isfinite(r).all() and (r >= 0).all()):
            raise RetargetError(f"contacts: ramp must be ({F},) finite values >= 0, got {r}")
        self.active, self.points, self.parts, self.ramp = a, p, k, r
        self._split = normals is not None and self.tangent_weight != 1.0
        if self._split:
            from retarget.force_matching import tangent_basis

            n = np.asarray(normals, dtype=np.float64)
            if n.shape != (F, 3) or not np.isfinite(n[a]).all():
                raise RetargetError(f"contacts: normals must be ({F}, 3), finite where active")
            for i in np.flatnonzero(a).tolist():
                u = n[i] / np.linalg.norm(n[i])
                self._frames[i] = (u, *tangent_basis(u))
        self._cache_q = None

    def finger_points(self, q: np.ndarray) -> list[tuple[str, np.ndarray]]:
        """Per finger: (body name, surface point [m] of its contact link nearest the object)."""
        self._nearest(q)
        return [(b, p) for b, p in zip(self._cache_b, self._cache_p, strict=True)]

    def finger_point_array(self, q: np.ndarray) -> np.ndarray:
        """(F, 3) [m] the points of :meth:`finger_points` as one array (shared: do not modify)."""
        self._nearest(q)
        return self._cache_p

    def nearest_of(
        self, q: np.ndarray, idx: np.ndarray
    ) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
        """Fingers ``idx``' entries of :meth:`finger_points` and :meth:`finger_distances`:
        (body names, (k, 3) points [m], (k,) signed distances [m]), computing only theirs (the
        grip squeeze presses the contacting fingers)."""
        idx = np.asarray(idx, dtype=int)
        self._nearest(q, idx)
        bodies = tuple(self._cache_b[i] for i in idx.tolist())
        return bodies, self._cache_p[idx], self._cache_d[idx]

    def finger_distances(self, q: np.ndarray) -> np.ndarray:
        """(F,) [m] signed distance from each finger to the object (negative: penetrating)."""
        self._nearest(q)
        return self._cache_d

    def _nearest(self, q: np.ndarray, idx: np.ndarray | None = None) -> None:
        """Compute (once per ``q`` and :meth:`set_contacts`) the nearest points of fingers
        ``idx`` (default all) into ``_cache_b/p/d``: the QP's iterates need the active fingers
        only (Shadow on the speed benchmark: 2.3 of 5 per iterate on average)."""
        key = np.asarray(q, dtype=np.float64).tobytes()  # (cheaper than array_equal)
        F = len(self.part_geoms)
        if key != self._cache_q:
            # Fresh arrays: callers may hold the last configuration's.
            self._cache_q, self._done = key, np.zeros(F, bool)
            self._cache_b, self._cache_p, self._cache_d = [""] * F, np.zeros((F, 3)), np.zeros(F)
        todo = np.flatnonzero(~self._done) if idx is None else idx[~self._done[idx]]
        if not todo.size:
            return
        mj, m = self._mj, self.model
        if self.kinematics is not None:
            d = self.kinematics(q)
        else:
            d = self.data
            d.qpos[: self.hand_nq] = q
            mj.mj_kinematics(m, d)
        fromto = np.zeros(6)
        for f in todo.tolist():
            best, best_g = np.inf, -1
            for g in self.part_geoms[f][self.parts[f]]:
                for o in self.object_geoms:
                    dist = mj.mj_geomDistance(m, d, g, o, 1.0, fromto)
                    if dist < best:
                        best, best_g = dist, g
                        self._cache_p[f] = fromto[:3]
            self._cache_b[f] = self._bodies[m.geom_bodyid[best_g]] if best_g >= 0 else ""
            self._cache_d[f] = best
        self._done[todo] = True

    def distances_to_targets(self, q: np.ndarray) -> np.ndarray:
        """(F,) [m] distance from each finger's nearest surface point to its target."""
        pts = self.finger_points(q)
        return np.array([np.linalg.norm(p - t) for (_, p), t in zip(pts, self.points, strict=True)])

    def weights(self, m: int) -> np.ndarray:
        axes = [1.0, self.tangent_weight, self.tangent_weight] if self._split else [1.0] * 3
        return (float(self.weight) * self.ramp[self.active][:, None] * axes).reshape(-1)

    def _in_surface_frames(self, idx: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Per-contact vectors ``(k, 3)`` or Jacobians ``(k, 3, nv)`` of the fingers ``idx``,
        in their targets' (normal, t₁, t₂) frames when this frame's errors are split."""
        return np.einsum("kij,kj...->ki...", self._frames[idx], x) if self._split else x

    def error(self, state: RobotState) -> np.ndarray:
        """Per active finger ``p_f − p_target`` (world axes; in the target's normal/tangent
        frame when :meth:`set_contacts` got normals)."""
        if not self.active.any():
            return np.zeros(0)
        idx = np.flatnonzero(self.active)
        e = self.finger_point_array(state.q)[idx] - self.points[idx]
        return self._in_surface_frames(idx, e).reshape(-1)

    def jacobian(self, state: RobotState) -> np.ndarray:
        if not self.active.any():
            return np.zeros((0, state.nv))
        pts = self.finger_points(state.q)
        idx = np.flatnonzero(self.active)
        J = state.kin.point_jacobians(
            tuple(pts[i][0] for i in idx.tolist()), self.finger_point_array(state.q)[idx]
        )
        return self._in_surface_frames(idx, J).reshape(-1, state.nv)

    def _points_and_jacobians(self, state: RobotState, idx: np.ndarray):
        """The active fingers' (``idx``) surface points nearest the object (k, 3) [m] and
        their point Jacobians (k, 3, nv), world axes."""
        bodies, points, _ = self.nearest_of(state.q, idx)
        return points, np.ascontiguousarray(state.kin.point_jacobians(bodies, points))

    def qp_terms(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`error` and :meth:`jacobian` in one pass over the active fingers (the same
        ``(H, c)`` as the base class's; a test pins the two)."""
        nv = state.nv
        idx = np.flatnonzero(self.active)
        if not idx.size:
            return np.zeros((nv, nv)), np.zeros(nv)
        points, J = self._points_and_jacobians(state, idx)
        e = self._in_surface_frames(idx, points - self.points[idx]).reshape(-1)
        J = self._in_surface_frames(idx, J).reshape(-1, nv)
        JW = J.T * self.weights(e.size)
        return JW @ J, JW @ e

    def accumulate(self, state: RobotState, P: np.ndarray, c: np.ndarray) -> None:
        idx = np.flatnonzero(self.active)
        if idx.size:
            points, J = self._points_and_jacobians(state, idx)
            surface_gram(
                J, points, self.points, self._frames, idx, self._split, float(self.weight),
                self.ramp, self.tangent_weight, P, c,
            )  # fmt: skip
