"""Errors of the visualisation layer (part of the ``RetargetError`` hierarchy)."""

from __future__ import annotations

from retarget.errors import RetargetError


class VizError(RetargetError):
    """Bad input to a picture, plot or report: a missing run file, a frame out of range, …"""


class RendererUnavailableError(VizError):
    """No usable renderer; the message names the system package(s) to install."""


def require(*modules: str) -> None:
    """Raise :class:`VizError` naming the extra to install when a module is missing."""
    import importlib.util

    missing = [m for m in modules if importlib.util.find_spec(m) is None]
    if missing:
        raise VizError(
            f"{', '.join(missing)} not installed; install the viz extra: "
            "pip install 'dexcanvas-retarget[viz]'"
        )
