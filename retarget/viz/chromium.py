"""Headless Chromium: screenshots and DOM dumps of local pages, offline.

Chromium draws meshcat's WebGL pages through SwiftShader (no GPU, no display). Every launch
gets a fresh profile directory, no network (a dead proxy and a resolver that resolves nothing,
so a page that tries to load a URL fails instead of waiting), and runs as a managed process
(``_process``): it and everything it starts end when the call returns, also on error or
timeout. The flags are the ones of ``docs/design.md`` (the machine it was built on).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from retarget.viz._process import run_process
from retarget.viz.errors import RendererUnavailableError, VizError

EXECUTABLES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
"""Names looked up on ``PATH`` (``$RETARGET_CHROMIUM`` names the executable explicitly)."""
PACKAGE_HINT = "apt-get install chromium"
VIRTUAL_TIME_BUDGET_MS = 8000
"""Virtual time [ms] a page gets to load and draw before the screenshot or DOM dump."""


def find_chromium() -> str | None:
    """Path of a Chromium executable, or None."""
    explicit = os.environ.get("RETARGET_CHROMIUM")
    if explicit:
        return shutil.which(explicit) or (explicit if os.access(explicit, os.X_OK) else None)
    for name in EXECUTABLES:
        path = shutil.which(name)
        if path:
            return path
    return None


def require_chromium() -> str:
    path = find_chromium()
    if path is None:
        raise RendererUnavailableError(
            f"headless Chromium not found (looked for {', '.join(EXECUTABLES)} on PATH and "
            f"$RETARGET_CHROMIUM); install it ({PACKAGE_HINT}) or use --renderer mujoco"
        )
    return path


def _flags(profile: str, width: int, height: int, budget_ms: int) -> list[str]:
    return [
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--enable-unsafe-swiftshader",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--disable-breakpad",
        "--no-first-run",
        "--no-default-browser-check",
        "--hide-scrollbars",
        "--mute-audio",
        "--proxy-server=127.0.0.1:9",  # nothing listens there: no page reaches the network
        "--host-resolver-rules=MAP * ~NOTFOUND",
        f"--user-data-dir={profile}",
        f"--window-size={width},{height}",
        f"--virtual-time-budget={budget_ms}",
    ]


def _run(
    args_tail: list[str], page: Path, *, width: int, height: int, timeout_s: float, budget_ms: int
) -> subprocess.CompletedProcess:
    exe = require_chromium()
    page = Path(page).resolve()
    if not page.is_file():
        raise VizError(f"no page to render at {page}")
    with tempfile.TemporaryDirectory(prefix="retarget-chromium-") as profile:
        args = [exe, *_flags(profile, width, height, budget_ms), *args_tail, page.as_uri()]
        try:
            return run_process(args, timeout_s=timeout_s)
        except subprocess.TimeoutExpired:
            raise VizError(
                f"headless Chromium did not finish {page.name} in {timeout_s:.0f} s"
            ) from None
        except OSError as e:
            raise RendererUnavailableError(f"cannot start {exe}: {e} ({PACKAGE_HINT})") from e


def screenshot(
    page: Path,
    png: Path,
    *,
    width: int = 800,
    height: int = 600,
    timeout_s: float = 120.0,
    budget_ms: int = VIRTUAL_TIME_BUDGET_MS,
) -> Path:
    """Render the local HTML file ``page`` to ``png`` (``width`` × ``height`` px)."""
    png = Path(png).resolve()
    png.unlink(missing_ok=True)
    r = _run(
        [f"--screenshot={png}"],
        page,
        width=width,
        height=height,
        timeout_s=timeout_s,
        budget_ms=budget_ms,
    )
    if r.returncode != 0 or not png.is_file() or png.stat().st_size == 0:
        tail = " | ".join((r.stderr or "").strip().splitlines()[-3:])
        raise VizError(f"headless Chromium wrote no screenshot (exit {r.returncode}): {tail}")
    return png


def dump_dom(
    page: Path,
    *,
    width: int = 1000,
    height: int = 800,
    timeout_s: float = 120.0,
    budget_ms: int = VIRTUAL_TIME_BUDGET_MS,
) -> str:
    """The DOM of the local HTML file ``page`` after its scripts ran (``--dump-dom``)."""
    r = _run(
        ["--dump-dom"], page, width=width, height=height, timeout_s=timeout_s, budget_ms=budget_ms
    )
    if r.returncode != 0:
        tail = " | ".join((r.stderr or "").strip().splitlines()[-3:])
        raise VizError(f"headless Chromium could not load {page} (exit {r.returncode}): {tail}")
    return r.stdout
