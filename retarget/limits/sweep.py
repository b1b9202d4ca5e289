"""One ``mj_collision`` sweep per configuration, shared by the collision limits and the
metrics (:class:`ContactSweep`; see ``retarget.limits.collision`` for when a pair takes it),
and the pairs' distances it reports (:class:`PairDistances`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from retarget.errors import RetargetError
from retarget.limits import _kernels


@dataclass
class PairDistances:
    """The pairs within ``distmax`` at one configuration (arrays over those pairs)."""

    index: np.ndarray
    """(k,) indices into the limit's ``pairs``."""
    distance: np.ndarray
    """(k,) signed distances [m] (negative: penetration)."""
    p_a: np.ndarray
    """(k, 3) nearest point on ``geom_a`` [m, world]."""
    p_b: np.ndarray
    """(k, 3) nearest point on ``geom_b`` [m, world]."""
    normal: np.ndarray
    """(k, 3) unit normal from ``geom_a`` to ``geom_b`` (the distance grows along it); NaN where
    the nearest points coincide (touching exactly) and the query has no other direction."""


def pose_scene(
    m: mujoco.MjModel, d: mujoco.MjData, scene: mujoco.MjData, q: np.ndarray, hand_nq: int
) -> mujoco.MjData:
    """``d`` at the scene's configuration with the hand at ``q`` (kinematics only)."""
    d.qpos[:] = scene.qpos
    d.qpos[:hand_nq] = q
    d.mocap_pos[:], d.mocap_quat[:] = scene.mocap_pos, scene.mocap_quat
    mujoco.mj_kinematics(m, d)
    return d


# Pairs with one of these geoms get identical answers from mj_collision and mj_geomDistance,
# except capsule–cylinder (swept_pair).
_SWEEP_TYPES = {
    int(mujoco.mjtGeom.mjGEOM_PLANE),
    int(mujoco.mjtGeom.mjGEOM_SPHERE),
    int(mujoco.mjtGeom.mjGEOM_CAPSULE),
}
_CAPSULE_CYLINDER = {int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_CYLINDER)}


def _margins_add() -> bool:
    """Whether ``mj_collision`` reports a geom pair up to the sum of the two geoms' margins
    (MuJoCo 4.0.1) rather than the larger one: two spheres with margins of 10 mm, 15 mm apart,
    make a contact only with the sum."""
    m = mujoco.MjModel.from_xml_string(
        """<mujoco><worldbody>
        <body><freejoint/><geom type="sphere" size="0.1" margin="0.01"/></body>
        <body pos="0 0 0.215"><freejoint/><geom type="sphere" size="0.1" margin="0.01"/></body>
        </worldbody></mujoco>"""
    )
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    mujoco.mj_collision(m, d)
    return d.ncon == 1


_MARGINS_ADD = _margins_add()


def _pair_margin(a, b):
    """A geom pair's margin (or gap) from the two geoms': their sum or the larger one
    (:func:`_margins_add`)."""
    return a + b if _MARGINS_ADD else np.maximum(a, b)


def swept_pair(type_a: int, type_b: int) -> bool:
    """Whether a pair of these geom types can take its distance from the sweep.

    Not capsule–cylinder: ``mj_collision`` (MuJoCo 4.0.1) reports some capsules near a
    cylinder's cap up to 19 mm farther than they are (Shadow's middle distal over the built-in
    cylinder1's top: 18.0 mm against ``mj_geomDistance``'s 1.6 mm, whose witness points lie
    1.6 mm apart). Retargeted and random poses, all hands, twelve objects: 30 of 3,862 such
    pairs off by more than 0.1 mm, every other type pair within 1.1 mm (sphere–mesh) and most
    exact. A capsule against a cylinder with a margin is a reported MuJoCo issue
    (google-deepmind/mujoco#1857, open: negative distances for separated geoms)."""
    if {type_a, type_b} == _CAPSULE_CYLINDER:
        return False
    return type_a in _SWEEP_TYPES or type_b in _SWEEP_TYPES


class ContactSweep:
    """``mj_collision`` on the scene, once per configuration (hand ``q`` and mocap poses).

    Args:
        model, data: the scene; the geom (and explicit pair) margins set the query distance, so
            give the scene margins of at least the largest ``distmax`` of the limits using it
            (:meth:`set_margins`). The scene must be kinematic only: margins change contacts.
        hand_nq: number of hand joints (the first ``hand_nq`` entries of ``qpos``).
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, hand_nq: int):
        if model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT:
            raise RetargetError("ContactSweep needs contacts enabled (mjDSBL_CONTACT is set)")
        self.model, self.data, self.hand_nq = model, data, hand_nq
        self._key = b""  # q and the mocap poses of the cached sweep, as bytes (b"": none)
        self.version = 0
        """Counts the sweeps run: the limits' per-configuration results are valid while it
        stays the same."""
        self._warn = data.warning[mujoco.mjtWarning.mjWARN_CONTACTFULL]  # a live view
        self._posed: mujoco.MjData | None = None  # see posed()
        self._posed_key = b""
        # Registered pairs (all limits on this sweep): (geom, geom) → registered pair index.
        self._lut = np.full(model.ngeom * model.ngeom, -1, dtype=int)
        self._ga = np.zeros(0, int)
        # Every contact of a registered pair this configuration, sorted by pair then distance:
        self.pair = np.zeros(0, int)
        """(k,) registered pair indices."""
        self.closest = np.zeros(0, bool)
        """(k,) the pair's closest contact (mj_geomDistance's answer for the sweep types); the
        others are further contacts of the same pair (e.g. both ends of a capsule lying on a
        surface)."""
        self.rows = np.zeros((0, _kernels.WIDTH))
        """(k, 10) packed: signed distance [m], the nearest points on the pair's first and
        second geom [m], the unit normal first → second (:mod:`retarget.limits._kernels`)."""

    @property
    def dist(self) -> np.ndarray:
        """(k,) signed distances [m] (a view of :attr:`rows`)."""
        return self.rows[:, _kernels.D]

    @property
    def p_a(self) -> np.ndarray:
        """(k, 3) nearest points on the pair's first geom [m, world]."""
        return self.rows[:, _kernels.PA : _kernels.PA + 3]

    @property
    def p_b(self) -> np.ndarray:
        """(k, 3) nearest points on the pair's second geom [m, world]."""
        return self.rows[:, _kernels.PB : _kernels.PB + 3]

    @property
    def normal(self) -> np.ndarray:
        """(k, 3) unit normals first → second geom."""
        return self.rows[:, _kernels.N : _kernels.N + 3]

    def register(self, pairs: Sequence[tuple[int, int]]) -> int:
        """Add pairs (hand geom first); returns the index of the first in the sweep's output."""
        ng = self.model.ngeom
        ga = np.array([a for a, _ in pairs], dtype=int)
        gb = np.array([b for _, b in pairs], dtype=int)
        if (self._lut[ga * ng + gb] >= 0).any():
            raise RetargetError("a collision pair is registered twice on one contact sweep")
        offset = self._ga.size
        self._lut[ga * ng + gb] = offset + np.arange(ga.size)
        self._lut[gb * ng + ga] = offset + np.arange(ga.size)
        self._ga = np.concatenate([self._ga, ga])
        self.invalidate()
        return offset

    def set_margins(
        self,
        hand_geoms: Sequence[int],
        hand_reach: float,
        other_geoms: Sequence[int] = (),
        other_reach: float = 0.0,
    ) -> None:
        """Query distances [m]: ``mj_collision`` reports two hand geoms up to ``hand_reach``
        apart, a hand geom and one of ``other_geoms`` (object, table) up to ``other_reach``
        (at least). Sets the geom margins for the installed MuJoCo's rule (:func:`_pair_margin`:
        4.0.1 adds the two geoms' margins), explicit ``<pair>``s to the same, gaps to 0, and
        turns the midphase off.
        """
        m = self.model
        # The BVH midphase prunes body pairs without the margins (pairs within them go missing).
        m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_MIDPHASE
        if _MARGINS_ADD:
            hand = 0.5 * hand_reach
            other = max(other_reach - hand, 0.0)
        else:
            hand, other = hand_reach, max(other_reach, hand_reach)
        m.geom_margin[list(hand_geoms)] = hand
        m.geom_margin[list(other_geoms)] = other
        m.geom_gap[list(hand_geoms) + list(other_geoms)] = 0.0
        if m.npair:
            g1, g2 = m.pair_geom1, m.pair_geom2
            m.pair_margin[:] = _pair_margin(m.geom_margin[g1], m.geom_margin[g2])
            m.pair_gap[:] = 0.0
        self.invalidate()

    def update(self, q: np.ndarray) -> None:
        """Contacts at hand configuration ``q`` (and the current mocap poses); cached."""
        d = self.data
        q = np.asarray(q, dtype=np.float64)
        key = self._config_key(q)
        if key == self._key:
            return
        d.qpos[: self.hand_nq] = q
        mujoco.mj_kinematics(self.model, d)
        warn = self._warn
        full = warn.number
        mujoco.mj_collision(self.model, d)
        if warn.number != full:
            # Dropped contacts would be pairs silently missing from the limits.
            raise RetargetError(
                f"mj_collision ran out of contact memory ({d.ncon} contacts within the margins); "
                "give the scene a larger memory size or smaller collision distmax values"
            )
        self._key = key
        self.version += 1
        c = d.contact
        self.pair, self.closest, self.rows = _kernels.sweep_select(
            c.geom, c.dist, c.pos, c.frame, self._lut, self.model.ngeom, self._ga
        )

    def posed(self, q: np.ndarray) -> mujoco.MjData:
        """A second ``MjData`` at hand configuration ``q`` and the scene's mocap poses
        (kinematics only; cached), for the limits' end-of-step checks: the sweep's own data
        stays at its cached configuration, which the next iterate reuses while the object
        rests."""
        q = np.asarray(q, dtype=np.float64)
        d = self.data
        key = self._config_key(q)
        if self._posed is None:
            self._posed = mujoco.MjData(self.model)
        elif key == self._posed_key:
            return self._posed
        self._posed_key = key
        return pose_scene(self.model, self._posed, d, q, self.hand_nq)

    def kinematics(self, q: np.ndarray) -> mujoco.MjData:
        """An ``MjData`` with the scene's kinematics at hand configuration ``q`` (and the
        current mocap poses), for reading geom poses: the sweep's own data when its last sweep
        is at ``q`` and nothing moved it since (no ``mj_kinematics`` then: the iterate's
        contact objective reads the sweep's configuration), else :meth:`posed`'s."""
        q = np.asarray(q, dtype=np.float64)
        d = self.data
        if self._config_key(q) == self._key and d.qpos[: self.hand_nq].tobytes() == q.tobytes():
            return d
        return self.posed(q)

    def _config_key(self, q: np.ndarray) -> bytes:
        """``q`` (float64) and the scene's mocap poses as bytes: what the cached sweep and
        posed data are valid for (a bytes compare: ~0.3 µs against ~8 µs for three array
        comparisons, and the check runs several times per iterate)."""
        d = self.data
        return q.tobytes() + d.mocap_pos.tobytes() + d.mocap_quat.tobytes()

    def invalidate(self) -> None:
        """Forget the cached contacts and pose (after changing the scene other than
        ``q``/mocap)."""
        self._key = self._posed_key = b""
        self.version += 1

    def query_distance(self, ga: int, gb: int) -> float:
        """The distance [m] up to which ``mj_collision`` reports the pair (its margin), or
        ``-inf`` when its filters skip the pair: contype/conaffinity, one weld body or weld
        parent and child, an excluded body pair (explicit ``<pair>``s are always seen)."""
        m = self.model
        for p in range(m.npair):
            if {int(m.pair_geom1[p]), int(m.pair_geom2[p])} == {ga, gb}:
                return float(m.pair_margin[p] - m.pair_gap[p])
        margin = float(
            _pair_margin(m.geom_margin[ga], m.geom_margin[gb])
            - _pair_margin(m.geom_gap[ga], m.geom_gap[gb])
        )
        if not (
            m.geom_contype[ga] & m.geom_conaffinity[gb]
            or m.geom_contype[gb] & m.geom_conaffinity[ga]
        ):
            return -np.inf
        ba, bb = int(m.geom_bodyid[ga]), int(m.geom_bodyid[gb])
        w = m.body_weldid
        wa, wb = int(w[ba]), int(w[bb])
        if wa == wb:
            return -np.inf
        filter_parent = not (m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_FILTERPARENT)
        if (
            filter_parent
            and wa
            and wb
            and (w[m.body_parentid[wa]] == wb or w[m.body_parentid[wb]] == wa)
        ):
            return -np.inf
        excluded = {int(x) for x in m.exclude_signature}
        return -np.inf if ((min(ba, bb) << 16) + max(ba, bb)) in excluded else margin
