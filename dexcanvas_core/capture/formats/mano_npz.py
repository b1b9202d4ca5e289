"""``mano-npz``: one sequence per ``.npz`` file, the keys of ``dexcanvas_core.capture.arrays``."""

from __future__ import annotations

import zipfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from dexcanvas_core.errors import ValidationError


def read_mano_npz(path: Path, *, models_dir: Path | None = None) -> Iterator[tuple]:
    """``(name, arrays, base_dir)`` of the ``.npz`` file ``path``, or of every ``*.npz`` in the
    directory ``path`` (sorted). ``models_dir`` is not used (the files carry their meshes).

    Arrays are read without pickles (``allow_pickle=False``): strings must be stored as numpy
    unicode arrays (``np.savez(..., object_name="mug")`` does that).
    """
    files = sorted(path.glob("*.npz")) if path.is_dir() else [path]
    for f in files:
        try:
            with np.load(f, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
        except ValueError as e:
            raise ValidationError(
                f"{f}: holds pickled (object) arrays, which are not read; store strings as "
                f"numpy strings (np.savez(..., object_name='mug')) ({e})",
                field="path",
            ) from e
        except (OSError, zipfile.BadZipFile, EOFError) as e:
            raise ValidationError(
                f"{f}: not a readable .npz file ({type(e).__name__}: {e})", field="path"
            ) from e
        yield f.stem, arrays, f.parent
