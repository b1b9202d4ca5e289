"""The docstring examples of the public API (``dexcanvas_core.__all__``) run and pass.

Every exported name carries an example, and every module defining one has at least one example
that doctest runs, so these tests cannot pass vacuously."""

from __future__ import annotations

import doctest
import importlib
import inspect

import pytest

import dexcanvas_core

EXPORTS = [n for n in dexcanvas_core.__all__ if n != "__version__"]
MODULES = sorted({"dexcanvas_core", *(dexcanvas_core._EXPORTS[n] for n in EXPORTS)})


@pytest.mark.parametrize("name", EXPORTS)
def test_every_export_has_an_example(name):
    assert ">>>" in (inspect.getdoc(getattr(dexcanvas_core, name)) or ""), name


@pytest.mark.parametrize("module", MODULES)
def test_module_examples_pass(module):
    result = doctest.testmod(importlib.import_module(module), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0, f"{module} has no example"
    assert result.failed == 0, f"{result.failed} example(s) of {module} failed"
