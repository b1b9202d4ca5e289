"""Tests that need a system package fail without it, naming the package and the fix.

``scripts/setup.sh`` installs the renderers' Debian packages (as root, with apt), so a missing
one is a broken setup, not a reason to skip: a skip would hide the gap. A machine that cannot
install them may opt out with ``DEXCANVAS_ALLOW_MISSING_SYSTEM_PACKAGES=1`` (those tests then
skip, each naming its package); CI (``CI=true``) never does."""

from __future__ import annotations

import os

import pytest

OPT_OUT = "DEXCANVAS_ALLOW_MISSING_SYSTEM_PACKAGES"


def _env_true(name: str) -> bool:
    return os.environ.get(name, "").lower() in ("1", "true", "yes")


def in_ci() -> bool:
    return _env_true("CI")


def require(available: bool, reason: str) -> None:
    """Inside a test: continue if ``available``; else fail (skip only with the opt-out set,
    outside CI)."""
    if available:
        return
    if in_ci() or not _env_true(OPT_OUT):
        pytest.fail(
            f"{reason} — run scripts/setup.sh as root to install it (or, on a machine that "
            f"cannot, set {OPT_OUT}=1 to skip these tests)",
            pytrace=False,
        )
    pytest.skip(f"{reason} ({OPT_OUT} is set)")


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
