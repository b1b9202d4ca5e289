"""Tests that need a system package: skipped on a developer machine without it, a failure in CI.

``scripts/setup.sh`` installs the renderers' Debian packages on CI machines, so a missing one
there is a broken setup, not a reason to skip (a skip would hide the gap)."""

from __future__ import annotations

import os

import pytest


def in_ci() -> bool:
    return os.environ.get("CI", "").lower() in ("1", "true", "yes")


def require(available: bool, reason: str) -> None:
    """Inside a test: continue if ``available``; else fail in CI, skip elsewhere."""
    if available:
        return
    if in_ci():
        pytest.fail(f"{reason} — scripts/setup.sh should have installed it", pytrace=False)
    pytest.skip(reason)


def requires(available: bool, reason: str):
    """Decorator form of :func:`require`."""

    def wrap(fn):
        import functools

        @functools.wraps(fn)
        def inner(*args, **kwargs):
            require(available, reason)
            return fn(*args, **kwargs)

        return inner

    return wrap
