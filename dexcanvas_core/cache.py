"""Where generated data is cached: the built-in demonstrations, object collision shapes."""

from __future__ import annotations

import os
from pathlib import Path

from platformdirs import user_cache_dir


def cache_dir() -> Path:
    """Directory for generated data (``$DEXCANVAS_CACHE_DIR`` overrides the platform default)."""
    env = os.environ.get("DEXCANVAS_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    return Path(user_cache_dir("dexcanvas-retarget"))
