"""Readers of published hand-object datasets into mano-npz dicts (``dexcanvas import FORMAT``).

Each reader is ``read_<fmt>(path, *, models_dir=None, fps=None, **opts) -> list[dict]``: ``path``
is a sequence (file or folder) or a folder holding many, returned sorted; each dict holds the
mano-npz keys of one sequence (source frame, SI units) plus ``hand_side`` and ``source``, ready
for the capture core to validate and convert. Readers do not mirror left hands.

Formats:

* ``ho3d`` — HO-3D ``meta/NNNN.pkl`` sequences, and DexYCB exported to that layout
  (:mod:`.ho3d`).
* ``taco`` — TACO clips as released with GeneOH-Diffusion (:mod:`.taco`).
* ``dexycb`` — the original DexYCB release (``meta.yml`` + ``pose.npz``; :mod:`.dexycb`).

Bad input raises :class:`~dexcanvas_core.errors.ValidationError` naming the file, the key and
the fix. Dataset pickles are read with :func:`dexcanvas_core.safe_pickle.load_pickle` (numpy
arrays and plain values only).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from dexcanvas_core.capture.formats.dexycb import read_dexycb
from dexcanvas_core.capture.formats.ho3d import read_ho3d
from dexcanvas_core.capture.formats.taco import read_taco

Reader = Callable[..., list[dict[str, Any]]]

READERS: dict[str, Reader] = {
    "ho3d": read_ho3d,
    "taco": read_taco,
    "dexycb": read_dexycb,
}
"""Reader of each format name."""

__all__ = ["READERS", "Reader", "read_dexycb", "read_ho3d", "read_taco"]
