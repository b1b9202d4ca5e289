"""``DexCanvasDataset``: a map-style torch dataset over a DexCanvas Lance dataset.

Each item is one trajectory as a dict of tensors (time along axis 0)::

    finger_pose    (T, 45) float32 [rad]  MANO finger axis-angles (mano_hand_pose[:, 3:])
    wrist_pose     (T, 6)  float32        MANO translation [m] + global axis-angle [rad], world
    object_pose    (T, 6)  float32        first object's position [m] + axis-angle [rad], world
    timestamp      (T,)    float64 [s]    as stored (float64: absolute capture clocks lose
                                          milliseconds in float32)
    joint_pos      (T, 21, 3) float32 [m] MANO21 keypoints, world        (when the row has them)
    contact_force  (T, 6, 3) float32 [N]  per-finger total contact force on the object, world
                                          frame; rows thumb, index, middle, ring, pinky, palm
                                          (``FORCE_GROUPS``)            (when the row has contacts)
    object_wrench  (T, 6)  float32        force [N] + torque [N·m] on the object about its
                                          centre of mass, world           (when the row has it)
    meta           dict[str, str]         uuid, scene, gesture (as stored), manipulation_type
                                          (canonical name, or as stored when unknown), operator

Only the first hand and the first object are served (the common single-hand case).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
import torch
from torch.utils.data import Dataset

from dexcanvas_core import builtin
from dexcanvas_core.checks import check_bool, check_float, check_int, check_path
from dexcanvas_core.errors import DexCanvasError
from dexcanvas_core.io import LanceTrajectories, open_dataset
from dexcanvas_core.loaders.selection import FilterValues, Selection, select_rows
from dexcanvas_core.taxonomy import manipulation_type
from dexcanvas_core.trajectory import Trajectory

log = logging.getLogger(__name__)

META_KEYS: tuple[str, ...] = ("uuid", "scene", "gesture", "manipulation_type", "operator")
"""Keys of the ``meta`` dict of every sample."""

REQUIRED_KEYS: tuple[str, ...] = ("finger_pose", "wrist_pose", "object_pose", "timestamp")
"""Tensor keys every sample has."""

OPTIONAL_KEYS: tuple[str, ...] = ("joint_pos", "contact_force", "object_wrench")
"""Tensor keys a sample has only when its row carries the data."""


def _manipulation_name(gesture: str) -> str:
    try:
        return manipulation_type(gesture).name
    except DexCanvasError:  # a code the catalogue leaves open: as stored
        return gesture


def _tensor(a: np.ndarray, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    np_dtype = np.float64 if dtype == torch.float64 else np.float32
    a = np.ascontiguousarray(a, dtype=np_dtype)
    if not a.flags.writeable:  # a zero-copy view of Arrow memory
        a = a.copy()
    return torch.from_numpy(a)


def trajectory_to_sample(traj: Trajectory) -> dict[str, Any]:
    """The loader's dict of tensors for one trajectory (see the module docstring)."""
    hand = traj.hand
    sample: dict[str, Any] = {
        "finger_pose": _tensor(hand.finger_pose),
        "wrist_pose": _tensor(traj.wrist_pose),
        "object_pose": _tensor(traj.object_pose),
        "timestamp": _tensor(traj.timestamp, torch.float64),
    }
    if hand.joint_pos is not None:
        sample["joint_pos"] = _tensor(hand.joint_pos)
    if traj.contacts is not None:
        sample["contact_force"] = _tensor(traj.contacts.finger_totals())
    if traj.object_wrench_world is not None:
        sample["object_wrench"] = _tensor(traj.object_wrench_world)
    sample["meta"] = {
        "uuid": traj.uuid,
        "scene": traj.scene,
        "gesture": traj.gesture,
        "manipulation_type": _manipulation_name(traj.gesture),
        "operator": traj.operator,
    }
    return sample


def _default_path() -> str:
    return str(builtin.default_dataset_path())  # looked up at call time (tests replace it)


class DexCanvasDataset(Dataset):
    """Random-access torch dataset of DexCanvas trajectories, optionally filtered.

    Args:
        path: a DexCanvas-layout Lance dataset (directory, or an already opened
            :class:`~dexcanvas_core.io.LanceTrajectories`); ``None`` uses the built-in
            demonstrations (built and cached on first use).
        manipulation_types: names, aliases or numeric gesture codes (``"tripod"``, ``1``,
            ``"01"``); every stored spelling of the same type matches.
        objects: object ids (``"cube2"``).
        operators: operator ids as stored.
        active_only: keep only the frames in which the object moves (``object_move``).
        fps: resample every trajectory to this rate [Hz] (``None``: as stored).
        max_frames: keep at most the first ``max_frames`` frames (after ``active_only`` and
            ``fps``); ``None``: all.
        validate: run ``Trajectory.validate()`` on every row read.

    ``None`` or an empty list means no filter. The rows matching the filters are resolved
    once, at construction, from the metadata columns (the filter is pushed down to Lance), so
    ``len`` is exact and ``dataset[i]`` reads one row.

    Raises:
        UnknownNameError: a filter value that neither the taxonomy nor the dataset knows (the
            message suggests close names).
        DatasetError: the path is not a readable dataset, or nothing matches the filters (the
            message lists the objects, types and operators the dataset contains).

    One built-in demonstration (``DexCanvasDataset()`` reads the whole built-in set):

    >>> from dexcanvas_core import DexCanvasDataset, builtin_demonstration_path
    >>> path = builtin_demonstration_path("cube2/tripod")  # the pair's, or the whole set if built
    >>> ds = DexCanvasDataset(path, objects=["cube2"], manipulation_types=["tripod"])
    >>> len(ds), tuple(ds[0]["finger_pose"].shape)
    (1, (736, 45))
    """

    def __init__(
        self,
        path: str | os.PathLike | LanceTrajectories | None = None,
        manipulation_types: FilterValues = None,
        objects: FilterValues = None,
        operators: FilterValues = None,
        *,
        active_only: bool = False,
        fps: float | None = None,
        max_frames: int | None = None,
        validate: bool = True,
    ):
        if fps is not None:
            check_float("fps", fps, positive=True)
        if max_frames is not None:
            check_int("max_frames", max_frames, min=1)
        check_bool("active_only", active_only)
        check_bool("validate", validate)
        if not isinstance(path, LanceTrajectories):
            check_path("path", path, optional=True)
        if isinstance(path, LanceTrajectories):
            self._ds: LanceTrajectories | None = path
            self.path = path.path
        else:
            self.path = str(path) if path is not None else _default_path()
            self._ds = open_dataset(self.path)
        self.active_only = bool(active_only)
        self.fps = None if fps is None else float(fps)
        self.max_frames = max_frames
        self.validate = bool(validate)
        self.filters = {
            "manipulation_types": manipulation_types,
            "objects": objects,
            "operators": operators,
        }
        self.selection: Selection = select_rows(
            self._ds,
            manipulation_types=manipulation_types,
            objects=objects,
            operators=operators,
        )
        log.debug("%s: %d trajectories (filter %s)", self.path, len(self), self.selection.filter)

    # -- pickling (DataLoader workers reopen the Lance dataset themselves) ------------------------
    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_ds"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)

    @property
    def lance(self) -> LanceTrajectories:
        """The underlying dataset reader (reopened lazily after unpickling)."""
        if self._ds is None:
            self._ds = open_dataset(self.path)
        return self._ds

    # -- selection --------------------------------------------------------------------------------
    def __len__(self) -> int:
        return int(self.selection.positions.shape[0])

    def __repr__(self) -> str:
        active = {k: v for k, v in self.filters.items() if v is not None}
        return f"DexCanvasDataset({self.path!r}, n={len(self)}, filters={active})"

    @property
    def uuids(self) -> tuple[str, ...]:
        """``index.uuid`` of every item, in item order (read from metadata, no frames)."""
        return self.selection.uuids

    @property
    def positions(self) -> np.ndarray:
        """(N,) 0-based row positions of the items in the underlying Lance dataset."""
        return self.selection.positions

    def _position(self, i: int) -> int:
        n = len(self)
        if isinstance(i, bool) or not isinstance(i, int | np.integer):
            raise TypeError(f"dataset index must be an int, got {type(i).__name__}")
        j = int(i) + n if i < 0 else int(i)
        if not 0 <= j < n:
            raise IndexError(f"index {i} out of range for a dataset of {n} trajectories")
        return int(self.selection.positions[j])

    # -- items ------------------------------------------------------------------------------------
    def prepare(self, traj: Trajectory) -> Trajectory:
        """Apply ``active_only``, ``fps`` and ``max_frames`` (in that order) to a stored row."""
        if self.active_only:
            traj = traj.active()
        if self.fps is not None and abs(traj.fps - self.fps) > 1e-9:
            traj = traj.resample(self.fps)
        if self.max_frames is not None and traj.num_frames > self.max_frames:
            traj = traj.slice(0, self.max_frames)
        return traj

    def trajectory(self, i: int, *, raw: bool = False) -> Trajectory:
        """Item ``i`` as a :class:`Trajectory`: as served (default) or as stored (``raw``)."""
        traj = self.lance.get(self._position(i), validate=self.validate)
        return traj if raw else self.prepare(traj)

    def __getitem__(self, i: int) -> dict[str, Any]:
        return trajectory_to_sample(self.trajectory(i))

    def iter_trajectories(
        self, indices: Sequence[int] | None = None, *, chunk: int = 16
    ) -> Iterator[Trajectory]:
        """Items as served, in order, reading ``chunk`` rows per Lance ``take``."""
        idx = range(len(self)) if indices is None else indices
        pos = [self._position(i) for i in idx]
        for k in range(0, len(pos), chunk):
            for traj in self.lance.take(pos[k : k + chunk], validate=self.validate):
                yield self.prepare(traj)
