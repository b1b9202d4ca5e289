"""The description of one robot hand: :class:`HandModel`.

A :class:`HandModel` says where a hand's model comes from (a PyPI package or ``robots/<hand>/``),
how its base frame sits relative to MANO's wrist frame (the common layout of
:mod:`retarget.hands.base`), which robot finger each human finger drives, where its keypoint sites
are, which joints are coupled, and how its joints are actuated. From that,
:meth:`HandModel.build_spec` builds one MuJoCo model (:mod:`retarget.hands.build`) with the same
layout for every hand.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import mujoco
import numpy as np

from dexcanvas_core.keypoints import FINGERS, MANO21
from dexcanvas_core.sim import mujoco_log  # noqa: F401 (MuJoCo's warnings to logging, not a file)
from retarget.errors import HandModelError
from retarget.hands.base import (
    HUMAN_FINGERS,
    WRIST_BODY,
    WRIST_JOINTS,
    WRIST_SITE,
    ActuatorSpec,
    ContactParams,
    JointCoupling,
    ModelSource,
    SitePlacement,
    WristAlignment,
    WristGains,
    WristOffset,
)
from retarget.hands.build import build_spec, coupling_tendons

_HUMAN_JOINT_LABELS = {
    # MANO21 joint keypoints per finger: (MANO name suffix, anatomical label of the robot site)
    "thumb": (("1", "cmc"), ("2", "mcp"), ("3", "ip")),
    "index": (("1", "mcp"), ("2", "pip"), ("3", "dip")),
    "middle": (("1", "mcp"), ("2", "pip"), ("3", "dip")),
    "ring": (("1", "mcp"), ("2", "pip"), ("3", "dip")),
    "pinky": (("1", "mcp"), ("2", "pip"), ("3", "dip")),
}


@dataclass(frozen=True, eq=False)
class HandModel:
    """One robot hand: model source, frames, human↔robot correspondence, couplings, gains.

    Instances are immutable descriptions; :meth:`build_spec` returns a fresh ``mujoco.MjSpec``
    each call and :meth:`compile` a cached ``mujoco.MjModel`` (treat it as read-only; build your
    own from :meth:`build_spec` to change it). Hand modules create one instance named ``HAND``.

    >>> from retarget import get_hand
    >>> hand = get_hand("allegro")
    >>> hand.mapped_human_fingers              # the pinky is dropped
    ('thumb', 'index', 'middle', 'ring')
    >>> model = hand.compile()                 # mujoco.MjModel: floating wrist + hand
    >>> model.nq, model.nu
    (22, 22)
    """

    name: str
    description: str
    source: ModelSource
    loader: Callable[[], object] = field(repr=False)
    """Returns a fresh ``mujoco.MjSpec`` that contains ``root_body`` (the source model)."""
    root_body: str
    fingers: Mapping[str, str | None]
    """Human finger (thumb…pinky) → robot finger name, or None when the robot has no such finger."""
    tip_sites: Mapping[str, SitePlacement | None]
    """Robot finger → where its ``<finger>_tip_site`` goes (None: the source model has it)."""
    joint_sites: Mapping[str, SitePlacement]
    """MANO21 joint keypoint (e.g. ``index1``) → placement of the robot's matching site."""
    wrist: WristAlignment
    actuators: tuple[ActuatorSpec, ...]
    couplings: tuple[JointCoupling, ...] = ()
    """Couplings added here (those already in the source model are kept as they are)."""
    coupling_notes: str = ""
    default_posture: Mapping[str, float] = field(default_factory=dict)
    """Open-hand posture [rad or m] of the finger joints (joints not listed: 0 or their range)."""
    joint_armature: float | None = None
    """If set, the armature [kg·m^2] of every finger joint (overrides the source)."""
    joint_damping: float | None = None
    """If set, the passive damping [N·m·s/rad] of every finger joint (overrides the source)."""
    joint_frictionloss: float | None = None
    """If set, the dry friction [N·m] of every finger joint (overrides the source)."""
    joint_ranges: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    """Joint range overrides [rad] (e.g. where a published range is narrower than the source)."""
    # Frozen dataclasses: one shared default instance is safe.
    contact: ContactParams = ContactParams()  # noqa: RUF009
    wrist_gains: WristGains = WristGains()  # noqa: RUF009
    wrist_offset: WristOffset | None = None
    """The wrist target's offset from the human wrist (:class:`WristOffset`); None: none."""
    joint_limit_margin: float = 0.0
    """How far [rad or m] the retargeting's kinematic solution keeps this hand's finger joints
    inside their ranges unless ``RetargetConfig.joint_limits.margin`` says otherwise (for a hand
    whose fingers press badly from a limit; see there)."""
    wrist_weight: float = 1.0
    """Factor on the retargeting's wrist-pose weights (``RetargetConfig.wrist``'s
    ``position_weight`` and ``rotation_weight``) for this hand; 0: the wrist is placed by the
    fingertips, the contacts and the smoothness term alone. For a hand whose wrist the human
    wrist pose places badly even with its calibrated offset (the Panda gripper has none: no one
    offset describes it; ``retarget calibrate-wrist``)."""
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        def bad(msg: str):
            raise HandModelError(f"hand {self.name!r}: {msg}")

        if set(self.fingers) != set(HUMAN_FINGERS):
            bad(f"fingers must map exactly {', '.join(HUMAN_FINGERS)}, got {sorted(self.fingers)}")
        for human, robot in self.fingers.items():
            if robot is not None and robot not in self.tip_sites:
                bad(f"finger {human!r} maps to {robot!r}, which has no entry in tip_sites")
        if self.fingers["thumb"] is None:
            bad("the thumb must drive a robot finger")
        joints = {f"{f}{i}" for f in HUMAN_FINGERS for i in "123"}
        for kp in self.joint_sites:
            if kp not in joints:
                bad(f"joint_sites key {kp!r} is not a MANO21 joint keypoint ({sorted(joints)})")
            self.joint_site_name(kp)  # raises for an unmapped finger
        if not (np.isfinite(self.joint_limit_margin) and self.joint_limit_margin >= 0):
            bad(f"joint_limit_margin must be finite and >= 0, got {self.joint_limit_margin}")
        if not (np.isfinite(self.wrist_weight) and self.wrist_weight >= 0):
            bad(f"wrist_weight must be finite and >= 0, got {self.wrist_weight}")
        names = [a.joint for a in self.actuators]
        if len(set(names)) != len(names):
            bad("two actuators on the same joint")

    # ------------------------------------------------------------------ correspondence
    @property
    def robot_fingers(self) -> tuple[str, ...]:
        """Robot finger names, in the order of ``tip_sites``."""
        return tuple(self.tip_sites)

    @property
    def mapped_human_fingers(self) -> tuple[str, ...]:
        """The human fingers this hand maps, thumb…pinky order: the retargeter's fingertip
        targets, and the columns of a force-matched run's ``human_force`` / ``robot_force``."""
        return tuple(f for f in FINGERS if self.fingers.get(f) is not None)

    @property
    def robot_to_human(self) -> dict[str, str]:
        """Robot finger → the first human finger (thumb…pinky order) mapped to it (a gripper's
        finger driven by index and middle: index)."""
        out: dict[str, str] = {}
        for human in FINGERS:
            robot = self.fingers.get(human)
            if robot is not None and robot not in out:
                out[robot] = human
        return out

    @property
    def tip_site_names(self) -> dict[str, str]:
        """Robot finger → its fingertip site name."""
        return {f: f"{f}_tip_site" for f in self.tip_sites}

    @property
    def keypoint_map(self) -> dict[str, str]:
        """MANO21 keypoint name → robot site name, for every keypoint the robot can match.

        Always the wrist and the tip of every mapped human finger; MCP/PIP/DIP (thumb CMC/MCP/IP)
        where the robot has a matching joint.
        """
        out = {"wrist": WRIST_SITE}
        for human in HUMAN_FINGERS:
            robot = self.fingers.get(human)
            if robot is not None:
                out[f"{human}_tip"] = f"{robot}_tip_site"
        for kp in self.joint_sites:
            out[kp] = self.joint_site_name(kp)
        return {k: out[k] for k in MANO21 if k in out}

    def joint_site_name(self, keypoint: str) -> str:
        """The robot site matching a MANO21 joint keypoint (e.g. ``index1`` → ``ff_mcp_site``)."""
        human = keypoint.rstrip("123")
        robot = self.fingers.get(human)
        if robot is None:
            raise HandModelError(f"hand {self.name!r}: keypoint {keypoint!r} on an unmapped finger")
        label = dict(_HUMAN_JOINT_LABELS[human])[keypoint[len(human) :]]
        return f"{robot}_{label}_site"

    @property
    def T_mano_robot_wrist(self) -> np.ndarray:
        """(4, 4) pose of the robot's root frame in MANO's wrist frame (see
        :mod:`retarget.hands.base`)."""
        return self.wrist.T_mano_robot

    # ------------------------------------------------------------------ model building
    def build_spec(self, *, self_collision: bool = False):
        """A new ``mujoco.MjSpec``: floating wrist + the hand, sites, couplings, actuators
        (:func:`retarget.hands.build.build_spec`, which says what ``self_collision`` does)."""
        return build_spec(self, self_collision=self_collision)

    def compile(self):
        """The compiled ``mujoco.MjModel`` (cached; do not modify it in place)."""
        model = self._cache.get("model")
        if model is None:
            spec = self.build_spec()
            try:
                model = spec.compile()
            except Exception as e:
                raise HandModelError(f"hand {self.name!r}: MuJoCo cannot compile it: {e}") from e
            self._cache["model"] = model
        return model

    # ------------------------------------------------------------------ postures and queries
    def default_qpos(self, model=None) -> np.ndarray:
        """``qpos`` (nq,) with the wrist at the origin and the fingers at ``default_posture``.

        Joints not listed in ``default_posture`` sit at 0 clipped into their range; followers of a
        joint coupling are set from their leader.
        """
        m = self.compile() if model is None else model
        q = m.qpos0.copy()
        for j in range(m.njnt):
            name = m.joint(j).name
            adr = m.jnt_qposadr[j]
            val = self.default_posture.get(name, q[adr])
            if m.jnt_limited[j]:
                lo, hi = m.jnt_range[j]
                val = float(np.clip(val, lo, hi))
            q[adr] = val
        for e in range(m.neq):
            if m.eq_type[e] != mujoco.mjtEq.mjEQ_JOINT or m.eq_obj2id[e] < 0:
                continue
            c = m.eq_data[e]
            x = q[m.jnt_qposadr[m.eq_obj2id[e]]]
            q[m.jnt_qposadr[m.eq_obj1id[e]]] = c[0] + c[1] * x + c[2] * x**2 + c[3] * x**3
        return q

    def default_ctrl(self, model=None) -> np.ndarray:
        """``ctrl`` (nu,) holding :meth:`default_qpos` (every actuator here is a joint servo)."""
        m = self.compile() if model is None else model
        q = self.default_qpos(m)
        ctrl = np.zeros(m.nu)
        for a in range(m.nu):
            ctrl[a] = q[m.jnt_qposadr[m.actuator_trnid[a, 0]]]
        return np.clip(ctrl, m.actuator_ctrlrange[:, 0], m.actuator_ctrlrange[:, 1])

    def hand_parts(self, model=None) -> dict[str, list[str]]:
        """Robot finger (and ``palm``) → names of its bodies, for contact reports.

        A finger owns the bodies on the chain from its tip site up to where it branches off the
        palm; every other hand body is the palm.
        """
        m = self.compile() if model is None else model
        wrist_id = m.body(WRIST_BODY).id
        chains = {}
        for f, site in self.tip_site_names.items():
            b = int(m.site_bodyid[m.site(site).id])
            chain = []
            while b != wrist_id and b > 0:
                chain.append(int(b))
                b = m.body_parentid[b]
            chains[f] = chain
        counts: dict[int, int] = {}
        for chain in chains.values():
            for b in chain:
                counts[b] = counts.get(b, 0) + 1
        parts = {f: [m.body(b).name for b in chain if counts[b] == 1][::-1]
                 for f, chain in chains.items()}  # fmt: skip
        owned = {n for names in parts.values() for n in names}
        parts["palm"] = [m.body(b).name for b in range(1, m.nbody) if m.body(b).name not in owned]
        return parts

    def self_collision_pairs(self) -> list[tuple[str, str]]:
        """Collision geom pairs (names) of different hand parts that must not interpenetrate.

        A pair's geoms belong to different parts of :meth:`hand_parts` (finger vs finger, or
        finger vs palm), and MuJoCo's own filters of the self-collision variant
        (``build_spec(self_collision=True)``) would let them touch: not on one weld body or on a
        weld parent and child, and not in an excluded body pair (the variant excludes the body
        pairs touching at the open posture, e.g. palm vs finger bases). Pairs that still touch
        at the open posture (signed distance ≤ 0, "by construction") are left out too. Geom
        names are those of :meth:`build_spec`, which the retargeting scene shares. Cached.
        """
        pairs = self._cache.get("self_collision_pairs")
        if pairs is not None:
            return list(pairs)
        m = self.build_spec(self_collision=True).compile()
        d = mujoco.MjData(m)
        d.qpos[:] = self.default_qpos(m)
        mujoco.mj_kinematics(m, d)
        part_of = {m.body(b).id: p for p, bodies in self.hand_parts(m).items() for b in bodies}
        geoms = [
            g
            for g in range(m.ngeom)
            if (m.geom_contype[g] or m.geom_conaffinity[g]) and m.geom_bodyid[g] in part_of
        ]
        excluded = {(int(s) >> 16, int(s) & 0xFFFF) for s in m.exclude_signature}
        weld = m.body_weldid
        fromto = np.zeros(6)
        pairs = []
        for i, a in enumerate(geoms):
            for b in geoms[i + 1 :]:
                ba, bb = int(m.geom_bodyid[a]), int(m.geom_bodyid[b])
                if part_of[ba] == part_of[bb]:
                    continue
                wa, wb = int(weld[ba]), int(weld[bb])
                if wa == wb or weld[m.body_parentid[wa]] == wb or weld[m.body_parentid[wb]] == wa:
                    continue  # MuJoCo's parent-child filter (on weld bodies)
                if any((min(x, y), max(x, y)) in excluded for x, y in ((ba, bb), (wa, wb))):
                    continue
                if mujoco.mj_geomDistance(m, d, a, b, 0.01, fromto) <= 0.0:
                    continue  # touching at the open posture
                pairs.append((m.geom(a).name, m.geom(b).name))
        self._cache["self_collision_pairs"] = pairs
        return list(pairs)

    @property
    def scale(self) -> float:
        """Robot/human hand size ratio (dimensionless).

        Mean wrist→fingertip distance of the robot fingers (open posture) over that of the
        human fingers they are mapped to, on MANO's default (mean) right hand.
        """
        val = self._cache.get("scale")
        if val is None:
            val = self._compute_scale()
            self._cache["scale"] = val
        return val

    def _compute_scale(self) -> float:
        # Here, not at the top: the MANO skeleton costs 0.9 s to import, only the scale needs it.
        from dexcanvas_core.mano.skeleton import HandSkeleton

        m = self.compile()
        d = mujoco.MjData(m)
        d.qpos[:] = self.default_qpos(m)
        mujoco.mj_kinematics(m, d)
        wrist = d.site(WRIST_SITE).xpos
        human = HandSkeleton.default("right").rest_keypoints
        h_wrist = human[MANO21.index("wrist")]
        r, h = [], []
        for f in HUMAN_FINGERS:
            rf = self.fingers.get(f)
            if rf is None:
                continue
            r.append(np.linalg.norm(d.site(f"{rf}_tip_site").xpos - wrist))
            h.append(np.linalg.norm(human[MANO21.index(f"{f}_tip")] - h_wrist))
        return float(np.mean(r) / np.mean(h))

    def summary(self) -> dict:
        """One row of ``retarget hands``: name, DoF, actuators, fingers, source, licence."""
        m = self.compile()
        n_finger_dof = m.nv - len(WRIST_JOINTS)
        n_finger_act = m.nu - len(WRIST_JOINTS)
        return {
            "name": self.name,
            "description": self.description,
            "dof": m.nv,
            "dof_wrist": len(WRIST_JOINTS),
            "dof_fingers": n_finger_dof,
            "actuators": m.nu,
            "actuators_fingers": n_finger_act,
            "couplings": int(m.neq + len(coupling_tendons(m))),
            "fingers": {f: self.fingers.get(f) for f in HUMAN_FINGERS},
            "tip_sites": self.tip_site_names,
            "scale": round(self.scale, 3),
            # The retargeting's per-hand settings (see their fields).
            "wrist_offset": self.wrist_offset is not None,
            "wrist_weight": round(self.wrist_weight, 4),
            "joint_limit_margin": self.joint_limit_margin,
            "source": self.source.short,
            "source_kind": self.source.kind,
            "location": self.source.location,
            "licence": self.source.licence_short,
            "licence_full": self.source.licence,
            "upstream": self.source.upstream,
        }
