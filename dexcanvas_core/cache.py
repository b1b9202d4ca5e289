"""Where generated data is cached: the built-in demonstrations, object collision shapes."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from platformdirs import user_cache_dir


def cache_dir() -> Path:
    """Directory for generated data (``$DEXCANVAS_CACHE_DIR`` overrides the platform default)."""
    env = os.environ.get("DEXCANVAS_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    return Path(user_cache_dir("dexcanvas-retarget"))


BUILTIN_PREFIX = "builtin-demos-"
"""Names of the built-in demonstrations' entries: the whole set (``builtin-demos-v<N>.lance``),
its report and lock, the per-pair caches (``builtin-demos-v<N>-pairs/``)."""

OBJECTS_DIR = "objects"
"""The object collision-shape cache (``objects.mesh.mesh_cache_dir``)."""


def entry_size(path: Path) -> int:
    """Bytes of a file, or of every file under a directory (symlinks not followed)."""
    if path.is_symlink() or path.is_file():
        return path.lstat().st_size
    return sum(p.lstat().st_size for p in path.rglob("*") if p.is_file() and not p.is_symlink())


def cache_entries(root: Path | None = None) -> list[tuple[Path, str, int]]:
    """What the cache directory holds: ``(path, kind, bytes)`` sorted by name; ``kind`` is
    ``built-in demonstrations``, ``object shapes``, ``tracebacks`` or ``other``."""
    root = cache_dir() if root is None else root
    if not root.is_dir():
        return []
    out = []
    for p in sorted(root.iterdir()):
        if p.name.startswith(BUILTIN_PREFIX):
            kind = "built-in demonstrations"
        elif p.name == OBJECTS_DIR:
            kind = "object shapes"
        elif p.name == "logs":
            kind = "tracebacks"
        else:
            kind = "other"
        out.append((p, kind, entry_size(p)))
    return out


def clearable_entries(root: Path | None = None) -> list[tuple[Path, str, int]]:
    """The entries :func:`clear_cache` removes: built-in demonstrations and object shapes."""
    kinds = ("built-in demonstrations", "object shapes")
    return [e for e in cache_entries(root) if e[1] in kinds]


def clear_cache(root: Path | None = None) -> list[Path]:
    """Remove the built-in demonstrations and object shapes from the cache (they are rebuilt
    on next use); tracebacks and other files stay. Returns the removed paths."""
    removed = []
    for path, _, _ in clearable_entries(root):
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink(missing_ok=True)
        removed.append(path)
    return removed
