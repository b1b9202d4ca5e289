"""The built-in dataset that ``DexCanvasDataset()`` uses when no path is given.

It is generated once, deterministically, and cached in the user cache directory
(``$DEXCANVAS_CACHE_DIR`` or the platform's cache dir, e.g. ``~/.cache/dexcanvas-retarget``).
The content comes from :mod:`dexcanvas_core.example` (scripted demonstrations).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

log = logging.getLogger(__name__)


def cache_dir() -> Path:
    """Directory for generated data (``$DEXCANVAS_CACHE_DIR`` overrides the platform default)."""
    env = os.environ.get("DEXCANVAS_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    from platformdirs import user_cache_dir

    return Path(user_cache_dir("dexcanvas-retarget"))


def default_dataset_path() -> Path:
    """Path of the built-in dataset, building it on first use (a few seconds)."""
    from dexcanvas_core.example import EXAMPLE_VERSION, build_example_dataset

    path = cache_dir() / f"builtin-example-v{EXAMPLE_VERSION}.lance"
    if not (path / "_versions").is_dir():
        log.info("building the built-in dataset at %s", path)
        build_example_dataset(path, seed=0, overwrite=True)
    return path
