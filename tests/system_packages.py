"""Tests that need a system package fail without it, naming the package and the fix.

``scripts/setup.sh`` installs the renderers' Debian packages (as root, with apt), so a missing
one is a broken setup, not a reason to skip: a skip would hide the gap. There is no opt-out;
a machine that cannot install them deselects those tests explicitly (``pytest --deselect`` or
``-k``), in the open."""

from __future__ import annotations

import functools

import pytest


def require(available: bool, reason: str) -> None:
    """Inside a test: continue if ``available``, else fail naming ``reason`` and the fix."""
    if not available:
        pytest.fail(f"{reason} — run scripts/setup.sh as root to install it", pytrace=False)


def requires(available: bool, reason: str):
    """Decorator form of :func:`require`."""

    def wrap(fn):
        @functools.wraps(fn)
        def inner(*args, **kwargs):
            require(available, reason)
            return fn(*args, **kwargs)

        return inner

    return wrap
