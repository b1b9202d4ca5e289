"""Exception hierarchy of the robot side.

Every error names the bad value and, where there is a finite set of valid ones, lists them.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable


class RetargetError(Exception):
    """Base class of every error raised by ``retarget``.

    >>> from retarget import get_hand
    >>> try:
    ...     get_hand("shadwo")
    ... except RetargetError as e:
    ...     print(str(e).split(";")[0])
    unknown hand 'shadwo'
    """


class UnknownHandError(RetargetError, KeyError):
    """A robot hand name that is not registered; the message lists close matches and all hands."""

    def __init__(self, name: object, available: Iterable[str]):
        self.name = name
        self.available = sorted(available)
        close = difflib.get_close_matches(str(name).lower(), self.available, n=3, cutoff=0.5)
        hint = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
        super().__init__(f"unknown hand {name!r}{hint} (available: {', '.join(self.available)})")
        self.close_matches = close

    def __str__(self) -> str:  # KeyError quotes its message; keep it readable.
        return str(self.args[0])


class HandModelError(RetargetError):
    """A robot hand model that cannot be loaded, built or compiled (names the hand and cause)."""
