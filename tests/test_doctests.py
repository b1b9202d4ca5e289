"""The docstring examples of the public API (``dexcanvas_core.__all__``, ``retarget.__all__``)
run and pass.

Every exported name carries an example in its own docstring, and every module defining one has
at least one example that doctest runs, so these tests cannot pass vacuously."""

from __future__ import annotations

import doctest
import importlib
import inspect

import pytest

import dexcanvas_core
import retarget

PACKAGES = (dexcanvas_core, retarget)
EXPORTS = [(pkg.__name__, n) for pkg in PACKAGES for n in pkg.__all__ if n not in ("__version__",)]
MODULES = sorted(
    {pkg.__name__ for pkg in PACKAGES}
    | {getattr(importlib.import_module(p), n).__module__ for p, n in EXPORTS}
)


@pytest.mark.parametrize(("package", "name"), EXPORTS, ids=[f"{p}.{n}" for p, n in EXPORTS])
def test_every_export_has_an_example(package, name):
    obj = getattr(importlib.import_module(package), name)
    assert ">>>" in (inspect.getdoc(obj) or ""), f"{package}.{name} has no example"


@pytest.mark.parametrize("module", MODULES)
def test_module_examples_pass(module):
    result = doctest.testmod(importlib.import_module(module), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0, f"{module} has no example"
    assert result.failed == 0, f"{result.failed} example(s) of {module} failed"
