"""Hand–object contacts of a trajectory: the hand parts DexCanvas names, the per-finger force
groups, and :class:`Contacts`, the public layout's contact records with their forces."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import FINGERS
from dexcanvas_core.trajectory.arrays import f32

CONTACT_PARTS: tuple[str, ...] = (
    "palm",
    *(f"{f}_{j}" for f in ("index", "middle", "ring", "pinky") for j in ("mcp", "pip", "dip")),
    "thumb_cmc",
    "thumb_mcp",
    "thumb_ip",
)
"""The 16 hand parts that DexCanvas contact records name (``joint_name``)."""

FORCE_GROUPS: tuple[str, ...] = (*FINGERS, "palm")
"""Rows of per-finger force totals ``(T, 6, 3)``: thumb, index, middle, ring, pinky, palm."""


def part_group(part: str) -> int:
    """Index into ``FORCE_GROUPS`` of a contact part name (``'index_pip'`` → 1, ``'palm'`` → 5)."""
    head = part.split("_", 1)[0]
    if head in FORCE_GROUPS:
        return FORCE_GROUPS.index(head)
    raise ValidationError(
        f"unknown contact part {part!r}; expected one of {', '.join(CONTACT_PARTS)}",
        field="contact.joint_name",
    )


CONTACT_PAIR_FIELDS = ("force_normal", "pos_world", "pos_wrist", "pos_joint", "pos_object")
CONTACT_TOTAL_FIELDS = (
    "total_force_world",
    "total_force_wrist",
    "total_force_joint",
    "total_force_object",
)


@dataclass
class Contacts:
    """Per-frame hand-part contacts in the public layout's record form (CSR, lossless).

    Each *record* is one hand part touching one object at one frame, with the part's total
    force in four frames; each record owns a run of *contact pairs* (points) with a normal force
    and the point in four frames. ``records[k]`` lives at frame ``frame[k]``; its pairs are
    ``pair_offsets[k]:pair_offsets[k + 1]``. ``force_world`` (full force vector per point, world
    frame, [N]) is a project addition written by the force pipeline; it is ``None`` for public
    data, where ``force_normal`` is the only per-point force.
    """

    num_frames: int
    frame: np.ndarray  # (K,) int64, non-decreasing
    hand_name: np.ndarray  # (K,) str
    joint_name: np.ndarray  # (K,) str, one of CONTACT_PARTS
    object_name: np.ndarray  # (K,) str
    totals: dict[str, np.ndarray]  # CONTACT_TOTAL_FIELDS → (K, 3) float32 [N]
    pair_offsets: np.ndarray  # (K + 1,) int64
    pairs: dict[str, np.ndarray]  # CONTACT_PAIR_FIELDS → (P, 3) float32 ([N] or [m])
    force_world: np.ndarray | None = None  # (P, 3) float32 [N], project addition

    def __post_init__(self) -> None:
        self.frame = np.asarray(self.frame, dtype=np.int64).reshape(-1)
        K = self.frame.shape[0]
        for name in ("hand_name", "joint_name", "object_name"):
            a = np.asarray(getattr(self, name), dtype=object).reshape(-1)
            if a.shape[0] != K:
                raise ValidationError(f"contact.{name} has {a.shape[0]} records, expected {K}")
            setattr(self, name, a)
        self.pair_offsets = np.asarray(self.pair_offsets, dtype=np.int64).reshape(-1)
        if self.pair_offsets.shape[0] != K + 1 or (K + 1 and self.pair_offsets[0] != 0):
            raise ValidationError("contact pair_offsets must have K + 1 entries starting at 0")
        if np.any(np.diff(self.pair_offsets) < 0):
            raise ValidationError("contact pair_offsets must be non-decreasing")
        P = int(self.pair_offsets[-1])
        self.totals = {k: f32(self.totals[k], (K, 3), f"contact.{k}") for k in CONTACT_TOTAL_FIELDS}
        self.pairs = {
            k: f32(self.pairs[k], (P, 3), f"contact.contact_pairs.{k}") for k in CONTACT_PAIR_FIELDS
        }
        if self.force_world is not None:
            self.force_world = f32(self.force_world, (P, 3), "contact.contact_pairs.force_world")

    @classmethod
    def empty(cls, num_frames: int) -> Contacts:
        z = np.zeros((0, 3), np.float32)
        return cls(
            num_frames=num_frames,
            frame=np.zeros(0, np.int64),
            hand_name=[],
            joint_name=[],
            object_name=[],
            totals={k: z for k in CONTACT_TOTAL_FIELDS},
            pair_offsets=np.zeros(1, np.int64),
            pairs={k: z for k in CONTACT_PAIR_FIELDS},
        )

    @property
    def num_records(self) -> int:
        return self.frame.shape[0]

    @property
    def num_pairs(self) -> int:
        return int(self.pair_offsets[-1])

    def pair_frame(self) -> np.ndarray:
        """(P,) frame index of every contact pair."""
        return np.repeat(self.frame, np.diff(self.pair_offsets))

    def pair_part(self) -> np.ndarray:
        """(P,) index into ``CONTACT_PARTS`` of every contact pair's hand part."""
        idx = np.array([CONTACT_PARTS.index(p) for p in self.joint_name], dtype=np.int64)
        return np.repeat(idx, np.diff(self.pair_offsets))

    def dense(self) -> dict[str, np.ndarray]:
        """Contact points as padded per-frame arrays.

        Returns a dict with ``pos_world (T, N, 3)`` [m], ``force_world (T, N, 3)`` [N] (the full
        vector when the force pipeline wrote it, else the normal force), ``valid (T, N)`` bool and
        ``part (T, N)`` int (index into ``CONTACT_PARTS``, -1 where invalid); ``N`` is the
        largest number of contact points in any frame.
        """
        T = self.num_frames
        pf = self.pair_frame()
        counts = np.bincount(pf, minlength=T) if pf.size else np.zeros(T, np.int64)
        N = int(counts.max()) if counts.size else 0
        # Slot of each pair inside its frame: running index since the frame's first pair.
        first = np.concatenate([[0], np.cumsum(counts)[:-1]])
        slot = np.arange(pf.shape[0]) - first[pf] if pf.size else pf
        out = {
            "pos_world": np.zeros((T, N, 3), np.float32),
            "force_world": np.zeros((T, N, 3), np.float32),
            "valid": np.zeros((T, N), bool),
            "part": np.full((T, N), -1, np.int64),
        }
        force = self.force_world if self.force_world is not None else self.pairs["force_normal"]
        out["pos_world"][pf, slot] = self.pairs["pos_world"]
        out["force_world"][pf, slot] = force
        out["valid"][pf, slot] = True
        out["part"][pf, slot] = self.pair_part()
        return out

    def finger_totals(self) -> np.ndarray:
        """(T, 6, 3) [N]: summed ``total_force_world`` per ``FORCE_GROUPS`` row and frame."""
        out = np.zeros((self.num_frames, len(FORCE_GROUPS), 3), np.float32)
        groups = np.array([part_group(p) for p in self.joint_name], dtype=np.int64)
        np.add.at(out, (self.frame, groups), self.totals["total_force_world"])
        return out

    def select_frames(self, frames: np.ndarray) -> Contacts:
        """Contacts at the given source frames (any order, repeats allowed), renumbered 0..M-1."""
        frames = np.asarray(frames, dtype=np.int64)
        by_frame: dict[int, list[int]] = {}
        for k, f in enumerate(self.frame):
            by_frame.setdefault(int(f), []).append(k)
        recs: list[int] = []
        new_frame: list[int] = []
        for i, f in enumerate(frames):
            for k in by_frame.get(int(f), []):
                recs.append(k)
                new_frame.append(i)
        rec = np.array(recs, dtype=np.int64)
        lengths = np.diff(self.pair_offsets)[rec] if rec.size else np.zeros(0, np.int64)
        pair_idx = (
            np.concatenate([np.arange(self.pair_offsets[k], self.pair_offsets[k + 1]) for k in rec])
            if rec.size
            else np.zeros(0, np.int64)
        ).astype(np.int64)
        return Contacts(
            num_frames=len(frames),
            frame=np.array(new_frame, dtype=np.int64),
            hand_name=self.hand_name[rec],
            joint_name=self.joint_name[rec],
            object_name=self.object_name[rec],
            totals={k: v[rec] for k, v in self.totals.items()},
            pair_offsets=np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64),
            pairs={k: v[pair_idx] for k, v in self.pairs.items()},
            force_world=None if self.force_world is None else self.force_world[pair_idx],
        )
