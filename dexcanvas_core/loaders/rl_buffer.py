"""``RLTrajectoryBuffer``: reference trajectories for many parallel RL environments, on device.

Every environment ``e`` follows one trajectory ``traj_ids[e]`` at its own frame
``timesteps[e]``. All frames of all trajectories are loaded once into device tensors; the
per-step methods (:meth:`~RLTrajectoryBuffer.get_observations`,
:meth:`~RLTrajectoryBuffer.advance_timesteps`, :meth:`~RLTrajectoryBuffer.reset_envs` with a
bool mask, :meth:`~RLTrajectoryBuffer.get_future`) are pure tensor gathers and element-wise
ops on that device: no host copies, no ``.item()``, no data-dependent shapes, so they do not
synchronise a GPU.

Storage: the frames of all ``N`` trajectories lie back to back (``F = lengths.sum()`` rows, no
padding), with ``offsets[N]`` where each trajectory starts; the frame of env ``e`` is row
``offsets[traj_ids[e]] + timesteps[e]``. Fields of one dtype share one ``[F, D]`` tensor (each
field flattened to its columns), so one observation is one ``index_select`` per dtype; the
returned fields are views of that gather (``[E, *shape]``, rows strided by ``D``).

Episode semantics:

* after :meth:`reset_envs`, the reset environments are at frame 0 of a trajectory drawn
  uniformly (with replacement) from the buffer's seeded generator;
* :meth:`advance_timesteps` moves every environment one frame on and returns
  ``done = timesteps >= lengths[traj_ids] - 1``: ``done`` is first True when the environment
  has reached its trajectory's last frame. Environments that are done stay clamped at the last
  frame until they are reset;
* the draws depend only on ``seed`` and the sequence of sampled resets: each sampled reset
  draws one candidate per environment (``num_envs`` draws) and the reset environments take
  theirs, so ``reset_envs(mask)`` and ``reset_envs(mask.nonzero())`` give the same result.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from dexcanvas_core.errors import DexCanvasError, UnknownNameError, ValidationError
from dexcanvas_core.loaders.dataset import (
    DexCanvasDataset,
    trajectory_to_sample,
)
from dexcanvas_core.trajectory import Trajectory

log = logging.getLogger(__name__)

DEFAULT_FIELDS: tuple[str, ...] = ("finger_pose", "wrist_pose", "object_pose")
"""Fields loaded when ``fields=None``; ``contact_force`` joins when every trajectory has it."""

EnvIds = torch.Tensor | Sequence[int] | np.ndarray | None


def _samples(source: Any, max_trajectories: int | None) -> list[dict[str, Any]]:
    """Samples (dicts of tensors) from a dataset, a path, or trajectories."""
    if isinstance(source, str | os.PathLike):
        source = DexCanvasDataset(source)
    n = len(source)
    if max_trajectories is not None:
        n = min(n, max_trajectories)
    if isinstance(source, DexCanvasDataset):
        return [trajectory_to_sample(t) for t in source.iter_trajectories(range(n))]
    out = []
    for i in range(n):
        item = source[i]
        out.append(trajectory_to_sample(item) if isinstance(item, Trajectory) else item)
    return out


def _as_tensor(x: Any) -> torch.Tensor:
    if isinstance(x, torch.Tensor):
        return x
    t = torch.as_tensor(x)
    return t.to(torch.int64) if t.numel() == 0 else t  # an empty list reads as float


def _generator(device: torch.device, seed: int) -> torch.Generator:
    try:
        g = torch.Generator(device=device)
    except RuntimeError:  # a device without its own generator: draw on the CPU
        g = torch.Generator()
    return g.manual_seed(int(seed))


class RLTrajectoryBuffer:
    """Reference trajectories for ``num_envs`` parallel environments, held on ``device``.

    Args:
        dataset: a :class:`DexCanvasDataset` (its selection and options apply), a dataset path,
            a sequence of :class:`Trajectory`, or any sequence of loader samples.
        num_envs: number of environments ``E`` (> 0).
        device: where every tensor lives (``"cpu"``, ``"cuda"``, ``"cuda:1"``, …).
        seed: seed of the trajectory draws (initial assignment and sampled resets).
        fields: sample keys to serve (``finger_pose``, ``wrist_pose``, ``object_pose``,
            ``contact_force``, ``object_wrench``, ``joint_pos``, ``timestamp``); every
            trajectory must have them. ``None``: ``DEFAULT_FIELDS`` plus ``contact_force`` when
            every trajectory has contacts.
        max_trajectories: load at most the first this many trajectories of ``dataset``.

    All trajectories are loaded at construction (memory: total frames × field sizes).

    >>> from dexcanvas_core import DexCanvasDataset, RLTrajectoryBuffer, builtin_demonstration_path
    >>> path = builtin_demonstration_path("cube2/tripod")
    >>> ds = DexCanvasDataset(path, objects=["cube2"], manipulation_types=["tripod"])
    >>> buf = RLTrajectoryBuffer(ds, num_envs=2)
    >>> tuple(buf.get_observations()["finger_pose"].shape)
    (2, 45)
    >>> buf.advance_timesteps().tolist()  # (E,) bool: which environments reached their end
    [False, False]
    """

    def __init__(
        self,
        dataset: Any,
        num_envs: int,
        device: str | torch.device = "cpu",
        seed: int = 0,
        fields: Sequence[str] | None = None,
        max_trajectories: int | None = None,
    ):
        if isinstance(num_envs, bool) or not isinstance(num_envs, int | np.integer) or num_envs < 1:
            raise ValidationError(f"num_envs must be a positive int, got {num_envs!r}")
        if max_trajectories is not None and (
            isinstance(max_trajectories, bool)
            or not isinstance(max_trajectories, int)
            or max_trajectories < 1
        ):
            raise ValidationError(
                f"max_trajectories must be a positive int or None, got {max_trajectories!r}"
            )
        if isinstance(fields, str):
            fields = (fields,)
        self.num_envs = int(num_envs)
        self.device = torch.device(device)
        self.seed = int(seed)
        samples = _samples(dataset, max_trajectories)
        if not samples:
            raise DexCanvasError("RLTrajectoryBuffer: the dataset holds no trajectory")
        self.fields = self._resolve_fields(samples, fields)
        lengths = [int(s[self.fields[0]].shape[0]) for s in samples]
        if min(lengths) < 1:
            bad = lengths.index(min(lengths))
            raise ValidationError(f"RLTrajectoryBuffer: trajectory {bad} has no frames")
        for i, s in enumerate(samples):
            for f in self.fields[1:]:
                if int(s[f].shape[0]) != lengths[i]:
                    raise ValidationError(
                        f"RLTrajectoryBuffer: trajectory {i} has {s[f].shape[0]} frames of {f} "
                        f"but {lengths[i]} of {self.fields[0]}",
                        field=f,
                    )
        self.uuids: tuple[str, ...] = tuple(str(s.get("meta", {}).get("uuid", "")) for s in samples)
        self._packs = self._pack(samples, self.fields, self.device)
        lengths_t = torch.tensor(lengths, dtype=torch.int64)
        self.lengths = lengths_t.to(self.device)
        """(N,) int64: frames of each trajectory."""
        self.offsets = (torch.cumsum(lengths_t, 0) - lengths_t).to(self.device)
        """(N,) int64: row of each trajectory's first frame in the storage tensors."""
        self._gen = _generator(self.device, self.seed)
        self._gen_device = self._gen.device
        E = self.num_envs
        zeros = torch.zeros(E, dtype=torch.int64, device=self.device)
        self.traj_ids = zeros
        """(E,) int64: trajectory of each environment (index into ``uuids``)."""
        self.timesteps = zeros.clone()
        """(E,) int64: current frame of each environment."""
        self._last_of = self.lengths - 1
        self._last = self._last_of.index_select(0, zeros)
        self._base = self.offsets.index_select(0, zeros)
        self.done = torch.zeros(E, dtype=torch.bool, device=self.device)
        """(E,) bool: environments at their trajectory's last frame (see module docstring)."""
        self.reset_envs()
        log.debug(
            "RLTrajectoryBuffer: %d trajectories, %d frames, %d envs on %s",
            self.num_trajectories, int(lengths_t.sum()), E, self.device,
        )  # fmt: skip

    @staticmethod
    def _resolve_fields(samples: list[dict[str, Any]], fields: Sequence[str] | None) -> tuple:
        available = sorted(k for k, v in samples[0].items() if isinstance(v, torch.Tensor))
        if fields is None:
            chosen = list(DEFAULT_FIELDS)
            if all("contact_force" in s for s in samples):
                chosen.append("contact_force")
        else:
            chosen = list(dict.fromkeys(fields))
            if not chosen:
                raise ValidationError("RLTrajectoryBuffer: fields must not be empty")
        known = set(available) | {"contact_force", "object_wrench", "joint_pos"}
        for f in chosen:
            if f not in known:
                raise UnknownNameError("buffer field", f, known)
            lacking = [i for i, s in enumerate(samples) if f not in s]
            if lacking:
                uuid = samples[lacking[0]].get("meta", {}).get("uuid", "")
                raise ValidationError(
                    f"RLTrajectoryBuffer: field {f!r} is missing from {len(lacking)} of "
                    f"{len(samples)} trajectories (first: #{lacking[0]} {uuid!r}); drop it from "
                    "fields or select trajectories that have it",
                    field=f,
                )
        return tuple(chosen)

    # -- properties ---------------------------------------------------------------------------
    @property
    def num_trajectories(self) -> int:
        return int(self.lengths.shape[0])

    @property
    def env_lengths(self) -> torch.Tensor:
        """(E,) int64: length of each environment's current trajectory."""
        return self._last + 1

    def trajectory_field(self, field: str, traj_id: int) -> torch.Tensor:
        """``(T, *shape)``: all frames of one trajectory's field (a view, on device)."""
        if field not in self.fields:
            raise UnknownNameError("buffer field", field, self.fields)
        if not 0 <= int(traj_id) < self.num_trajectories:
            raise ValidationError(
                f"traj_id {traj_id} out of range: the buffer holds {self.num_trajectories}"
            )
        start = int(self.offsets[int(traj_id)])
        return self.frames[field][start : start + int(self.lengths[int(traj_id)])]

    @property
    def frames(self) -> dict[str, torch.Tensor]:
        """Every field's frames of all trajectories back to back, ``[F, *shape]`` (views)."""
        out = {}
        for data, layout in self._packs:
            for name, c0, c1, shape in layout:
                out[name] = data[:, c0:c1].view(-1, *shape)
        return out

    @staticmethod
    def _pack(samples: list[dict[str, Any]], fields: tuple[str, ...], device: torch.device) -> list:
        """``[(data [F, D], [(field, col0, col1, shape), …]), …]``, one entry per dtype."""
        by_dtype: dict[torch.dtype, list[str]] = {}
        for f in fields:
            by_dtype.setdefault(samples[0][f].dtype, []).append(f)
        packs = []
        for dtype, names in by_dtype.items():
            layout, col = [], 0
            for f in names:
                shape = tuple(samples[0][f].shape[1:])
                for i, s in enumerate(samples):
                    if tuple(s[f].shape[1:]) != shape or s[f].dtype != dtype:
                        raise ValidationError(
                            f"RLTrajectoryBuffer: {f} of trajectory {i} is {s[f].dtype} "
                            f"{tuple(s[f].shape)}, trajectory 0 has {dtype} (T, {shape})",
                            field=f,
                        )
                width = int(np.prod(shape, dtype=np.int64))
                layout.append((f, col, col + width, shape))
                col += width
            data = torch.cat(
                [
                    torch.cat([s[f].reshape(s[f].shape[0], -1) for f in names], dim=1)
                    for s in samples
                ]
            )
            packs.append((data.to(device), layout))
        return packs

    def _gather(self, idx: torch.Tensor, lead: tuple[int, ...]) -> dict[str, torch.Tensor]:
        """Rows ``idx`` (flat) of every field, as ``[*lead, *shape]`` views."""
        out = {}
        for data, layout in self._packs:
            rows = data.index_select(0, idx)
            for name, c0, c1, shape in layout:
                out[name] = rows[:, c0:c1].view(*lead, *shape)
        return out

    # -- per-step methods (device only) -------------------------------------------------------
    def get_observations(self) -> dict[str, torch.Tensor]:
        """Current frame of every environment: ``{field: [E, *shape]}`` plus ``timesteps``,
        ``traj_ids`` and ``done`` ([E] each)."""
        idx = self._base + self.timesteps
        obs = self._gather(idx, (self.num_envs,))
        obs["timesteps"] = self.timesteps
        obs["traj_ids"] = self.traj_ids
        obs["done"] = self.done
        return obs

    def advance_timesteps(self) -> torch.Tensor:
        """Move every environment one frame on; return ``done`` [E] bool (see module docstring)."""
        self.timesteps = torch.minimum(self.timesteps + 1, self._last)
        self.done = self.timesteps >= self._last
        return self.done

    def get_future(self, horizon: int) -> dict[str, torch.Tensor]:
        """Frames ``t+1 … t+horizon`` of every environment: ``{field: [E, horizon, *shape]}``.

        Past the trajectory's end the last frame repeats; ``future_valid [E, horizon]`` is
        False there.
        """
        if isinstance(horizon, bool) or not isinstance(horizon, int) or horizon < 1:
            raise ValidationError(f"horizon must be a positive int, got {horizon!r}")
        k = torch.arange(1, horizon + 1, device=self.device)
        t = self.timesteps[:, None] + k[None, :]
        last = self._last[:, None]
        valid = t <= last
        idx = (self._base[:, None] + torch.minimum(t, last)).reshape(-1)
        out = self._gather(idx, (self.num_envs, horizon))
        out["future_valid"] = valid
        return out

    def reset_envs(self, env_ids: EnvIds = None, traj_ids: EnvIds = None) -> None:
        """Start new trajectories, at frame 0, in the given environments; others are untouched.

        Args:
            env_ids: which environments: a bool mask ``[E]`` (e.g. the ``done`` tensor; the
                sync-free form), integer indices, or ``None`` for all.
            traj_ids: trajectories to assign, one per selected environment, in the order of
                ``env_ids`` (integer indices) or ``[E]`` (mask or ``None``: entries of
                unselected environments are ignored). ``None``: drawn uniformly from the seeded
                generator. Explicit assignments do not consume the generator.

        Integer ``env_ids``/``traj_ids`` on the CPU are range-checked; on an accelerator they
        are not (that would synchronise), and out-of-range indices fail in the device kernel.
        """
        E = self.num_envs
        mask, ids = self._env_selection(env_ids)
        if traj_ids is None:
            draw = torch.randint(
                0, self.num_trajectories, (E,), generator=self._gen, device=self._gen_device
            ).to(self.device)
            new_traj = torch.where(mask, draw, self.traj_ids)
        else:
            tids = self._index_tensor(traj_ids, "traj_ids", self.num_trajectories)
            if ids is None:  # mask (or all): one entry per environment
                if tids.shape != (E,):
                    raise ValidationError(
                        f"traj_ids must have shape ({E},) with a mask or env_ids=None, "
                        f"got {tuple(tids.shape)}"
                    )
                new_traj = torch.where(mask, tids, self.traj_ids)
            else:
                if tids.shape != ids.shape:
                    raise ValidationError(
                        f"traj_ids has {tids.shape[0]} entries, env_ids {ids.shape[0]}"
                    )
                new_traj = self.traj_ids.index_put((ids,), tids)
        self.traj_ids = new_traj
        self.timesteps = torch.where(mask, torch.zeros_like(self.timesteps), self.timesteps)
        self._last = self._last_of.index_select(0, new_traj)
        self._base = self.offsets.index_select(0, new_traj)
        self.done = self.timesteps >= self._last

    # -- input normalisation ------------------------------------------------------------------
    def _index_tensor(self, x: Any, what: str, bound: int) -> torch.Tensor:
        t = _as_tensor(x)
        if t.dtype == torch.bool or t.is_floating_point() or t.is_complex():
            raise ValidationError(f"{what} must hold integer indices, got dtype {t.dtype}")
        if t.ndim != 1:
            raise ValidationError(f"{what} must be 1-D, got shape {tuple(t.shape)}")
        if t.device.type == "cpu" and t.numel():
            lo, hi = int(t.min()), int(t.max())
            if lo < 0 or hi >= bound:
                bad = lo if lo < 0 else hi
                raise ValidationError(f"{what} holds {bad}, outside 0..{bound - 1}")
        return t.to(device=self.device, dtype=torch.int64)

    def _env_selection(self, env_ids: EnvIds) -> tuple[torch.Tensor, torch.Tensor | None]:
        """``(mask [E] bool, indices or None)`` on the buffer's device."""
        E = self.num_envs
        if env_ids is None:
            return torch.ones(E, dtype=torch.bool, device=self.device), None
        t = _as_tensor(env_ids)
        if t.dtype == torch.bool:
            if t.shape != (E,):
                raise ValidationError(f"an env mask must have shape ({E},), got {tuple(t.shape)}")
            return t.to(self.device), None
        ids = self._index_tensor(t, "env_ids", E)
        mask = torch.zeros(E, dtype=torch.bool, device=self.device)
        mask[ids] = True
        return mask, ids

    def __repr__(self) -> str:
        return (
            f"RLTrajectoryBuffer(num_trajectories={self.num_trajectories}, "
            f"num_envs={self.num_envs}, fields={self.fields}, device={self.device})"
        )
