"""Readers of captured sequences, by format name (``dexcanvas import FORMAT``).

``reader_for(name)`` gives a callable ``(path, *, models_dir) -> iterator of (name, arrays,
base_dir)``: ``arrays`` holds the ``mano-npz`` keys of one sequence
(``dexcanvas_core.capture.arrays``), ``base_dir`` is what relative mesh paths are relative to.

Formats:

* ``mano-npz`` — this toolkit's own: one ``.npz`` per sequence (:mod:`.mano_npz`).
* ``ho3d`` — HO-3D ``meta/NNNN.pkl`` sequences, and DexYCB exported to that layout
  (:mod:`.ho3d`).
* ``taco`` — TACO clips as released with GeneOH-Diffusion (:mod:`.taco`).
* ``dexycb`` — the original DexYCB release (``meta.yml`` + ``pose.npz``; :mod:`.dexycb`).

The published formats' readers are ``read_<fmt>(path, *, models_dir=None, fps=None, **opts) ->
list[dict]`` (one dict per sequence, source frame, SI units, plus ``hand_side`` and ``source``);
they do not mirror left hands (the import does, with ``--mirror-left``). Dataset pickles are read
with :func:`dexcanvas_core.safe_pickle.load_pickle` (numpy arrays and plain values only).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from dexcanvas_core.capture.formats.dexycb import read_dexycb
from dexcanvas_core.capture.formats.ho3d import read_ho3d
from dexcanvas_core.capture.formats.mano_npz import read_mano_npz
from dexcanvas_core.capture.formats.taco import read_taco
from dexcanvas_core.errors import UnknownNameError

Reader = Callable[..., list[dict[str, Any]]]

READERS: dict[str, Callable] = {
    "mano-npz": read_mano_npz,
    "ho3d": read_ho3d,
    "taco": read_taco,
    "dexycb": read_dexycb,
}
"""Reader of each format name."""


def sequence_name(source: str, fallback: str) -> str:
    """A short unique name of a sequence from its reader's ``source`` (``fmt:<path>[#a-b]``):
    the last two path parts and the frame range."""
    path = source.split(":", 1)[-1]
    path, _, frames = path.partition("#")
    parts = [p for p in Path(path).with_suffix("").parts if p not in ("/", "meta")][-2:]
    name = "_".join(parts) or fallback
    return f"{name}_{frames}" if frames else name


def _published(fn: Reader) -> Callable:
    def read(path: Path, *, models_dir: Path | None = None) -> Iterator[tuple]:
        for i, d in enumerate(fn(path, models_dir=models_dir)):
            yield sequence_name(str(d.get("source", "")), f"{path.stem}_{i}"), d, None

    read.__doc__ = fn.__doc__
    return read


def reader_for(name: str) -> Callable:
    """The reader of format ``name`` (yielding ``(name, arrays, base_dir)``).

    Raises:
        UnknownNameError: no such format (with the known ones).
    """
    key = str(name).strip().lower().replace("_", "-")
    if key not in READERS:
        raise UnknownNameError("capture format", name, list(READERS))
    fn = READERS[key]
    return fn if key == "mano-npz" else _published(fn)


__all__ = ["READERS", "Reader", "read_dexycb", "read_ho3d", "read_mano_npz", "read_taco",
           "reader_for"]  # fmt: skip
