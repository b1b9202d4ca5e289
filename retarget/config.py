"""The retargeter's configuration: one small config per objective, limit and stage, composed.

``RetargetConfig(contacts=ContactsConfig(weight=100.0))`` changes one setting; the defaults are
the default-constructed term configs. Settings are also named by dotted paths
(``contacts.weight``; ``retarget run --set contacts.weight=100``) or by the flat names of the
one-level config they replace (``w_contacts``; :data:`FLAT_NAMES`), which
:meth:`RetargetConfig.from_overrides` and :meth:`RetargetConfig.flat` translate.
"""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Mapping
from dataclasses import dataclass, field

from retarget.errors import RetargetError
from retarget.force_matching import ForceMatchingConfig
from retarget.grip import GripConfig
from retarget.limits.collision import CollisionConfig, SelfCollisionConfig
from retarget.limits.joints import JointLimitsConfig, VelocityConfig
from retarget.objectives.contacts import ClosingConfig, ContactsConfig
from retarget.objectives.keypoints import KeypointsConfig, VectorsConfig
from retarget.objectives.regularization import PostureConfig, SmoothnessConfig
from retarget.objectives.wrist import WristConfig
from retarget.solve import SolverConfig

__all__ = [
    "FLAT_NAMES",
    "ClosingConfig",
    "CollisionConfig",
    "ContactsConfig",
    "ForceMatchingConfig",
    "GripConfig",
    "JointLimitsConfig",
    "KeypointsConfig",
    "PostureConfig",
    "RetargetConfig",
    "SelfCollisionConfig",
    "SmoothnessConfig",
    "SolverConfig",
    "VectorsConfig",
    "VelocityConfig",
    "WristConfig",
    "resolve_name",
]


@dataclass(frozen=True)
class RetargetConfig:
    """Weights and switches of the per-frame QP, one config per term (each validated when
    constructed).

    >>> cfg = RetargetConfig.from_overrides({"contacts.weight": 100.0, "w_posture": 1e-3})
    >>> cfg.contacts.weight, cfg.posture.weight
    (100.0, 0.001)
    >>> cfg.flat()["w_contacts"]               # the flat names of metrics.json
    100.0
    """

    solver: SolverConfig = field(default_factory=SolverConfig)
    """The per-frame solve (backend, iterations, warm start, feasibility re-steps)."""
    wrist: WristConfig = field(default_factory=WristConfig)
    """The wrist pose term."""
    keypoints: KeypointsConfig = field(default_factory=KeypointsConfig)
    """The keypoint term and the keypoints' scaling to the robot hand."""
    vectors: VectorsConfig = field(default_factory=VectorsConfig)
    """The fingertip-to-thumb vector term."""
    contacts: ContactsConfig = field(default_factory=ContactsConfig)
    """The contact terms and how the human's contacts are found."""
    closing: ClosingConfig = field(default_factory=ClosingConfig)
    """The closing terms (a finger's other touching links)."""
    posture: PostureConfig = field(default_factory=PostureConfig)
    """The posture term."""
    smoothness: SmoothnessConfig = field(default_factory=SmoothnessConfig)
    """The temporal smoothness term."""
    joint_limits: JointLimitsConfig = field(default_factory=JointLimitsConfig)
    """The joint range limit."""
    velocity: VelocityConfig = field(default_factory=VelocityConfig)
    """The per-iterate joint and per-frame wrist speed limits."""
    collision: CollisionConfig = field(default_factory=CollisionConfig)
    """The hand–object non-penetration limit and clearances."""
    self_collision: SelfCollisionConfig = field(default_factory=SelfCollisionConfig)
    """The finger–finger non-penetration limit."""
    grip: GripConfig = field(default_factory=GripConfig)
    """The position command's grip."""
    force_matching: ForceMatchingConfig = field(default_factory=ForceMatchingConfig)
    """Force matching (replaces the grip)."""

    def __post_init__(self):
        for f in dataclasses.fields(self):
            want = _SECTIONS[f.name]
            if not isinstance(getattr(self, f.name), want):
                raise RetargetError(
                    f"RetargetConfig.{f.name} must be a {want.__name__}, got "
                    f"{type(getattr(self, f.name)).__name__}"
                )

    def get(self, name: str):
        """The setting ``name``: a dotted path (``contacts.weight``) or a flat name."""
        section, key = resolve_name(name).split(".")
        return getattr(getattr(self, section), key)

    def flat(self) -> dict:
        """Every setting under its flat name (:data:`FLAT_NAMES`, in that order): the one-level
        dict the configuration was recorded as (``metrics.json``'s ``retarget_config``)."""
        return {name: self.get(path) for name, path in FLAT_NAMES.items()}

    def with_overrides(self, overrides: Mapping[str, object]) -> RetargetConfig:
        """This config with ``overrides`` (``{name: value}``, dotted or flat names, applied in
        order: a later name for the same setting wins). An unknown name raises
        ``RetargetError`` listing the settings and the close matches; a refused value, the
        term config's ``RetargetError``."""
        changes: dict[str, dict] = {}
        for name, value in overrides.items():
            section, key = resolve_name(name).split(".")
            changes.setdefault(section, {})[key] = value
        return dataclasses.replace(
            self,
            **{s: dataclasses.replace(getattr(self, s), **kw) for s, kw in changes.items()},
        )

    @classmethod
    def from_overrides(cls, overrides: Mapping[str, object]) -> RetargetConfig:
        """The defaults with ``overrides`` (:meth:`with_overrides`): ``{"w_contacts": 100}`` or
        ``{"contacts.weight": 100}``."""
        return cls().with_overrides(overrides)

    @staticmethod
    def setting_names() -> list[str]:
        """Every setting's dotted path, in field order."""
        return list(_DOTTED)

    @staticmethod
    def alias_names() -> list[str]:
        """Every setting's flat name (:data:`FLAT_NAMES`)."""
        return list(FLAT_NAMES)

    @staticmethod
    def canonical_name(name: str) -> str | None:
        """The dotted path of a setting named by its dotted path or flat name; None when there
        is no such setting."""
        return FLAT_NAMES.get(name) or (name if name in _DOTTED_SET else None)


_SECTIONS = {f.name: f.default_factory for f in dataclasses.fields(RetargetConfig)}

_DOTTED = [f"{s}.{f.name}" for s, cls in _SECTIONS.items() for f in dataclasses.fields(cls)]

FLAT_NAMES: dict[str, str] = {
    "backend": "solver.backend",
    "iterations": "solver.iterations",
    "first_frame_iterations": "solver.first_frame_iterations",
    "step_tolerance": "solver.step_tolerance",
    "warm_start_extrapolate": "solver.warm_start_extrapolate",
    "max_feasibility_iterations": "solver.max_feasibility_iterations",
    "solver": "solver.qp_solver",
    "w_wrist_pos": "wrist.position_weight",
    "w_wrist_rot": "wrist.rotation_weight",
    "w_tips": "keypoints.tip_weight",
    "w_joints": "keypoints.joint_weight",
    "w_vectors": "vectors.weight",
    "w_contacts": "contacts.weight",
    "contact_tangent_weight": "contacts.tangent_weight",
    "force_contact_tangent_weight": "force_matching.tangent_weight",
    "contact_hover_m": "contacts.hover_m",
    "w_closing": "closing.weight",
    "closing_slack_m": "closing.slack_m",
    "closing_ramp_s": "closing.ramp_s",
    "grip_surface_normals": "grip.surface_normals",
    "w_posture": "posture.weight",
    "w_smooth": "smoothness.weight",
    "damping": "solver.damping",
    "joint_limit_margin": "joint_limits.margin",
    "use_wrist_offset": "wrist.use_offset",
    "use_contacts": "contacts.enabled",
    "use_collision": "collision.enabled",
    "penetration_margin": "collision.penetration_margin",
    "table_clearance": "collision.table_clearance",
    "noncontact_clearance": "collision.noncontact_clearance",
    "collision_distmax": "collision.distmax",
    "use_self_collision": "self_collision.enabled",
    "self_collision_margin": "self_collision.margin",
    "self_collision_distmax": "self_collision.distmax",
    "contact_ramp_s": "contacts.ramp_s",
    "use_link_contacts": "contacts.link_contacts",
    "link_contact_threshold": "contacts.link_threshold_m",
    "contact_threshold": "contacts.threshold_m",
    "keypoint_scaling": "keypoints.scaling",
    "finger_radius_m": "keypoints.finger_radius_m",
    "scale_blend_m": "keypoints.scale_blend_m",
    "max_joint_speed": "velocity.max_joint_speed",
    "max_wrist_speed": "velocity.max_wrist_speed",
    "squeeze_depth": "grip.squeeze_depth",
    "grip": "grip.mode",
    "grip_force_n": "grip.force_n",
    "grip_lead_s": "grip.lead_s",
    "force_matching": "force_matching.enabled",
    "idle_contact_clearance": "force_matching.idle_contact_clearance",
    "force_mu": "grip.mu",
    "force_scale": "force_matching.scale",
    "contacts_from": "contacts.source",
}
"""The flat name of every setting (the one-level config's fields, the names ``--set``,
benchmark records and scripts use) → its dotted path."""


def resolve_name(name: str) -> str:
    """The dotted path of a setting named by its dotted path or its flat name; an unknown name
    raises ``RetargetError`` with the close matches and every dotted path."""
    path = RetargetConfig.canonical_name(name)
    if path is None:
        close = difflib.get_close_matches(name, [*_DOTTED, *FLAT_NAMES], n=3)
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        raise RetargetError(
            f"unknown RetargetConfig field {name!r}{hint}; available: {', '.join(_DOTTED)}"
        )
    return path


_DOTTED_SET = frozenset(_DOTTED)
