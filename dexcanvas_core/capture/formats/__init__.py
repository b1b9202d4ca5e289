"""Readers of captured sequences, by format name (``dexcanvas import FORMAT``).

Each reader takes a file or directory and yields ``(name, arrays, base_dir)`` per sequence:
``arrays`` holds the ``mano-npz`` keys (``dexcanvas_core.capture.arrays``), ``base_dir`` is what
relative mesh paths are relative to.
"""

from __future__ import annotations

from collections.abc import Callable

from dexcanvas_core.capture.formats.mano_npz import read_mano_npz
from dexcanvas_core.errors import UnknownNameError

READERS: dict[str, Callable] = {
    "mano-npz": read_mano_npz,
}


def reader_for(name: str) -> Callable:
    """The reader of format ``name``.

    Raises:
        UnknownNameError: no such format (with the known ones).
    """
    key = str(name).strip().lower().replace("_", "-")
    if key not in READERS:
        raise UnknownNameError("capture format", name, list(READERS))
    return READERS[key]
