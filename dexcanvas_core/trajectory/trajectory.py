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

from dexcanvas_core.checks import check_number
from dexcanvas_core.errors import ValidationError
from dexcanvas_core.plausibility import check_trajectory
from dexcanvas_core.rotations import slerp_aa
from dexcanvas_core.table import Table
from dexcanvas_core.trajectory.arrays import check_aa, check_finite, f32
from dexcanvas_core.trajectory.contacts import CONTACT_PARTS, Contacts
from dexcanvas_core.trajectory.tracks import HandTrack, ObjectMove, ObjectTrack


@dataclass
class Trajectory:
    """One demonstration. See the module docstring for frames and units.

    >>> from dexcanvas_core import load_demonstration
    >>> traj = load_demonstration("cube2/tripod")
    >>> traj.num_frames, traj.hand.joint_pos.shape, traj.object.pos.shape
    (736, (736, 21, 3), (736, 3))
    >>> traj.slice(0, 120).num_frames, traj.resample(60.0).fps
    (120, 60.0)
    """

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
        check_number("fps", self.fps)  # its range: validate()
        self.timestamp = np.asarray(self.timestamp, dtype=np.float64).reshape(-1)
        self.hands = list(self.hands)
        self.objects = list(self.objects)
        if self.table is not None and not isinstance(self.table, Table):
            raise ValidationError(
                f"trajectory table must be a Table or None, got {type(self.table).__name__}",
                field="table",
            )
        if self.object_wrench_world is not None:
            self.object_wrench_world = f32(
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
        """Check shapes, finiteness, rotations, timestamps and fps, then plausibility (hand
        scale, human motion limits, outlier frames: :mod:`dexcanvas_core.plausibility`, which
        only warns under ``allowing_implausible``); raise on the first problem.

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
                check_finite(a, f"{where}: hands[{h.name}].{name}", name)
        for o in self.objects:
            for name, a in (("pos", o.pos), ("rot_aa", o.rot_aa)):
                if a.shape[0] != T:
                    raise ValidationError(
                        f"{where}: objects[{o.name}].{name} has {a.shape[0]} frames, "
                        f"timestamp has {T}",
                        field=name,
                    )
                check_finite(a, f"{where}: objects[{o.name}].{name}", name)
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
                check_finite(v, f"{where}: contact.{k}", k)
        if self.object_wrench_world is not None:
            check_finite(self.object_wrench_world, f"{where}: object_wrench_world", "wrench")
        # Units before rotations: a unit mistake also garbles the rotations fitted from it.
        check_trajectory(self)
        for h in self.hands:
            check_aa(h.global_rot_aa, 2 * np.pi, f"{where}: hands[{h.name}].mano_global_rot_aa")
            check_aa(
                h.hand_pose[:, 3:].reshape(T, 15, 3),
                np.pi,
                f"{where}: hands[{h.name}].mano_hand_pose (finger joints)",
            )
        for o in self.objects:
            check_aa(o.rot_aa, 2 * np.pi, f"{where}: objects[{o.name}].rot_aa")
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
