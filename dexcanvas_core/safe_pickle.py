"""Reading pickles from outside the toolkit without running their code.

A pickle can name any importable callable (``os.system``, ``builtins.eval``, …) and have it called
while it loads, so a pickle from a dataset download or a user must never go through a plain
``pickle.load``. :class:`RestrictedUnpickler` admits only what array data needs — numpy arrays,
dtypes and scalars, and a few harmless builtins — and refuses every other global with an error
naming it. :func:`load_pickle` wraps it with errors that name the file.

Subclasses widen the allowed set for a known file type (the MANO model files add chumpy
stand-ins and scipy sparse matrices, see ``dexcanvas_core.mano.model_file``).
"""

from __future__ import annotations

import importlib
import pickle
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from dexcanvas_core.errors import ValidationError


def _numpy_attr(candidates: tuple[str, ...], name: str) -> Any:
    """``name`` from the first importable module of ``candidates`` (numpy 2 renamed ``core``)."""
    for module in candidates:
        try:
            return getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError):
            continue
    raise AttributeError(f"none of {candidates} defines {name}")


_MULTIARRAY = ("numpy._core.multiarray", "numpy.core.multiarray")
_NUMERIC = ("numpy._core.numeric", "numpy.core.numeric")

ALLOWED_GLOBALS: dict[tuple[str, str], Callable[[], Any]] = {
    ("numpy", "ndarray"): lambda: np.ndarray,
    ("numpy", "dtype"): lambda: np.dtype,
    ("numpy.core.multiarray", "_reconstruct"): lambda: _numpy_attr(_MULTIARRAY, "_reconstruct"),
    ("numpy._core.multiarray", "_reconstruct"): lambda: _numpy_attr(_MULTIARRAY, "_reconstruct"),
    ("numpy.core.multiarray", "scalar"): lambda: _numpy_attr(_MULTIARRAY, "scalar"),
    ("numpy._core.multiarray", "scalar"): lambda: _numpy_attr(_MULTIARRAY, "scalar"),
    ("numpy.core.numeric", "_frombuffer"): lambda: _numpy_attr(_NUMERIC, "_frombuffer"),
    ("numpy._core.numeric", "_frombuffer"): lambda: _numpy_attr(_NUMERIC, "_frombuffer"),
    ("copyreg", "_reconstructor"): lambda: importlib.import_module("copyreg")._reconstructor,
    ("builtins", "object"): lambda: object,
    ("builtins", "set"): lambda: set,
    ("builtins", "frozenset"): lambda: frozenset,
    ("builtins", "slice"): lambda: slice,
    ("builtins", "complex"): lambda: complex,
    # Python 3 pickles of bytes at protocol < 3 (numpy array buffers) go through _codecs.encode.
    ("_codecs", "encode"): lambda: importlib.import_module("_codecs").encode,
}
"""``(module, name)`` globals a restricted pickle may reference, each with a factory that returns
the object: numpy array reconstruction, dtypes and scalars, and harmless builtins."""

PY2_MODULES = {"copy_reg": "copyreg", "__builtin__": "builtins"}
"""Python 2 module names (in pickles written by Python 2) and their Python 3 names."""


class RestrictedUnpickler(pickle.Unpickler):
    """An unpickler that loads numpy arrays, dtypes, scalars and plain Python containers only.

    Any other global (a class or function the pickle asks to import) raises
    :class:`pickle.UnpicklingError` naming it, before anything is called. ``what`` names the kind
    of file in that message.
    """

    what = "a data file"

    def find_class(self, module: str, name: str) -> Any:
        module = PY2_MODULES.get(module, module)
        factory = ALLOWED_GLOBALS.get((module, name))
        if factory is None:
            raise pickle.UnpicklingError(
                f"refusing to load global {module}.{name}: not expected in {self.what} "
                "(only numpy arrays and plain Python values are read from pickles)"
            )
        return factory()


def load_pickle(path: str | Path, *, what: str = "pickle") -> Any:
    """Read a pickle of numpy arrays and plain Python values with :class:`RestrictedUnpickler`.

    Python 2 pickles are read with ``encoding="latin1"`` (numpy's own advice for array buffers).

    Args:
        path: the file.
        what: what the file is, for messages (e.g. ``"HO-3D meta file"``).

    Raises:
        ValidationError: the file is missing, is not a pickle, or references a global that is
            not allowed (the message names the file and the global).
    """
    path = Path(path)
    try:
        with path.open("rb") as f:
            unpickler = RestrictedUnpickler(f, encoding="latin1")
            unpickler.what = what
            return unpickler.load()
    except FileNotFoundError as exc:
        raise ValidationError(f"{what} not found: {path}") from exc
    except pickle.UnpicklingError as exc:
        raise ValidationError(f"cannot read {what} {path}: {exc}") from exc
    except (EOFError, AttributeError, ImportError, TypeError, ValueError, IndexError) as exc:
        raise ValidationError(
            f"cannot read {what} {path}: not a readable pickle ({type(exc).__name__}: {exc})"
        ) from exc
