"""Contact points drawn per frame: the human's (recorded or inferred) and the robot's.

Contacts are kept as padded per-frame arrays (:class:`ContactFrames`), each point with the
force of the hand on the object [N] (world frame) and its hand part: a ``FORCE_GROUPS`` row
(thumb, index, middle, ring, pinky, palm; colours per finger) and a ``CONTACT_PARTS`` index (the
16 hand parts of the DexCanvas contact records; robot bodies are mapped onto them by
:func:`robot_body_parts`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dexcanvas_core.mano.hand_model import CAPSULES, SAMPLE_SPACING
from dexcanvas_core.rotations import aa_to_matrix
from dexcanvas_core.trajectory import CONTACT_PARTS, FORCE_GROUPS, Contacts, Trajectory, part_group

# Segments of each human finger as CONTACT_PARTS names, proximal to distal.
_FINGER_SEGMENTS = {
    "thumb": ("thumb_cmc", "thumb_mcp", "thumb_ip"),
    **{f: (f"{f}_mcp", f"{f}_pip", f"{f}_dip") for f in ("index", "middle", "ring", "pinky")},
}


@dataclass
class ContactFrames:
    """Contact points of one hand, padded per frame (``N`` = most points in any frame)."""

    pos_world: np.ndarray
    """(T, N, 3) [m] contact points, world frame."""
    force_world: np.ndarray
    """(T, N, 3) [N] force of the hand on the object at each point, world frame."""
    valid: np.ndarray
    """(T, N) bool."""
    group: np.ndarray
    """(T, N) int: row of ``FORCE_GROUPS`` (thumb … pinky, palm); -1 where invalid."""
    part: np.ndarray
    """(T, N) int: index into ``CONTACT_PARTS``; -1 where invalid or unknown."""
    source: str = ""
    """Where the points come from (shown in legends), e.g. ``'re-simulation'``."""

    @property
    def num_frames(self) -> int:
        return self.valid.shape[0]

    @classmethod
    def empty(cls, num_frames: int, source: str = "") -> ContactFrames:
        return cls(
            pos_world=np.zeros((num_frames, 0, 3)),
            force_world=np.zeros((num_frames, 0, 3)),
            valid=np.zeros((num_frames, 0), bool),
            group=np.zeros((num_frames, 0), np.int64),
            part=np.zeros((num_frames, 0), np.int64),
            source=source,
        )

    @classmethod
    def from_contacts(cls, contacts: Contacts, source: str = "demonstration") -> ContactFrames:
        """From a trajectory's contact records (``Trajectory.contacts``)."""
        d = contacts.dense()
        part = d["part"]
        group = np.full(part.shape, -1, np.int64)
        ok = part >= 0
        group[ok] = [part_group(CONTACT_PARTS[p]) for p in part[ok]]
        return cls(
            pos_world=d["pos_world"].astype(np.float64),
            force_world=d["force_world"].astype(np.float64),
            valid=d["valid"],
            group=group,
            part=part,
            source=source,
        )

    @classmethod
    def from_records(
        cls, records: list[list[tuple[np.ndarray, np.ndarray, int, int]]], source: str = ""
    ) -> ContactFrames:
        """From per-frame lists of ``(pos_world, force_world, group, part)``."""
        T = len(records)
        N = max((len(r) for r in records), default=0)
        out = cls.empty(T, source)
        out.pos_world = np.zeros((T, N, 3))
        out.force_world = np.zeros((T, N, 3))
        out.valid = np.zeros((T, N), bool)
        out.group = np.full((T, N), -1, np.int64)
        out.part = np.full((T, N), -1, np.int64)
        for t, rec in enumerate(records):
            for k, (p, f, g, part) in enumerate(rec):
                out.pos_world[t, k] = p
                out.force_world[t, k] = f
                out.valid[t, k] = True
                out.group[t, k] = g
                out.part[t, k] = part
        return out

    def at(self, t: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Points (n, 3) [m], forces (n, 3) [N] and groups (n,) of frame ``t``."""
        v = self.valid[t]
        return self.pos_world[t, v], self.force_world[t, v], self.group[t, v]

    def max_per_group(self, frames: np.ndarray | None = None) -> np.ndarray:
        """(6,) most points of one ``FORCE_GROUPS`` row in any of ``frames`` (default: all)."""
        sel = np.arange(self.num_frames) if frames is None else np.asarray(frames)
        out = np.zeros(len(FORCE_GROUPS), np.int64)
        for t in sel:
            g = self.group[t, self.valid[t]]
            if g.size:
                out = np.maximum(out, np.bincount(g, minlength=len(FORCE_GROUPS)))
        return out

    def part_frequency(self) -> np.ndarray:
        """(16,) fraction of frames in which each ``CONTACT_PARTS`` part touches the object."""
        T = self.num_frames
        hit = np.zeros((T, len(CONTACT_PARTS)), bool)
        t_idx, k_idx = np.nonzero(self.valid & (self.part >= 0))
        hit[t_idx, self.part[t_idx, k_idx]] = True
        return hit.mean(axis=0) if T else np.zeros(len(CONTACT_PARTS))


INFER_TOLERANCE_M = 0.002
"""A hand capsule closer than this [m] to the object surface counts as touching it (the
built-in demonstrations keep pads within ±1.5 mm of the surface at contact frames)."""


def infer_contacts(traj: Trajectory, geometry, tol_m: float = INFER_TOLERANCE_M) -> ContactFrames:
    """Contacts of a demonstration that has no contact records, from its keypoints alone.

    The hand is the capsule model of the demonstration generator
    (``dexcanvas_core.mano.hand_model.CAPSULES``: one capsule per phalanx, five for the palm,
    default hand size); a capsule touches the object where its surface is within ``tol_m`` of the
    object's. The contact point is the object-surface point nearest the capsule's closest axis
    sample; there is no force (zero vectors).
    """
    kp = np.asarray(traj.hand.joint_pos, dtype=np.float64)  # (T, 21, 3)
    T = kp.shape[0]
    R = np.asarray(aa_to_matrix(np.asarray(traj.object.rot_aa, dtype=np.float64)))  # (T, 3, 3)
    p_obj = np.asarray(traj.object.pos, dtype=np.float64)
    records: list[list] = [[] for _ in range(T)]
    for cap in CAPSULES:
        a, b = kp[:, cap.a], kp[:, cap.b]
        length = float(np.nanmax(np.linalg.norm(b - a, axis=1)))
        n = max(2, int(np.ceil(length / SAMPLE_SPACING)) + 1)
        s = np.linspace(0.0, 1.0, n)
        pts = a[:, None] + s[None, :, None] * (b - a)[:, None]  # (T, n, 3) world
        local = np.einsum("tji,tnj->tni", R, pts - p_obj[:, None])  # world → object frame
        d = geometry.signed_distance(local) - cap.radius
        k = np.argmin(d, axis=1)
        touching = d[np.arange(T), k] < tol_m
        if not touching.any():
            continue
        t_idx = np.flatnonzero(touching)
        near = geometry.closest_point(local[t_idx, k[t_idx]])  # object frame
        near_world = np.einsum("tij,tj->ti", R[t_idx], near) + p_obj[t_idx]
        g, part = part_group(cap.part), CONTACT_PARTS.index(cap.part)
        for t, q in zip(t_idx, near_world, strict=True):
            records[t].append((q, np.zeros(3), g, part))
    return ContactFrames.from_records(records, source="inferred from keypoints (no forces)")


def human_contacts(traj: Trajectory, geometry) -> ContactFrames:
    """The demonstration's recorded contacts, or contacts inferred from its keypoints."""
    if traj.contacts is not None and traj.contacts.num_pairs:
        return ContactFrames.from_contacts(traj.contacts)
    return infer_contacts(traj, geometry)


def robot_body_parts(hand, model) -> tuple[np.ndarray, np.ndarray]:
    """Map every body of ``model`` onto the human hand parts.

    Returns ``(group, part)``, each ``(nbody,)`` int: the ``FORCE_GROUPS`` row and the
    ``CONTACT_PARTS`` index of each hand body (-1 for bodies that are not the hand's). A robot
    finger counts as the first human finger (thumb … pinky) mapped onto it; its bodies that
    form rigid segments (a body without joints moves with its parent); the segments that carry
    collision geoms are matched to the human segments: the last three to ``mcp, pip, dip``
    (thumb ``cmc, mcp, ip``) and any before them to ``mcp`` (``cmc``); two segments to ``mcp,
    dip`` (thumb ``mcp, ip``: the distal link stands for the fused distal phalanges); one to
    ``dip`` (``ip``). Bodies hanging off a finger's last body belong to that finger; every
    other hand body is the palm. An approximation: robot links are not phalanges.
    """
    parts = hand.hand_parts(model)
    hand_nbody = hand.compile().nbody  # the hand's bodies come first in every scene
    robot_to_human = hand.robot_to_human
    has_collision = np.zeros(model.nbody, bool)
    for g in range(model.ngeom):
        if model.geom_contype[g] or model.geom_conaffinity[g]:
            has_collision[model.geom_bodyid[g]] = True
    group = np.full(model.nbody, -1, np.int64)
    part = np.full(model.nbody, -1, np.int64)
    palm = FORCE_GROUPS.index("palm")
    for name in parts.get("palm", []):
        b = model.body(name).id
        if b < hand_nbody:
            group[b], part[b] = palm, CONTACT_PARTS.index("palm")
    for robot_finger, human in robot_to_human.items():
        bodies = [model.body(n).id for n in parts.get(robot_finger, [])]
        # Rigid segments, proximal to distal: a body without joints moves with its parent.
        segments: list[list[int]] = []
        for b in bodies:
            if model.body_jntnum[b] > 0 or not segments:
                segments.append([b])
            else:
                segments[-1].append(b)
        solid = [seg for seg in segments if has_collision[seg].any()]
        names = _FINGER_SEGMENTS[human]
        for b in bodies:
            group[b] = FORCE_GROUPS.index(human)
            part[b] = CONTACT_PARTS.index(names[0])
        n = len(solid)
        if n >= 3:
            which = [0] * (n - 3) + [0, 1, 2]
        elif n == 2:  # proximal phalanx + a distal link (middle and distal phalanges fused)
            which = [1, 2] if human == "thumb" else [0, 2]
        else:
            which = [2] * n
        for seg, k in zip(solid, which, strict=True):
            part[seg] = CONTACT_PARTS.index(names[k])
    # Bodies hanging off a finger beyond its tip site (e.g. a fingertip body) belong to it.
    for b in range(1, hand_nbody):  # parents have smaller ids than their children
        parent = model.body_parentid[b]
        if group[b] == palm and group[parent] not in (-1, palm):
            group[b], part[b] = group[parent], part[parent]
    return group, part
