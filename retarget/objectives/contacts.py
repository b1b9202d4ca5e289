"""Contact preservation: robot links touch the object where the human touched it (surface
contacts, closing terms); their settings (``ContactsConfig``, ``ClosingConfig``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import mujoco
import numpy as np

from dexcanvas_core.rotations import tangent_basis
from retarget._checks import check_choice, check_range
from retarget.errors import RetargetError
from retarget.objectives._kernels import surface_gram, weighted_gram
from retarget.objectives.base import Objective
from retarget.objectives.link_distance import link_distance
from retarget.state import RobotState

ContactSource = Literal["geometry", "records"]


@dataclass(frozen=True, kw_only=True)
class ContactsConfig:
    """The contact terms (``SurfaceContactObjective``): where the human touches the object, the
    robot link goes to the same surface point. Chosen on the retargeting and force-preservation
    benchmarks; docs/method.md#contacts."""

    enabled: bool = True
    """Add the contact terms to the QP (the contacts are still measured). Default True."""
    weight: float = 200.0
    """Weight of a contact's error across the surface [per m²]. Default 200."""
    tangent_weight: float = 0.01
    """Factor on ``weight`` of a contact's error along the surface (1: isotropic; force matching
    uses ``ForceMatchingConfig.tangent_weight``). Default 0.01."""
    hover_m: float | None = 0.005
    """Scale ``h`` [m] over which a contact's error across the surface turns from the link
    point's offset along the human contact's normal to the link's signed distance to the
    object (``SurfaceContactObjective.hover``); None: always the offset. Default 0.005."""
    ramp_s: float = 0.0
    """A contact's weight ramps up over its first and down over its last this many seconds
    (0: off). Default 0."""
    link_contacts: bool = True
    """A finger touching with its distal pad, middle or proximal phalanx but not its tip
    keypoint gets the contact on the corresponding robot link. Default True."""
    link_threshold_m: float = 0.011
    """Distance [m] from a human phalanx's bone axis to the surface below which that phalanx
    touches (inferred contacts). Default 0.011."""
    threshold_m: float = 0.012
    """Human fingertip keypoint–surface distance [m] below which a fingertip touches (inferred
    contacts). Default 0.012."""
    source: ContactSource = "geometry"
    """Which human phalanges touch: ``geometry`` (inferred from the captured keypoints and the
    surface) or ``records`` (the force pipeline's contact records). Default ``geometry``."""

    def __post_init__(self):
        check_range(self, "weight")
        check_range(self, "tangent_weight")
        check_range(self, "hover_m", optional=True, unit="m")
        check_range(self, "ramp_s", unit="s")
        check_choice(self, "source", ContactSource)


@dataclass(frozen=True, kw_only=True)
class ClosingConfig:
    """The closing terms of ``SurfaceContactObjective`` (see there). docs/method.md#contacts."""

    weight: float = 50.0
    """Weight [per m²] of each closing term (0: only the contact's link). Default 50."""
    slack_m: float = 0.004
    """A closing link within this [m] of the object is left where it is. Default 0.004."""
    ramp_s: float = 0.5
    """A closing term's weight rises from 0 to ``weight`` over this long [s] after its human
    phalanx began to touch. Default 0.5."""

    def __post_init__(self):
        check_range(self, "weight")
        check_range(self, "slack_m", unit="m")
        check_range(self, "ramp_s", unit="s")


class SurfaceContactObjective(Objective):
    """Active contacts: the robot finger's surface point nearest the object goes to the target.

    For each robot finger with an active contact, MuJoCo's ``mj_geomDistance`` between the
    finger's distal collision geoms and the object gives the finger surface point ``p_f`` closest
    to the object; ``e = p_f − p_target`` with ``p_f`` treated as fixed to its body for the
    Jacobian. Unlike a site-based target this does not depend on where a hand model puts its
    fingertip site: whatever part of the distal link meets the object, meets it at the human's
    contact point. ``pad_axis`` normal matching is not used here.

    With the target's surface normal ``n`` (:meth:`set_contacts`' ``normals``) the error is
    split into its part across the surface, ``nᵀ(p_f − p_target)``, and its part along it
    (``tangent_weight``). The part across is zero wherever ``p_f`` lies in the target's
    tangent plane, which a link can do far off a curved surface (a straight finger over an
    apple, its nearest point level with the human's contact). With ``hover`` = ``h`` [m], the
    error across is ``o + φ(d − o)`` instead, ``o`` that offset, ``d`` the link's signed
    distance to the object (the two geoms' distance, negative when penetrating),
    ``φ(x) = x²/h`` for ``0 ≤ x < h``, ``x`` beyond and 0 below (once continuously
    differentiable); its Jacobian is ``(n + φ'(x)(g − n))ᵀ J(p_f)``, ``g`` the unit direction
    in which ``d`` grows at ``p_f``. A link hovering off a curved surface is pulled onto it;
    on a flat face and near the human's point (``d ≈ o``) the offset stays, which brings the
    link in along the human's normal rather than onto whatever part of the object is nearest.

    Closing terms (``closing_weight`` > 0, :meth:`set_contacts`' ``closing``): a finger's other
    links whose human phalanx touches the object too (a power grasp's middle phalanges) are
    pulled to within ``closing_slack`` of the surface, ``e = d − closing_slack`` per link
    farther than that (``d`` its signed distance to the object), so that the finger wraps the
    object as the human's does instead of touching it with the contact's link alone. Links
    already that near are left alone (pushed onto the surface exactly, a pinch's thumb turns
    about its pad).

    Args:
        model, data: the retargeting scene; ``data.qpos[:hand_nq]`` is synchronised with ``q``.
        finger_geoms: per robot finger, its distal link's collision geom ids.
        object_geoms: the object's geom ids.
        part_geoms: per robot finger, the geom ids of each link that may hold its contact
            (``[0]`` is ``finger_geoms[f]``, then links towards the palm); :meth:`set_contacts`
            picks one per frame (a lateral pinch holds the object on the index finger's
            middle phalanx, not its tip). Default: the distal link only.
        tangent_weight: weight factor of the error along the surface (1: isotropic).
        hover: the scale ``h`` [m] over which the error across the surface turns from the
            offset along the target's normal to the link's signed distance to the object where
            the distance exceeds the offset (see above); ``None`` (default): always the offset.
        closing_weight: weight [per m²] of each closing term (0: none).
        closing_reach: links farther than this [m] from the object get no closing term (a
            linear pull from farther away is no model of the distance).
        closing_slack: a closing link within this [m] of the object is left where it is (its
            term is ``d − closing_slack`` beyond it, none within: it pulls, never pushes).
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
        hover: float | None = None,
        closing_weight: float = 0.0,
        closing_reach: float = 0.05,
        closing_slack: float = 0.0,
    ):
        super().__init__(weight)
        if not (np.isfinite(tangent_weight) and tangent_weight >= 0):
            raise RetargetError(f"contacts: tangent_weight must be >= 0, got {tangent_weight}")
        if not (np.isfinite(closing_weight) and closing_weight >= 0):
            raise RetargetError(f"contacts: closing_weight must be >= 0, got {closing_weight}")
        if not (np.isfinite(closing_reach) and closing_reach > 0):
            raise RetargetError(f"contacts: closing_reach must be > 0 [m], got {closing_reach}")
        if not (np.isfinite(closing_slack) and 0 <= closing_slack < closing_reach):
            raise RetargetError(
                f"contacts: closing_slack must be in [0, closing_reach) [m], got {closing_slack}"
            )

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
        if hover is not None and not (np.isfinite(hover) and hover >= 0):
            raise RetargetError(f"contacts: hover must be None or >= 0 [m], got {hover}")
        self.hover = hover
        """The scale [m] over which a link's error across the surface turns from its offset
        along the target's normal to its signed distance to the object (see the class
        docstring; needs :meth:`set_contacts`' ``normals``); ``None``: always the offset."""
        self.closing_weight = float(closing_weight)
        self.closing_reach = float(closing_reach)
        self.closing_slack = float(closing_slack)
        self.closing = np.zeros((F, 3))
        """This frame's closing terms: per finger and part (as ``part_geoms``), the factor on
        :attr:`closing_weight` with which that link is pulled onto the surface (0: not; only
        where the finger's contact is active and the link is not the contact's own)."""
        self._split = False  # this frame's errors are in the targets' surface frames
        self._gap = False  # this frame's normal rows may be the links' signed distances
        self._frames = np.zeros((F, 3, 3))  # per finger rows n, t1, t2 (when split)
        self._cache_q: bytes | None = None  # q of the cached finger points (_nearest)
        self._closing_q: bytes | None = None  # q of the cached closing terms (_closing_terms)
        self._closing_links: list[tuple[int, list[int], float]] = []  # (finger, geoms, factor)
        self._closing_cache = None  # (fingers, bodies, points, errors, directions, weights)
        self._no_gap = (np.zeros(F), np.zeros((F, 3)))
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
        closing: np.ndarray | None = None,
    ) -> None:
        """This frame's contacts: per finger, whether it touches, the surface point [m],
        (``parts``) which of its links touches (index into ``part_geoms[f]``; default 0, the
        distal link), (``ramp``, in [0, 1]) a factor on its weight (default 1),
        (``normals``) the object's outward unit normals at the points, which split the error
        into its normal and tangential parts for :attr:`tangent_weight` (and make the normal
        part the link's distance where it hovers, :attr:`hover`), and (``closing``, (F, 3))
        the other links of each finger whose human phalanx touches the object (closing terms:
        flags, or factors on :attr:`closing_weight`; default none)."""
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
        self._gap = normals is not None and self.hover is not None
        self._split = normals is not None and (self.tangent_weight != 1.0 or self._gap)
        if self._split:
            n = np.asarray(normals, dtype=np.float64)
            if n.shape != (F, 3) or not np.isfinite(n[a]).all():
                raise RetargetError(f"contacts: normals must be ({F}, 3), finite where active")
            for i in np.flatnonzero(a).tolist():
                u = n[i] / np.linalg.norm(n[i])
                self._frames[i] = (u, *tangent_basis(u))
        self._cache_q = None
        self._closing_q = None
        self._closing_cache = None
        self._closing_links = []
        if closing is not None and self.closing_weight > 0:
            c = np.asarray(closing, dtype=np.float64)
            if c.shape != (F, 3) or not (np.isfinite(c).all() and (c >= 0).all()):
                raise RetargetError(
                    f"contacts: closing must be ({F}, 3) flags or factors >= 0, got {c.shape}"
                )
            self.closing = c * a[:, None]
            for f in np.flatnonzero(self.closing.any(axis=1)).tolist():
                parts = self.part_geoms[f]
                links = {}  # the contact's own link holds no closing term
                for j in np.flatnonzero(self.closing[f]).tolist():
                    if j < len(parts) and parts[j] != parts[k[f]]:
                        key = tuple(parts[j])  # (a two-link finger's parts 1 and 2 share one)
                        links[key] = max(links.get(key, 0.0), float(self.closing[f, j]))
                self._closing_links += [(f, list(g), w) for g, w in links.items()]
        else:
            self.closing = np.zeros((F, 3))

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

    def nearest_directions(self, q: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """(k, 3) for fingers ``idx``: the unit direction in which each contact link's signed
        distance to the object grows at its nearest point (away from the object: the object's
        outward normal where the link is nearest it; the target's normal where the two nearest
        points coincide, zeros before :meth:`set_contacts` gave normals)."""
        idx = np.asarray(idx, dtype=int)
        self._nearest(q, idx)
        return self._cache_g[idx].copy()

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
            self._cache_g = np.zeros((F, 3))
        todo = np.flatnonzero(~self._done) if idx is None else idx[~self._done[idx]]
        if not todo.size:
            return
        d = self.kinematics(q) if self.kinematics is not None else self._posed_data(q)
        for f in todo.tolist():
            body, self._cache_p[f], self._cache_d[f], self._cache_g[f] = self._link_distance(
                d, self.part_geoms[f][self.parts[f]], 1.0, self._frames[f, 0]
            )
            self._cache_b[f] = body
        self._done[todo] = True

    def _link_distance(self, d, geoms, reach: float, fallback: np.ndarray):
        """``(body, p, dist, g)`` of the link with collision ``geoms`` against the object in
        ``d`` (:func:`link_distance`)."""
        return link_distance(self.model, d, geoms, self.object_geoms, self._bodies, reach, fallback)

    def _closing_terms(self, q: np.ndarray):
        """This frame's closing terms at ``q`` (cached per ``q``): ``(fingers (k,), bodies,
        points (k, 3) [m], errors (k,) [m], directions (k, 3), weights (k,))`` of the closing
        links between :attr:`closing_slack` and :attr:`closing_reach` from the object, each
        error the link's signed distance less the slack (see :meth:`_link_distance`)."""
        key = np.asarray(q, dtype=np.float64).tobytes()
        if key == self._closing_q:
            return self._closing_cache
        fingers, bodies, P, D, G, W = [], [], [], [], [], []
        if self._closing_links:
            d = self.kinematics(q) if self.kinematics is not None else self._posed_data(q)
            for f, geoms, factor in self._closing_links:
                body, p, dist, g = self._link_distance(
                    d, geoms, self.closing_reach, self._frames[f, 0]
                )
                if self.closing_slack < dist < self.closing_reach and body:
                    fingers.append(f)
                    bodies.append(body)
                    P.append(p)
                    D.append(dist - self.closing_slack)
                    G.append(g)
                    W.append(self.closing_weight * factor * self.ramp[f])
        self._closing_q = key
        self._closing_cache = (
            np.array(fingers, dtype=np.int64),
            tuple(bodies),
            np.array(P, dtype=np.float64).reshape(-1, 3),
            np.array(D, dtype=np.float64),
            np.array(G, dtype=np.float64).reshape(-1, 3),
            np.array(W, dtype=np.float64),
        )
        return self._closing_cache

    def _posed_data(self, q: np.ndarray):
        """The scene's data at hand configuration ``q`` (``mj_kinematics``)."""
        d = self.data
        d.qpos[: self.hand_nq] = q
        self._mj.mj_kinematics(self.model, d)
        return d

    def distances_to_targets(self, q: np.ndarray) -> np.ndarray:
        """(F,) [m] distance from each finger's nearest surface point to its target."""
        pts = self.finger_points(q)
        return np.array([np.linalg.norm(p - t) for (_, p), t in zip(pts, self.points, strict=True)])

    def weights(self, m: int) -> np.ndarray:
        axes = [1.0, self.tangent_weight, self.tangent_weight] if self._split else [1.0] * 3
        w = (float(self.weight) * self.ramp[self.active][:, None] * axes).reshape(-1)
        if m > w.size and self._closing_cache is not None:
            # The closing rows of the last error() / jacobian(), one per term.
            w = np.concatenate([w, self._closing_cache[5][: m - w.size]])
        return w

    def _in_surface_frames(self, idx: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Per-contact vectors ``(k, 3)`` or Jacobians ``(k, 3, nv)`` of the fingers ``idx``,
        in their targets' (normal, t₁, t₂) frames when this frame's errors are split."""
        return np.einsum("kij,kj...->ki...", self._frames[idx], x) if self._split else x

    def _contact_rows(self, q: np.ndarray, idx: np.ndarray, points: np.ndarray, J: np.ndarray):
        """The active fingers' (``idx``) errors (k, 3) and Jacobians (k, 3, nv) from their
        link points ``points`` and point Jacobians ``J``: in the surface frames when split,
        the normal row the link's signed distance where it hovers (:attr:`hover`)."""
        e = self._in_surface_frames(idx, points - self.points[idx])
        Js = self._in_surface_frames(idx, J)
        if self._gap:
            gap, gdir = self._gap_rows(q, idx)
            e[:, 0] = gap
            Js[:, 0] = np.einsum("ki,kij->kj", gdir, J)
        return e, Js

    def _closing_rows(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        """The closing terms' errors (k,) [m] and Jacobians (k, nv) at ``state``."""
        fingers, bodies, P, D, G, _ = self._closing_terms(state.q)
        if not fingers.size:
            return np.zeros(0), np.zeros((0, state.nv))
        Jp = state.kin.point_jacobians(bodies, P)
        return D.copy(), np.einsum("ki,kij->kj", G, Jp)

    def _rows(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        """Every row's error (m,) and Jacobian (m, nv): the active contacts' (3 each, see
        :meth:`error`), then the closing terms' (one each)."""
        nv = state.nv
        idx = np.flatnonzero(self.active)
        if not idx.size:
            return np.zeros(0), np.zeros((0, nv))
        points, Jw = self._points_and_jacobians(state, idx)
        e, J = self._contact_rows(state.q, idx, points, Jw)
        ec, Jc = self._closing_rows(state)
        return (
            np.concatenate([e.reshape(-1), ec]),
            np.concatenate([J.reshape(-1, nv), Jc], axis=0),
        )

    def error(self, state: RobotState) -> np.ndarray:
        """Per active finger ``p_f − p_target`` (world axes; in the target's normal/tangent
        frame when :meth:`set_contacts` got normals, the normal row then the link's signed
        distance to the object where it hovers, :attr:`hover`), then one row per closing term (the
        link's signed distance [m])."""
        return self._rows(state)[0]

    def jacobian(self, state: RobotState) -> np.ndarray:
        return self._rows(state)[1]

    def _points_and_jacobians(self, state: RobotState, idx: np.ndarray):
        """The active fingers' (``idx``) surface points nearest the object (k, 3) [m] and
        their point Jacobians (k, 3, nv), world axes."""
        bodies, points, _ = self.nearest_of(state.q, idx)
        return points, np.ascontiguousarray(state.kin.point_jacobians(bodies, points))

    def qp_terms(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`error` and :meth:`jacobian` in one pass over the active fingers (the same
        ``(H, c)`` as the base class's; a test pins the two)."""
        nv = state.nv
        if not self.active.any():
            return np.zeros((nv, nv)), np.zeros(nv)
        e, J = self._rows(state)
        JW = J.T * self.weights(e.size)
        return JW @ J, JW @ e

    def accumulate(self, state: RobotState, P: np.ndarray, c: np.ndarray) -> None:
        idx = np.flatnonzero(self.active)
        if not idx.size:
            return
        points, J = self._points_and_jacobians(state, idx)
        gap, gdir = self._gap_rows(state.q, idx)
        surface_gram(
            J, points, self.points, self._frames, idx, self._split, float(self.weight),
            self.ramp, self.tangent_weight, self._gap, gap, gdir, P, c,
        )  # fmt: skip
        if self._closing_links:
            ec, Jc = self._closing_rows(state)
            if ec.size:
                weighted_gram(np.ascontiguousarray(Jc), self._closing_cache[5], ec, P, c)

    def _gap_rows(self, q: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The active fingers' (``idx``) errors across the surface (k,) [m] and the directions
        (k, 3) of their rows (the rows' Jacobians are ``directionᵀ J``): with ``o`` the
        offset along the target's normal ``n``, ``d`` the link's signed distance, its
        direction ``g``, ``x = d − o`` and ``h`` = :attr:`hover`, the error is ``o + φ(x)``
        with ``φ(x) = x²/h`` below ``h`` and ``x`` beyond (0 for ``x ≤ 0``; once continuously
        differentiable, so the iterations do not flip between two rows), its direction
        ``n + φ'(x)(g − n)``. Zeros without :attr:`hover` (the kernel then takes the targets'
        normals)."""
        if not self._gap:
            return self._no_gap[0][: idx.size], self._no_gap[1][: idx.size]
        self._nearest(q, idx)
        n = self._frames[idx, 0]
        offset = np.einsum("ki,ki->k", n, self._cache_p[idx] - self.points[idx])
        x = np.maximum(self._cache_d[idx] - offset, 0.0)
        h = self.hover
        if h > 0:
            near = x < h
            phi = np.where(near, x * x / h, x)
            dphi = np.where(near, 2.0 * x / h, 1.0)
        else:
            phi, dphi = x, (x > 0).astype(np.float64)
        return offset + phi, n + dphi[:, None] * (self._cache_g[idx] - n)
