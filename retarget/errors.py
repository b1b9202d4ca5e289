"""Exception hierarchy of the robot side."""

from __future__ import annotations


class RetargetError(Exception):
    """Base class of every error raised by ``retarget``."""
