"""The ``Trajectory``: one demonstration as typed numpy arrays, mirroring a DexCanvas Lance row.

Frames: positions are in the world frame [m], z up; rotations are axis-angle [rad]. Time runs
along axis 0 of every per-frame array (``T`` frames at ``fps`` [Hz]).

A trajectory holds

* identity (``uuid``, ``operator``, ``scene`` = object id, ``cap_machine``, ``is_generated``,
  ``seed_uuid``) and metadata (``fps``, ``gesture``, ``object_move`` active segments),
* one :class:`HandTrack` per hand (MANO wrist pose, 48-D pose, 21 keypoints, ``urdf_dof``),
* one :class:`ObjectTrack` per object (position and axis-angle rotation),
* optionally :class:`Contacts`: per-frame hand-part contacts with forces, stored losslessly in
  the public layout's record form and viewable as dense ``(T, N, 3)`` arrays,
* optionally the force pipeline's additions (``object_wrench_world``, solver settings),
* optionally the :class:`~dexcanvas_core.table.Table` it was performed on (else the default),
* ``extras``: any further fields of the source row, kept as Arrow scalars so that a row read
  from a dataset is written back unchanged.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import FINGERS
from dexcanvas_core.rotations import slerp_aa
from dexcanvas_core.table import Table

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


URDF_DOF_NAMES_26: tuple[str, ...] = (
    "ARTx", "ARTy", "ARTz", "ARRx", "ARRy", "ARRz",
    "thumb_cmc_abd", "thumb_cmc_flex", "thumb_mcp", "thumb_ip",
    *(f"{f}_{j}" for f in ("index", "middle", "ring", "pinky")
      for j in ("mcp_abd", "mcp_flex", "pip", "dip")),
)  # fmt: skip
"""``urdf_dof`` order of the 26-DoF hand: wrist xyz [m] + intrinsic XYZ Euler [rad], 20 fingers."""

URDF_DOF_NAMES_28: tuple[str, ...] = (
    *URDF_DOF_NAMES_26[:6],
    "thumb_cmc_abd", "thumb_cmc_flex", "thumb_cmc_twist", "thumb_mcp_flex", "thumb_mcp_abd",
    "thumb_ip",
    *URDF_DOF_NAMES_26[10:],
)  # fmt: skip
"""``urdf_dof`` order of the newer 28-DoF hand (thumb CMC twist and MCP abduction added)."""


def _f32(x, shape: tuple[int | None, ...], name: str) -> np.ndarray:
    """Normalise an array-like to float32 and check its shape (``None`` = any length)."""
    try:
        a = np.asarray(x, dtype=np.float32)
    except (TypeError, ValueError) as e:
        raise ValidationError(f"{name}: cannot convert to a float array ({e})", field=name) from e
    ok = a.ndim == len(shape) and all(
        s is None or s == d for s, d in zip(shape, a.shape, strict=False)
    )
    if not ok:
        want = "(" + ", ".join("T" if s is None else str(s) for s in shape) + ")"
        raise ValidationError(f"{name} must have shape {want}, got {a.shape}", field=name)
    return a


@dataclass
class HandTrack:
    """One hand's kinematics over ``T`` frames (world frame, metres, axis-angle)."""

    name: str
    """``'right'`` or ``'left'`` (the public data's ``hand_name``)."""
    global_pos: np.ndarray
    """``mano_global_pos`` (T, 3) [m]: MANO translation."""
    global_rot_aa: np.ndarray
    """``mano_global_rot_aa`` (T, 3) [rad]: MANO global orientation."""
    hand_pose: np.ndarray
    """``mano_hand_pose`` (T, 48) [rad]: 3 global + 15 joints × 3, MANO joint order."""
    joint_pos: np.ndarray | None = None
    """``mano_joint_pos`` (T, 21, 3) [m]: keypoints in ``keypoints.MANO21`` order."""
    urdf_dof: np.ndarray | None = None
    """(T, 26) or (T, 28): 6 wrist (xyz [m], XYZ Euler [rad]) + anatomical finger joints [rad]."""
    urdf_dof_target: np.ndarray | None = None
    """Same layout as ``urdf_dof``: the actuated hand's targets, when present."""
    betas: np.ndarray = field(default_factory=lambda: np.zeros(10, np.float32))
    """MANO shape (10,) from ``trajectory_metadata.mano_hand_shapes``."""

    def __post_init__(self) -> None:
        self.global_pos = _f32(self.global_pos, (None, 3), f"hands[{self.name}].mano_global_pos")
        T = self.global_pos.shape[0]
        self.global_rot_aa = _f32(
            self.global_rot_aa, (T, 3), f"hands[{self.name}].mano_global_rot_aa"
        )
        self.hand_pose = _f32(self.hand_pose, (T, 48), f"hands[{self.name}].mano_hand_pose")
        if self.joint_pos is not None:
            self.joint_pos = _f32(self.joint_pos, (T, 21, 3), f"hands[{self.name}].mano_joint_pos")
        for attr in ("urdf_dof", "urdf_dof_target"):
            v = getattr(self, attr)
            if v is not None:
                a = _f32(v, (T, None), f"hands[{self.name}].{attr}")
                if a.shape[1] not in (26, 28):
                    raise ValidationError(
                        f"hands[{self.name}].{attr} must have 26 or 28 columns, got {a.shape[1]}",
                        field=attr,
                    )
                setattr(self, attr, a)
        self.betas = _f32(self.betas, (10,), f"hands[{self.name}].betas")

    @property
    def num_frames(self) -> int:
        return self.global_pos.shape[0]

    @property
    def finger_pose(self) -> np.ndarray:
        """(T, 45) [rad]: the 15 finger joints' axis-angles (``hand_pose[:, 3:]``)."""
        return self.hand_pose[:, 3:]


@dataclass
class ObjectTrack:
    """One object's pose over ``T`` frames (world frame)."""

    name: str
    pos: np.ndarray
    """(T, 3) [m]: position of the object frame's origin."""
    rot_aa: np.ndarray
    """(T, 3) [rad]: orientation, axis-angle."""

    def __post_init__(self) -> None:
        self.pos = _f32(self.pos, (None, 3), f"objects[{self.name}].pos")
        self.rot_aa = _f32(self.rot_aa, (self.pos.shape[0], 3), f"objects[{self.name}].rot_aa")

    @property
    def num_frames(self) -> int:
        return self.pos.shape[0]


@dataclass
class ObjectMove:
    """A segment of frames during which an object moves (``trajectory_info.object_move``)."""

    object_name: str
    start_frame: int
    end_frame: int
    """Last frame of the segment, inclusive."""


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
        self.totals = {
            k: _f32(self.totals[k], (K, 3), f"contact.{k}") for k in CONTACT_TOTAL_FIELDS
        }
        self.pairs = {
            k: _f32(self.pairs[k], (P, 3), f"contact.contact_pairs.{k}")
            for k in CONTACT_PAIR_FIELDS
        }
        if self.force_world is not None:
            self.force_world = _f32(self.force_world, (P, 3), "contact.contact_pairs.force_world")

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


@dataclass
class Trajectory:
    """One demonstration. See the module docstring for frames and units."""

    uuid: str
    timestamp: np.ndarray
    """(T,) float64 [s], strictly increasing."""
    fps: float
    """Data frame rate [Hz] (``trajectory_metadata.data_fps``)."""
    hands: list[HandTrack]
    objects: list[ObjectTrack]
    gesture: str = ""
    """Manipulation type as stored (numeric code or name); see ``manipulation_type``."""
    operator: str = ""
    scene: str = ""
    """Object id of the scene (``index.scene``), e.g. ``'cube2'``."""
    cap_machine: str = ""
    is_generated: bool = False
    seed_uuid: str = ""
    object_move: list[ObjectMove] = field(default_factory=list)
    contacts: Contacts | None = None
    object_wrench_world: np.ndarray | None = None
    """(T, 6): force [N] and torque [N·m] on the object about its centre of mass, world frame."""
    solver_settings: dict[str, Any] | None = None
    """Physics settings the contact forces were computed with (force pipeline output)."""
    table: Table | None = None
    """The table the demonstration was performed on (Lance column ``table``); ``None``: the
    default table (:data:`dexcanvas_core.table.DEFAULT_TABLE`, see ``table_of``)."""
    extras: dict[str, Any] = field(default_factory=dict)
    """Further source fields (Arrow scalars) kept for a lossless write-back."""

    def __post_init__(self) -> None:
        self.timestamp = np.asarray(self.timestamp, dtype=np.float64).reshape(-1)
        self.hands = list(self.hands)
        self.objects = list(self.objects)
        if self.table is not None and not isinstance(self.table, Table):
            raise ValidationError(
                f"trajectory table must be a Table or None, got {type(self.table).__name__}",
                field="table",
            )
        if self.object_wrench_world is not None:
            self.object_wrench_world = _f32(
                self.object_wrench_world, (self.num_frames, 6), "object_wrench_world"
            )

    # -- convenience views -------------------------------------------------------------------
    @property
    def num_frames(self) -> int:
        return self.timestamp.shape[0]

    @property
    def duration(self) -> float:
        """Length [s] from the first to the last frame."""
        return float(self.timestamp[-1] - self.timestamp[0]) if self.num_frames else 0.0

    @property
    def hand(self) -> HandTrack:
        """The first hand (the common single-hand case)."""
        if not self.hands:
            raise ValidationError(f"trajectory {self.uuid} has no hand", field="hands")
        return self.hands[0]

    @property
    def object(self) -> ObjectTrack:
        """The first object (the common single-object case)."""
        if not self.objects:
            raise ValidationError(f"trajectory {self.uuid} has no object", field="objects")
        return self.objects[0]

    @property
    def object_pose(self) -> np.ndarray:
        """(T, 6): first object's position [m] and axis-angle [rad]."""
        return np.concatenate([self.object.pos, self.object.rot_aa], axis=1)

    @property
    def wrist_pose(self) -> np.ndarray:
        """(T, 6): first hand's MANO translation [m] and global axis-angle [rad]."""
        return np.concatenate([self.hand.global_pos, self.hand.global_rot_aa], axis=1)

    # -- checks ------------------------------------------------------------------------------
    def validate(self, *, fps_tolerance: float = 0.05) -> Trajectory:
        """Check shapes, finiteness, rotations, timestamps and fps; raise on the first problem.

        Rotations: axis-angle norms must be below 2π (larger norms usually mean degrees were
        stored); per-joint finger rotations below π. Timestamps must be strictly increasing, and
        the median frame interval must match ``1 / fps`` within ``fps_tolerance`` (relative).

        Returns ``self`` so calls can be chained.
        """
        T = self.num_frames
        where = f"trajectory {self.uuid!r}"
        if T == 0:
            raise ValidationError(f"{where}: no frames", field="timestamp")
        if not (math.isfinite(self.fps) and self.fps > 0):
            raise ValidationError(
                f"{where}: fps must be positive, got {self.fps}", field="data_fps"
            )
        if not np.all(np.isfinite(self.timestamp)):
            raise ValidationError(f"{where}: timestamp contains NaN or inf", field="timestamp")
        if T > 1:
            dt = np.diff(self.timestamp)
            if np.any(dt <= 0):
                bad = int(np.argmax(dt <= 0))
                raise ValidationError(
                    f"{where}: timestamps must be strictly increasing; frame {bad + 1} "
                    f"({self.timestamp[bad + 1]:.6f} s) is not after frame {bad} "
                    f"({self.timestamp[bad]:.6f} s)",
                    field="timestamp",
                )
            measured = 1.0 / float(np.median(dt))
            if abs(measured - self.fps) > fps_tolerance * self.fps:
                raise ValidationError(
                    f"{where}: data_fps is {self.fps:g} Hz but the timestamps run at "
                    f"{measured:.3f} Hz",
                    field="data_fps",
                )
        if not self.hands:
            raise ValidationError(f"{where}: no hand", field="hands")
        for h in self.hands:
            arrays = {
                "mano_global_pos": h.global_pos,
                "mano_global_rot_aa": h.global_rot_aa,
                "mano_hand_pose": h.hand_pose,
                "mano_joint_pos": h.joint_pos,
                "urdf_dof": h.urdf_dof,
                "urdf_dof_target": h.urdf_dof_target,
                "mano_hand_shapes": h.betas[None],
            }
            for name, a in arrays.items():
                if a is None:
                    continue
                if name != "mano_hand_shapes" and a.shape[0] != T:
                    raise ValidationError(
                        f"{where}: hands[{h.name}].{name} has {a.shape[0]} frames, "
                        f"timestamp has {T}",
                        field=name,
                    )
                _check_finite(a, f"{where}: hands[{h.name}].{name}", name)
            _check_aa(h.global_rot_aa, 2 * np.pi, f"{where}: hands[{h.name}].mano_global_rot_aa")
            _check_aa(
                h.hand_pose[:, 3:].reshape(T, 15, 3),
                np.pi,
                f"{where}: hands[{h.name}].mano_hand_pose (finger joints)",
            )
        for o in self.objects:
            for name, a in (("pos", o.pos), ("rot_aa", o.rot_aa)):
                if a.shape[0] != T:
                    raise ValidationError(
                        f"{where}: objects[{o.name}].{name} has {a.shape[0]} frames, "
                        f"timestamp has {T}",
                        field=name,
                    )
                _check_finite(a, f"{where}: objects[{o.name}].{name}", name)
            _check_aa(o.rot_aa, 2 * np.pi, f"{where}: objects[{o.name}].rot_aa")
        for m in self.object_move:
            if not (0 <= m.start_frame <= m.end_frame < T):
                raise ValidationError(
                    f"{where}: object_move {m.object_name} [{m.start_frame}, {m.end_frame}] "
                    f"is outside frames 0..{T - 1}",
                    field="object_move",
                )
        if self.contacts is not None:
            c = self.contacts
            if c.num_frames != T:
                raise ValidationError(f"{where}: contacts cover {c.num_frames} frames, not {T}")
            if c.num_records and (c.frame.min() < 0 or c.frame.max() >= T):
                raise ValidationError(f"{where}: contact frame index out of range", field="contact")
            if c.num_records and np.any(np.diff(c.frame) < 0):
                raise ValidationError(f"{where}: contact records are not in frame order")
            unknown = sorted(set(c.joint_name) - set(CONTACT_PARTS))
            if unknown:
                raise ValidationError(
                    f"{where}: unknown contact parts {unknown}; "
                    f"expected {', '.join(CONTACT_PARTS)}",
                    field="contact.joint_name",
                )
            for k, v in {**c.totals, **c.pairs}.items():
                _check_finite(v, f"{where}: contact.{k}", k)
        if self.object_wrench_world is not None:
            _check_finite(self.object_wrench_world, f"{where}: object_wrench_world", "wrench")
        return self

    # -- time operations ---------------------------------------------------------------------
    def active_range(self) -> tuple[int, int]:
        """``(start, stop)`` frame range covering every ``object_move`` segment (stop exclusive).

        The whole trajectory when there is no segment.
        """
        if not self.object_move:
            return 0, self.num_frames
        start = min(m.start_frame for m in self.object_move)
        stop = max(m.end_frame for m in self.object_move) + 1
        return start, min(stop, self.num_frames)

    def slice(self, start: int, stop: int) -> Trajectory:
        """Frames ``start:stop`` as a new trajectory (segments clipped, contacts renumbered)."""
        T = self.num_frames
        if not (0 <= start < stop <= T):
            raise ValidationError(f"slice [{start}, {stop}) is outside frames 0..{T}")
        frames = np.arange(start, stop)
        moves = [
            ObjectMove(
                m.object_name, max(m.start_frame, start) - start, min(m.end_frame, stop - 1) - start
            )
            for m in self.object_move
            if m.end_frame >= start and m.start_frame < stop
        ]
        return self._take(frames, self.timestamp[start:stop].copy(), moves, self.fps)

    def crop(self, max_frames: int | None) -> Trajectory:
        """At most ``max_frames`` frames, starting a third of the window before the objects
        move (``active_range``); the trajectory itself when it is short enough or ``None``."""
        if max_frames is None or self.num_frames <= max_frames:
            return self
        start, _ = self.active_range()
        s = int(np.clip(start - max_frames // 3, 0, self.num_frames - max_frames))
        return self.slice(s, s + max_frames)

    def active(self) -> Trajectory:
        """The frames in which objects move (see ``active_range``)."""
        return self.slice(*self.active_range())

    def resample(self, fps: float) -> Trajectory:
        """The trajectory at another frame rate.

        Positions, keypoints and ``urdf_dof`` are linearly interpolated; rotations (hand global
        orientation, each finger joint, objects) by slerp. Contacts and wrenches are events, not
        signals: each new frame takes those of the nearest source frame. ``object_move`` frames are
        mapped through time.
        """
        if not (math.isfinite(fps) and fps > 0):
            raise ValidationError(f"resample: fps must be positive, got {fps}", field="fps")
        t = self.timestamp
        n = math.floor(self.duration * fps + 1e-9) + 1
        t_new = t[0] + np.arange(n) / fps
        t_new[-1] = min(t_new[-1], t[-1])

        def lin(a: np.ndarray | None) -> np.ndarray | None:
            if a is None:
                return None
            flat = a.reshape(a.shape[0], -1).astype(np.float64)
            out = np.stack([np.interp(t_new, t, flat[:, j]) for j in range(flat.shape[1])], axis=1)
            return out.reshape((n, *a.shape[1:])).astype(np.float32)

        def rot(a: np.ndarray) -> np.ndarray:
            return slerp_aa(t, a, t_new).astype(np.float32)

        hands = []
        for h in self.hands:
            pose = np.concatenate(
                [
                    rot(h.hand_pose[:, :3]),
                    rot(h.hand_pose[:, 3:].reshape(-1, 15, 3)).reshape(n, 45),
                ],
                axis=1,
            )
            hands.append(
                HandTrack(
                    name=h.name,
                    global_pos=lin(h.global_pos),
                    global_rot_aa=rot(h.global_rot_aa),
                    hand_pose=pose,
                    joint_pos=lin(h.joint_pos),
                    urdf_dof=lin(h.urdf_dof),
                    urdf_dof_target=lin(h.urdf_dof_target),
                    betas=h.betas.copy(),
                )
            )
        objects = [ObjectTrack(o.name, lin(o.pos), rot(o.rot_aa)) for o in self.objects]
        nearest = (
            np.clip(np.searchsorted(t, t_new), 1, len(t) - 1) if len(t) > 1 else np.zeros(n, int)
        )
        if len(t) > 1:
            left = nearest - 1
            nearest = np.where(np.abs(t_new - t[left]) <= np.abs(t[nearest] - t_new), left, nearest)

        def to_new(frame: int) -> int:
            return int(np.clip(np.round((t[frame] - t[0]) * fps), 0, n - 1))

        moves = [
            ObjectMove(m.object_name, to_new(m.start_frame), to_new(m.end_frame))
            for m in self.object_move
        ]
        out = dataclasses.replace(
            self,
            timestamp=t_new,
            fps=float(fps),
            hands=hands,
            objects=objects,
            object_move=moves,
            contacts=None if self.contacts is None else self.contacts.select_frames(nearest),
            object_wrench_world=None
            if self.object_wrench_world is None
            else self.object_wrench_world[nearest],
        )
        return out

    def _take(
        self, frames: np.ndarray, timestamp: np.ndarray, moves: Sequence[ObjectMove], fps: float
    ) -> Trajectory:
        def take(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else a[frames].copy()

        hands = [
            HandTrack(
                name=h.name,
                global_pos=take(h.global_pos),
                global_rot_aa=take(h.global_rot_aa),
                hand_pose=take(h.hand_pose),
                joint_pos=take(h.joint_pos),
                urdf_dof=take(h.urdf_dof),
                urdf_dof_target=take(h.urdf_dof_target),
                betas=h.betas.copy(),
            )
            for h in self.hands
        ]
        objects = [ObjectTrack(o.name, take(o.pos), take(o.rot_aa)) for o in self.objects]
        return dataclasses.replace(
            self,
            timestamp=timestamp,
            fps=fps,
            hands=hands,
            objects=objects,
            object_move=list(moves),
            contacts=None if self.contacts is None else self.contacts.select_frames(frames),
            object_wrench_world=take(self.object_wrench_world),
        )


def _check_finite(a: np.ndarray, where: str, name: str) -> None:
    bad = ~np.isfinite(a)
    if np.any(bad):
        first = np.argwhere(bad)[0]
        raise ValidationError(
            f"{where} contains NaN or inf (first at index {tuple(int(i) for i in first)})",
            field=name,
        )


def _check_aa(aa: np.ndarray, limit: float, where: str) -> None:
    norms = np.linalg.norm(aa, axis=-1)
    if np.any(norms > limit + 1e-4):
        first = np.argwhere(norms > limit + 1e-4)[0]
        raise ValidationError(
            f"{where}: axis-angle norm {norms[tuple(first)]:.3f} rad at index "
            f"{tuple(int(i) for i in first)} exceeds {limit:.3f} rad (degrees stored as radians?)",
            field=where.rsplit(".", 1)[-1],
        )
