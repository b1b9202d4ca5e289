"""Batching variable-length trajectories: zero padding, attention mask, a DataLoader helper.

A batch of ``B`` samples from :class:`~dexcanvas_core.loaders.DexCanvasDataset` is a dict::

    finger_pose    (B, T, 45)   wrist_pose (B, T, 6)   object_pose (B, T, 6)
    timestamp      (B, T) float64
    attention_mask (B, T) bool  True on real frames, False on padding
    lengths        (B,)   int64 number of real frames of each sample
    meta           dict[str, list[str]]  one list entry per sample (uuid, scene, …)

``T`` is the longest sample's length; shorter samples are padded with zeros at the end.

Optional keys (``contact_force (B, T, 6, 3)``, ``object_wrench (B, T, 6)``, ``joint_pos
(B, T, 21, 3)``) are present when at least one sample has them, always together with a
``has_<key> (B,)`` bool mask: samples without the data hold zeros there and ``False`` in the
mask (all ``True`` when every sample has it). So a loss over contact forces is
``mask = attention_mask & has_contact_force[:, None]``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import torch
from torch.utils.data import DataLoader, Dataset

from dexcanvas_core.checks import check_bool, check_int
from dexcanvas_core.errors import ValidationError
from dexcanvas_core.loaders.dataset import OPTIONAL_KEYS, REQUIRED_KEYS


def _pad(tensors: Sequence[torch.Tensor | None], T: int, key: str) -> torch.Tensor:
    """Stack ``(T_i, *shape)`` tensors into ``(B, T, *shape)`` with zeros after ``T_i``."""
    first = next(t for t in tensors if t is not None)
    shape, dtype = tuple(first.shape[1:]), first.dtype
    out = torch.zeros((len(tensors), T, *shape), dtype=dtype)
    for b, t in enumerate(tensors):
        if t is None:
            continue
        if tuple(t.shape[1:]) != shape:
            raise ValidationError(
                f"collate: {key} of sample {b} has shape {tuple(t.shape)}, sample 0 has "
                f"(T, {', '.join(map(str, shape))})",
                field=key,
            )
        out[b, : t.shape[0]] = t
    return out


def collate_trajectories(samples: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Pad a list of samples to the longest one (see the module docstring for the layout)."""
    if not samples:
        raise ValidationError("collate: empty batch")
    for b, s in enumerate(samples):
        missing = [k for k in REQUIRED_KEYS if k not in s]
        if missing:
            raise ValidationError(
                f"collate: sample {b} lacks {', '.join(missing)} (not a DexCanvasDataset sample?)"
            )
    lengths = torch.tensor([int(s["finger_pose"].shape[0]) for s in samples], dtype=torch.int64)
    for b, s in enumerate(samples):
        for k in (*REQUIRED_KEYS, *OPTIONAL_KEYS):
            if k in s and int(s[k].shape[0]) != int(lengths[b]):
                raise ValidationError(
                    f"collate: sample {b} has {s[k].shape[0]} frames of {k} but "
                    f"{int(lengths[b])} of finger_pose",
                    field=k,
                )
    T = int(lengths.max())
    batch: dict[str, Any] = {k: _pad([s[k] for s in samples], T, k) for k in REQUIRED_KEYS}
    for k in OPTIONAL_KEYS:
        present = [k in s for s in samples]
        if any(present):
            batch[k] = _pad([s.get(k) for s in samples], T, k)
            batch[f"has_{k}"] = torch.tensor(present, dtype=torch.bool)
    batch["attention_mask"] = torch.arange(T)[None, :] < lengths[:, None]
    batch["lengths"] = lengths
    metas = [s.get("meta", {}) for s in samples]
    keys = list(dict.fromkeys(k for m in metas for k in m))
    batch["meta"] = {k: [m.get(k, "") for m in metas] for k in keys}
    return batch


def make_dataloader(
    dataset: Dataset,
    batch_size: int = 8,
    shuffle: bool = False,
    num_workers: int = 0,
    seed: int | None = None,
    **kwargs: Any,
) -> DataLoader:
    """A ``torch.utils.data.DataLoader`` that batches with :func:`collate_trajectories`.

    ``seed`` fixes the shuffling order (a seeded ``torch.Generator``). With ``num_workers > 0``
    the workers are started with ``spawn`` unless ``multiprocessing_context`` is given: Lance
    runs its own threads, which ``fork`` does not carry over safely. Further keyword arguments
    go to ``DataLoader`` as they are.

    >>> from dexcanvas_core import DexCanvasDataset, builtin_demonstration_path, make_dataloader
    >>> path = builtin_demonstration_path("cube2/tripod")
    >>> ds = DexCanvasDataset(path, objects=["cube2"], manipulation_types=["tripod"])
    >>> batch = next(iter(make_dataloader(ds, batch_size=1)))
    >>> tuple(batch["finger_pose"].shape), tuple(batch["attention_mask"].shape)
    ((1, 736, 45), (1, 736))
    """
    if isinstance(dataset, str | os.PathLike) or dataset is None:
        raise ValidationError(
            f"dataset must be a dataset object, got {dataset!r}; open a path with "
            "DexCanvasDataset(path)",
            field="dataset",
        )
    check_int("batch_size", batch_size, min=1)
    check_bool("shuffle", shuffle)
    check_int("num_workers", num_workers, min=0)
    if seed is not None:
        check_int("seed", seed, min=0)
    if seed is not None and "generator" not in kwargs:
        kwargs["generator"] = torch.Generator().manual_seed(int(seed))
    if num_workers > 0:
        kwargs.setdefault("multiprocessing_context", "spawn")
    kwargs.setdefault("collate_fn", collate_trajectories)
    return DataLoader(
        dataset, batch_size=batch_size, shuffle=shuffle, num_workers=num_workers, **kwargs
    )
