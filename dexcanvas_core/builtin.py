"""The built-in dataset that ``DexCanvasDataset()`` uses when no path is given.

It is generated once, deterministically, and cached in the user cache directory
(``$DEXCANVAS_CACHE_DIR`` or the platform's cache dir, e.g. ``~/.cache/dexcanvas-retarget``).
The content comes from :mod:`dexcanvas_core.demos`: the built-in subset of feasible
(object, manipulation type) pairs (``demos.builtin_pairs``), one demonstration each, operators
cycling, seed 0, every demonstration passing the plausibility checks. The build report is
written next to the dataset (``<dataset>.report.json``). No network is needed.
"""

from __future__ import annotations

import contextlib
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


def builtin_dataset_name() -> str:
    """File name of the cached built-in dataset (changes with the generator's version)."""
    from dexcanvas_core.demos import DEMOS_VERSION

    return f"builtin-demos-v{DEMOS_VERSION}.lance"


@contextlib.contextmanager
def _build_lock(path: Path):
    """Serialise concurrent first builds (POSIX advisory lock; no-op elsewhere)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    lock = path.with_name(path.name + ".lock")
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield
        return
    with open(lock, "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def default_dataset_path() -> Path:
    """Path of the built-in dataset, building it on first use (under a minute)."""
    path = cache_dir() / builtin_dataset_name()
    if (path / "_versions").is_dir():
        return path
    with _build_lock(path):
        if not (path / "_versions").is_dir():  # another process may have built it meanwhile
            from dexcanvas_core.demos import build_builtin

            log.info("building the built-in dataset at %s", path)
            build_builtin(path)
    return path
