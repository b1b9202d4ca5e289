"""Non-penetration: linearised signed distances from MuJoCo's collision queries.

For each geom pair closer than ``distmax``, ``mj_geomDistance`` gives the signed distance ``d``
[m] and the nearest points ``p₁`` (hand geom) and ``p₂``. With ``n`` the unit direction from
``p₁`` to ``p₂`` (flipped when penetrating), moving the hand by ``Δq`` changes the distance by
``−nᵀ(J₁ − J₂)Δq`` to first order, so ``d − nᵀ(J₁ − J₂)Δq ≥ −margin`` becomes the row
``nᵀ(J₁ − J₂) Δq ≤ d + margin``. ``J₂`` is zero for the object (it is kinematic in the
retargeting scene), and the other hand body's point Jacobian for self-collision pairs.

Two ways to find the pairs within ``distmax``, with the same result:

* per pair (default): a broad phase drops the pairs whose bounding spheres (MuJoCo's
  ``geom_rbound`` about ``geom_xpos``; against a box, such as the table, the hand geom's
  bounding sphere against the box; a plane's half-space) are farther apart than
  ``distmax``, all at once; the survivors go through ``mj_geomDistance`` one by one;
* one sweep (:class:`ContactSweep`): ``mj_collision`` finds every contact within the model's
  geom margins in C, once per configuration, shared by several limits (hand–object and self
  collision) and the metrics. For pairs with a sphere, capsule or plane, ``mj_geomDistance`` is
  the same narrow phase (the pair's collision function run with ``distmax`` as margin, keeping
  its closest contact), so the sweep keeps each pair's closest contact; it needs those pairs to
  pass MuJoCo's contact filters and margins of at least ``distmax``, which
  :class:`CollisionLimit` checks. Capsule–cylinder pairs are the exception (``swept_pair``:
  the sweep puts some capsules near a cylinder's cap up to 19 mm too far). Those, box–box and
  mesh pairs keep the per-pair path (``mj_collision``'s multi-contact routines report depths
  up to millimetres off the Euclidean distance that ``mj_geomDistance`` computes). Mesh pairs
  come closer but not close enough (SVH, Ability and Panda on the example cube2, 60 frames of
  random finger poses, MuJoCo 4.0.1: every pair found, distances within 0.32 mm, but the
  directions differ by up to 10° at 3 mm or more apart and 27° when penetrating); the sweep
  does find them, so the mesh pairs it reports are their per-pair candidates, in place of the
  bounding-sphere broad phase (SVH, Ability and Panda, twelve objects, retargeted and random
  poses: none missing in 30,000 checks of mesh pairs within ``distmax``). A mesh pair whose
closest contact in the sweep is at least ``CollisionLimit.MESH_FAR`` beyond its allowed
distance takes that contact, and no ``mj_geomDistance`` call: such a pair is far from binding,
and its further contacts give it rows anyway (SVH on the speed benchmark's first 10 pairs:
26 ``mj_geomDistance`` calls per frame instead of 49).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from retarget._checks import check_range
from retarget.errors import RetargetError
from retarget.kinematics import PinocchioKinematics
from retarget.limits import _kernels
from retarget.limits.base import Limit
from retarget.limits.sweep import ContactSweep, PairDistances, pose_scene, swept_pair
from retarget.state import RobotState


@dataclass(frozen=True, kw_only=True)
class CollisionConfig:
    """The hand–object non-penetration limit (:class:`CollisionLimit`), with the table's and
    the non-contact links' clearances. docs/method.md#limits."""

    enabled: bool = True
    """Add the non-penetration rows to the QP (the distances are still measured). Default
    True."""
    penetration_margin: float = 0.001
    """Penetration [m] the non-penetration rows allow (soft contacts need a little). Default
    0.001."""
    table_clearance: float = 0.003
    """Height [m] the hand's collision geoms keep above the table. Default 0.003."""
    noncontact_clearance: float = 0.002
    """Distance [m] a robot finger link keeps from the object on frames where the human's
    corresponding phalanx does not touch it (0: only non-penetration). Default 0.002."""
    distmax: float = 0.03
    """Hand–object pairs farther than this [m] are left out of an iterate. Default 0.03."""

    def __post_init__(self):
        for name in ("penetration_margin", "table_clearance", "noncontact_clearance"):
            check_range(self, name, unit="m")
        check_range(self, "distmax", positive=True, unit="m")


@dataclass(frozen=True, kw_only=True)
class SelfCollisionConfig:
    """The self-collision limit: the collision geoms of different fingers (and of fingers and
    palm; ``HandModel.self_collision_pairs``) kept apart."""

    enabled: bool = True
    """Add the self-collision rows to the QP (the distances are still measured). Default
    True."""
    margin: float = 0.001
    """Finger–finger penetration [m] the self-collision rows allow. Default 0.001."""
    distmax: float = 0.01
    """Hand–hand pairs farther than this [m] are left out of an iterate. Default 0.01."""

    def __post_init__(self):
        check_range(self, "margin", unit="m")
        check_range(self, "distmax", positive=True, unit="m")


class CollisionLimit(Limit):
    """Keep geom pairs apart (hand–object, or hand–hand for self-collision).

    Args:
        model, data: the MuJoCo scene (hand + object); ``data.qpos[:nq_hand]`` is synchronised
            with the solver's ``q`` and the object pose is set by the caller (mocap body).
        pairs: ``(geom_a, geom_b)`` ids; ``geom_a`` must belong to the hand (and ``geom_b`` too
            with ``self_collision``).
        hand_nq: number of hand joints (the first ``hand_nq`` entries of ``qpos``).
        margin: allowed penetration [m] (e.g. 0.002).
        pair_margins: per pair, instead of ``margin`` (negative: a clearance the pair keeps).
        distmax: pairs farther than this [m] are ignored this iterate.
        self_collision: ``geom_b`` moves with the hand too (``J = J_a − J_b``).
        sweep: find the pairs with a sphere, capsule or plane from this shared ``mj_collision``
            sweep instead of one ``mj_geomDistance`` per pair (same result; see the module
            docstring); the other pairs keep the per-pair path.
        max_recovery: how far [m] a pair already deeper than ``margin`` is asked to back out
            in one step (the row's right side is ``max(d + margin, −max_recovery)``); ``None``:
            all the way at once. A cap keeps the QP feasible when a large step (e.g. the first
            frame's, from the open posture) has pushed two fingers deep into each other and the
            joint ranges forbid undoing it in one step; the rest is recovered over later steps.
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
        max_recovery: float | None = None,
        sweep: ContactSweep | None = None,
        pair_margins: Sequence[float] | None = None,
    ):
        if not (np.isfinite(margin) and margin >= 0):
            raise RetargetError(f"collision margin must be finite and >= 0, got {margin}")
        if not (np.isfinite(distmax) and distmax > 0):
            raise RetargetError(f"collision distmax must be finite and > 0, got {distmax}")
        self.model, self.data = model, data
        self.pairs = [(int(a), int(b)) for a, b in pairs]
        for a, b in self.pairs:
            if not (0 <= a < model.ngeom and 0 <= b < model.ngeom):
                raise RetargetError(f"collision pair ({a}, {b}): geom ids must be < {model.ngeom}")
        self.hand_nq = hand_nq
        self.margin = margin
        self.pair_margins = np.full(len(self.pairs), float(margin))
        if pair_margins is not None:
            pm = np.asarray(pair_margins, dtype=np.float64)
            if pm.shape != (len(self.pairs),) or not np.isfinite(pm).all():
                raise RetargetError(f"pair_margins must be {len(self.pairs)} finite values [m]")
            self.pair_margins = pm
        self.distmax = distmax
        self.self_collision = self_collision
        if max_recovery is not None and not (np.isfinite(max_recovery) and max_recovery >= 0):
            raise RetargetError(f"max_recovery must be finite and >= 0, got {max_recovery}")
        self.max_recovery = max_recovery
        self.hold_only = False
        """Rows only forbid going deeper (``h ≥ 0``) instead of asking a penetrating pair to
        back out: the solver's fallback when backing out is infeasible (joint limits)."""
        self._near = np.zeros(0, int)  # pairs near at the last inequalities() (near_violation)
        self._near_pred: tuple = ()  # (q, G, near_rows, near_slack) of that linearisation
        self._check_data: mujoco.MjData | None = None
        self._body_names = [
            mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(model.nbody)
        ]
        ga = np.array([a for a, _ in self.pairs], dtype=int)
        gb = np.array([b for _, b in self.pairs], dtype=int)
        self._ga, self._gb = ga, gb
        self._ga_list, self._gb_list = ga.tolist(), gb.tolist()
        plane = int(mujoco.mjtGeom.mjGEOM_PLANE)
        if np.any(model.geom_type[ga] == plane):
            raise RetargetError("collision pairs: geom_a must be a hand geom, not a plane")
        swept = np.zeros(len(self.pairs), bool)
        if sweep is not None:
            t = model.geom_type
            swept = np.array([swept_pair(int(t[a]), int(t[b])) for a, b in self.pairs])
        self._swept = np.flatnonzero(swept)
        self._bodies_a = np.array([self._body_names[b] for b in model.geom_bodyid[ga]], object)
        self._bodies_b = np.array([self._body_names[b] for b in model.geom_bodyid[gb]], object)
        self._fromto = np.zeros(6)
        self._direct_seen = np.zeros(0, int)
        self._mesh_seen = np.zeros(0, int)  # the per-pair pairs with a mesh the sweep sees
        self._direct_offset = 0
        self._no_rows = (np.zeros(0, int), np.zeros((0, _kernels.WIDTH)))
        for x in self._no_rows:
            x.flags.writeable = False
        self.sweep = sweep
        self._cached: tuple[tuple, tuple] | None = None  # ((sweep, distmax, margins), _answer)
        self._masks = None  # (kinematics, dof masks of the pairs' bodies a and b): inequalities
        self._maps: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # see _sweep_maps
        if sweep is not None:
            if sweep.model is not model or sweep.data is not data:
                raise RetargetError("the contact sweep must run on the limit's own model and data")
            for a, b in (self.pairs[i] for i in self._swept):
                reach = sweep.query_distance(a, b)
                names = f"({model.geom(a).name}, {model.geom(b).name})"
                if reach == -np.inf:
                    raise RetargetError(
                        f"collision pair {names} is filtered out of mj_collision (contype/"
                        "conaffinity, parent/child or excluded): the sweep would never see it"
                    )
                if reach < distmax:
                    raise RetargetError(
                        f"collision pair {names}: mj_collision margin {reach} < distmax "
                        f"{distmax}; ContactSweep.set_margins first"
                    )
            self._offset = sweep.register([self.pairs[i] for i in self._swept])
            # The per-pair pairs (box–box, mesh, cylinder) are registered too, for their
            # further contacts (see row_points); their distances stay mj_geomDistance's.
            direct = np.setdiff1d(np.arange(len(self.pairs)), self._swept)
            seen = [i for i in direct.tolist() if sweep.query_distance(*self.pairs[i]) >= distmax]
            self._direct_seen = np.array(seen, dtype=int)
            self._direct_offset = sweep.register([self.pairs[i] for i in seen])
            # Mesh pairs the sweep sees: it reports their contacts out to its margins
            # (≥ distmax), so their candidates are the pairs it reports; the broad phase keeps
            # the others (mj_collision's box–box routine misses pairs millimetres inside its
            # margin, see the module docstring).
            mesh = int(mujoco.mjtGeom.mjGEOM_MESH)
            self._mesh_seen = np.array(
                [i for i in seen if mesh in (t[self.pairs[i][0]], t[self.pairs[i][1]])], dtype=int
            )
        self._broad_phase_sets(np.setdiff1d(np.flatnonzero(~swept), self._mesh_seen))

    def _broad_phase_sets(self, pairs: np.ndarray) -> None:
        """The broad phase's pairs (indices, no swept ones) and their reaches."""
        m, ga, gb, distmax = self.model, self._ga, self._gb, self.distmax
        b_plane = m.geom_type[gb[pairs]] == mujoco.mjtGeom.mjGEOM_PLANE
        # Sphere pairs: bounding spheres about geom_xpos; centre distance beyond the radii's sum
        # plus distmax cannot be within distmax.
        self._sph = pairs[~b_plane]
        self._sph_a, self._sph_b = ga[self._sph], gb[self._sph]
        reach = m.geom_rbound[self._sph_a] + m.geom_rbound[self._sph_b] + distmax
        self._sph_reach2 = reach**2
        # Box–box pairs also take the boxes' separating axis test (Allegro's self pairs: 22
        # broad-phase candidates per iterate with the spheres, 5 with the boxes, 4.5 within
        # distmax; built-in demonstrations).
        box = mujoco.mjtGeom.mjGEOM_BOX
        self._box = (m.geom_type[self._sph_a] == box) & (m.geom_type[self._sph_b] == box)
        self._box_a = m.geom_size[self._sph_a] + distmax
        self._box_b = m.geom_size[self._sph_b].copy()
        # Other pairs with a box second (the table: a bounding sphere of some 0.7 m, so the
        # sphere test keeps every hand geom) take the first geom's bounding sphere against the
        # box.
        self._obb = (m.geom_type[self._sph_b] == box) & ~self._box
        self._obb_reach = m.geom_rbound[self._sph_a] + distmax
        # Plane pairs (geom_b a plane, e.g. a floor): the hand geom's bounding sphere against
        # the plane's half-space.
        self._pln = pairs[b_plane]
        self._pln_a, self._pln_b = ga[self._pln], gb[self._pln]
        self._pln_reach = m.geom_rbound[self._pln_a] + distmax

    def candidates(self) -> np.ndarray:
        """Indices of the per-pair pairs whose bounding volumes are within ``distmax`` (broad
        phase), except those a contact sweep sees (:meth:`_answer` takes theirs from it).

        Uses the geom poses already in ``data`` (call after ``mj_kinematics``).
        """
        d = self.data
        return _kernels.broad_phase(
            d.geom_xpos, d.geom_xmat, self._sph, self._sph_a, self._sph_b, self._sph_reach2,
            self._box, self._box_a, self._box_b, self._obb, self._obb_reach,
            self._pln, self._pln_a, self._pln_b, self._pln_reach,
        )  # fmt: skip

    def query(self, q: np.ndarray) -> PairDistances:
        """Signed distances and nearest points of every pair within ``distmax`` at ``q`` (those
        of the mesh pairs beyond :attr:`MESH_FAR` from the sweep: within 0.32 mm)."""
        index, rows, n_first = self._answer(q)
        return _pair_distances(index[:n_first], rows[:n_first])

    def _answer(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """The rows at ``q``: ``(index, rows, n_first)``, pair indices and packed rows
        (:mod:`retarget.limits._kernels`) of, first, every pair within ``distmax`` at its
        closest points (:meth:`query`: the swept pairs', then the per-pair ones'), ``n_first``
        of them, then the further contacts ``mj_collision`` reports for the same pairs
        (:meth:`row_points`). Read-only.

        Kept with the sweep's version: the warm-start check, the first iterate's rows and the
        step's end check ask at the same configuration (box and mesh pairs' mj_geomDistance
        calls and the selection are then done once)."""
        sw = self.sweep
        if sw is None:
            index, rows = self._query_direct(q)
            return index, rows, index.size
        sw.update(q)  # (leaves data at q)
        # (the margins set which mesh pairs take their distance from the sweep: MESH_FAR)
        key = (sw.version, self.distmax, self.pair_margins.tobytes())
        if self._cached is not None and self._cached[0] == key:
            return self._cached[1]
        swept_map, every_map, mesh_map = self._sweep_maps()
        pm, far = self.pair_margins, self.MESH_FAR
        index, rows, n_first = _kernels.limit_select(
            sw.pair, sw.closest, sw.rows, swept_map, every_map, mesh_map, pm, far, self.distmax
        )
        if self._swept.size != len(self.pairs):
            # The per-pair pairs the sweep reports a contact for (within its margins: their
            # mj_collision distances are within 0.32 mm of mj_geomDistance's, see the module
            # docstring) nearer than MESH_FAR, and the broad phase's: SVH's 236 per-pair
            # pairs, retargeting the built-in cube1, had 52 broad-phase candidates per
            # iterate, 17 of them within distmax; 22 candidates with the sweep's pairs.
            idx = _kernels.seen_candidates(
                sw.pair, sw.closest, sw.rows, mesh_map, pm, far, self.candidates()
            )
            d_index, d_rows = self._query_direct(q, kinematics=False, idx=idx)
            if d_index.size:
                index = np.concatenate([index[:n_first], d_index, index[n_first:]])
                rows = np.concatenate([rows[:n_first], d_rows, rows[n_first:]])
                n_first += d_index.size
        index.flags.writeable = rows.flags.writeable = False  # shared until the next sweep
        answer = (index, rows, n_first)
        self._cached = (key, answer)
        return answer

    def _query_direct(
        self, q: np.ndarray, kinematics: bool = True, idx: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The per-pair path: ``mj_geomDistance`` per candidate (``idx``, ascending; default
        the broad phase's); ``(index, rows)`` of the pairs within ``distmax``, packed rows."""
        m, d = self.model, self.data
        if kinematics:
            d.qpos[: self.hand_nq] = q
            mujoco.mj_kinematics(m, d)
        if idx is None:
            idx = self.candidates()
        if not idx.size:
            return self._no_rows
        rows = np.empty((idx.size, _kernels.WIDTH))
        fromto, distmax = self._fromto, self.distmax
        ga, gb = self._ga_list, self._gb_list
        keep = []
        for i in idx.tolist():
            r = mujoco.mj_geomDistance(m, d, ga[i], gb[i], distmax, fromto)
            if r < distmax:
                row = rows[len(keep)]
                row[_kernels.D] = r
                row[_kernels.PA : _kernels.PB + 3] = fromto
                keep.append(i)
        if not keep:
            return self._no_rows
        rows = rows[: len(keep)]
        _kernels.set_normals(rows)
        return np.array(keep), rows

    def _sweep_maps(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per pair registered on the sweep, this limit's pair index (-1: another limit's or
        not this one's): for the swept pairs only, for the swept and per-pair pairs, and for
        the per-pair mesh pairs (the sweep's registrations can grow after this limit's, so
        rebuilt when they do)."""
        n = self.sweep._ga.size
        if self._maps is None or self._maps[0].size != n:
            swept = np.full(n, -1)
            swept[self._offset : self._offset + self._swept.size] = self._swept
            every = swept.copy()
            at = slice(self._direct_offset, self._direct_offset + self._direct_seen.size)
            every[at] = self._direct_seen
            mesh = np.full(n, -1)
            mesh[at] = np.where(np.isin(self._direct_seen, self._mesh_seen), self._direct_seen, -1)
            self._maps = (swept, every, mesh)
        return self._maps

    def distances(self, q: np.ndarray) -> list[tuple[int, int, float, np.ndarray, np.ndarray]]:
        """``(geom_a, geom_b, d, p_a, p_b)`` for every pair within ``distmax`` at ``q``."""
        r = self.query(q)
        return [
            (self.pairs[i][0], self.pairs[i][1], float(dd), pa, pb)
            for i, dd, pa, pb in zip(r.index.tolist(), r.distance, r.p_a, r.p_b, strict=True)
        ]

    def min_distance(self, q: np.ndarray) -> float:
        """Smallest signed distance [m] over the pairs within ``distmax`` at ``q`` (else inf)."""
        _, rows, n_first = self._answer(q)
        return float(rows[:n_first, _kernels.D].min()) if n_first else np.inf

    def row_points(self, q: np.ndarray) -> PairDistances:
        """The witness points of :meth:`inequalities`' rows at ``q``, in row order: each pair
        within ``distmax`` at its closest points (:meth:`query`), then the further contacts
        ``mj_collision`` reports for the same pairs (the per-pair pairs: all of theirs).

        A row at the closest points alone lets a step turn another part of the geom into the
        surface: a capsule or box lying along a cylinder pivots about the constrained end and
        the other end goes in (built-in demonstrations, Allegro and LEAP: up to 7.0 mm deep
        with closest-point rows).
        """
        index, rows, _ = self._answer(q)
        return _pair_distances(index, rows)

    NEAR = 0.005
    """Pairs within this [m] of their allowed distance (``−pair_margin`` where that is a
    clearance, else 0) at a linearisation are the near ones :meth:`near_violation` considers
    after the step."""

    NEAR_AFTER = 0.003
    """Of the near pairs, :meth:`near_violation` measures those the linear rows predict within
    this [m] of their allowed distance after the step (and those without a row). Measured on
    the speed benchmark's 20 pairs on all seven hands (740,793 near pairs at the end of a
    step): the true distance was within 2.51 mm of the prediction everywhere and
    within 0.07 mm where the prediction was beyond 2 mm, so a pair predicted 3 mm out would
    need an error of 3.5 mm to end 0.5 mm inside its margin (the check's tolerance); 58 % of
    the near pairs are predicted beyond 3 mm (Inspire 78 %, Ability 69 %, Shadow 59 %, Allegro
    41 %, SVH 40 %, LEAP 28 %, Panda 25 %)."""

    MESH_FAR = 0.006
    """A mesh pair whose closest contact in the sweep is at least this far [m] beyond its
    allowed distance takes that contact as its distance and nearest points instead of an
    ``mj_geomDistance`` call: ``mj_collision``'s mesh distances are within 0.32 mm of
    ``mj_geomDistance``'s (module docstring), so such a pair is not near (:attr:`NEAR`), and
    its row only binds after a step of several millimetres towards it. Measured against
    ``mj_geomDistance`` on the mesh pairs beyond it (SVH, Ability and Panda, 10 of the speed
    benchmark's pairs, 8 random finger poses each at the human wrist; 1,242 pairs): distance
    within 0.13 mm, direction within 9.9° (median 0°). The speed benchmark's 20 pairs on SVH,
    Ability, Panda and Shadow: joint trajectories within 1.4e-3 rad of measuring every mesh
    pair, bit-identical on 70 of 80 runs; SVH 0.90× and Ability 0.94× the time per frame
    (same process, alternating runs)."""

    def near_violation(self, q: np.ndarray) -> float:
        """Smallest ``d + pair_margin`` [m] at ``q`` (negative: the pair is closer than its
        margin allows) over the pairs that were near at the last :meth:`inequalities` (within
        :attr:`NEAR` of contact, or of their clearance where the margin is negative: a link the
        human keeps clear of the object, the table) and that its rows predict within
        :attr:`NEAR_AFTER` of it at ``q``. ``inf`` if none.

        The end-of-step check: the rows are linear, so a pair near contact can end the step
        closer than its margin (a finger turning on a curved surface, a link swinging round
        the cube's edge). Pairs farther than that would need a longer step than the velocity
        rows allow to get there. One ``mj_kinematics`` and one ``mj_geomDistance`` per pair
        checked (the same distance as the sweep's, see the module docstring) instead of a
        sweep of the whole scene: on Shadow, built-in cube2/tripod, ~20 µs instead of ~180 µs
        per frame; none when no pair is predicted that close.
        """
        if not self._near.size:  # (also before the first inequalities())
            return np.inf
        q_lin, G, rows, slack = self._near_pred
        q = np.asarray(q, dtype=np.float64)
        near = _kernels.check_after_step(G, rows, slack, self._near, q, q_lin, self.NEAR_AFTER)
        if not near.size:
            return np.inf
        m = self.model
        if self.sweep is not None:
            d = self.sweep.posed(q)  # (shared by the limits on the sweep)
        else:
            if self._check_data is None:
                self._check_data = mujoco.MjData(m)
            d = pose_scene(m, self._check_data, self.data, q, self.hand_nq)
        ga, gb, pm = self._ga_list, self._gb_list, self.pair_margins
        reach = self.NEAR + max(0.0, -float(pm[near].min()))
        return min(
            mujoco.mj_geomDistance(m, d, ga[i], gb[i], reach, None) + pm[i] for i in near.tolist()
        )

    def inequalities(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        index, rows, n_first = self._answer(state.q)
        setup = (
            index, rows, n_first, self.data.geom_xpos, self._ga, self.pair_margins,
            np.nan if self.max_recovery is None else self.max_recovery, self.hold_only,
            self.NEAR,
        )  # fmt: skip
        kin = state.kin
        if isinstance(kin, PinocchioKinematics):
            # The rows straight from the world-frame joint Jacobian, in the same pass.
            if self._masks is None or self._masks[0] is not kin:
                a = kin.body_dof_masks(self._bodies_a)
                b = kin.body_dof_masks(self._bodies_b) if self.self_collision else a
                self._masks = (kin, a, b)
            _, masks_a, masks_b = self._masks
            G, h, self._near, rows_near, slack = _kernels.rows_and_jacobians(
                *setup, kin.world_jacobian(), masks_a, masks_b, self.self_collision
            )
            self._near_pred = (state.q.copy(), G, rows_near, slack)
            return G, h
        index, out, self._near, rows_near, slack = _kernels.row_setup(*setup)
        K = _kernels
        if not index.size:
            G = np.zeros((0, state.nv))
        else:
            n = out[:, K.N :]
            J = kin.point_jacobians(tuple(self._bodies_a[index]), out[:, K.PA : K.PA + 3])
            if self.self_collision:  # J = J_a − J_b
                J = J - kin.point_jacobians(tuple(self._bodies_b[index]), out[:, K.PB : K.PB + 3])
            G = np.einsum("ki,kij->kj", n, J)
        self._near_pred = (state.q.copy(), G, rows_near, slack)
        return G, out[:, K.D].copy()


def _pair_distances(index: np.ndarray, rows: np.ndarray) -> PairDistances:
    """Packed rows (:mod:`retarget.limits._kernels`) as :class:`PairDistances` (views)."""
    K = _kernels
    return PairDistances(
        index, rows[:, K.D], rows[:, K.PA : K.PA + 3], rows[:, K.PB : K.PB + 3], rows[:, K.N :]
    )
