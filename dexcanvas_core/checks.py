"""Argument checks at the boundary of the public API and of the config dataclasses.

Each check returns the value normalised (``int``, ``float``, ``tuple``, ``ndarray``) or raises
one line naming the argument, the value given and what was expected, e.g.
``index must be an int >= 0, got '0' (str)``. The error class is the caller's package's:
:class:`~dexcanvas_core.errors.ValidationError` by default, ``retarget``'s own error when
``retarget`` calls with ``error=``.

>>> check_int("index", 3, min=0)
3
>>> check_str_seq("objects", ["cube2", "sphere1"])
('cube2', 'sphere1')
>>> try:
...     check_str_seq("objects", "cube2")
... except ValidationError as e:
...     print(e)
objects must be a list of strings, got 'cube2' (str); for one value write ['cube2']
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import os
import types
import typing
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from dexcanvas_core.errors import ValidationError

ErrorFactory = Callable[[str], Exception]


def _shown(value: object) -> str:
    """``repr`` of a value (cut to 60 characters) and its type name."""
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} ({value.dtype})"
    r = " ".join(repr(value).split())  # one line
    if len(r) > 60:
        r = r[:57] + "..."
    return f"{r} ({type(value).__name__})"


def _raise(error: ErrorFactory, name: str, value: object, expected: str, hint: str = ""):
    msg = f"{name} must be {expected}, got {_shown(value)}{hint}"
    if error is ValidationError:
        raise ValidationError(msg, field=name)
    raise error(msg)


def _bound(kind: str, min, max) -> str:
    if min is not None and max is not None:
        return f"{kind} in [{min}, {max}]"
    if min is not None:
        return f"{kind} >= {min}"
    if max is not None:
        return f"{kind} <= {max}"
    return kind


def check_int(
    name: str, value: object, *, min: int | None = None, max: int | None = None,
    error: ErrorFactory = ValidationError,
) -> int:  # fmt: skip
    """``value`` as an ``int`` (Python or NumPy integer; not ``bool``, not ``"3"``, not ``3.0``)
    within ``[min, max]`` (each bound optional)."""
    expected = _bound("an int", min, max)
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        _raise(error, name, value, expected)
    v = int(value)
    if (min is not None and v < min) or (max is not None and v > max):
        _raise(error, name, value, expected)
    return v


def check_float(
    name: str, value: object, *, min: float | None = None, max: float | None = None,
    positive: bool = False, error: ErrorFactory = ValidationError,
) -> float:  # fmt: skip
    """``value`` as a finite ``float`` (any real number but ``bool``; not ``"120"``), ``> 0``
    with ``positive``, within ``[min, max]`` (each bound optional)."""
    expected = _bound("a finite number > 0" if positive else "a finite number", min, max)
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        _raise(error, name, value, expected)
    v = float(value)
    if (
        not math.isfinite(v)
        or (positive and not v > 0)
        or (min is not None and v < min)
        or (max is not None and v > max)
    ):
        _raise(error, name, value, expected)
    return v


def check_number(name: str, value: object, *, error: ErrorFactory = ValidationError):
    """``value`` unchanged if it is a real number (not ``bool``, not ``"120"``); its range is
    the caller's to check."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        _raise(error, name, value, "a number")
    return value


def check_bool(name: str, value: object, *, error: ErrorFactory = ValidationError) -> bool:
    """``value`` if it is a ``bool`` (or NumPy bool)."""
    if not isinstance(value, bool | np.bool_):
        _raise(error, name, value, "True or False")
    return bool(value)


def check_str(
    name: str, value: object, *, optional: bool = False, choices: Sequence[str] | None = None,
    empty: bool = False, error: ErrorFactory = ValidationError,
) -> str | None:  # fmt: skip
    """``value`` if it is a ``str``, non-empty unless ``empty``, one of ``choices`` when given;
    ``None`` passes when ``optional``."""
    if value is None and optional:
        return None
    if choices is not None:
        if not isinstance(value, str) or value not in choices:
            _raise(error, name, value, "one of " + ", ".join(repr(c) for c in choices))
        return value
    if not isinstance(value, str) or not (value or empty):
        kind = "a str" if empty else "a non-empty str"
        _raise(error, name, value, kind + (" or None" if optional else ""))
    return value


def check_path(
    name: str, value: object, *, optional: bool = False, error: ErrorFactory = ValidationError
) -> Path | None:
    """``value`` (``str`` or ``os.PathLike``) as a ``Path``; ``None`` passes when
    ``optional``."""
    if value is None and optional:
        return None
    if not isinstance(value, str | os.PathLike) or not str(value):
        _raise(error, name, value, "a path (str or Path)" + (" or None" if optional else ""))
    return Path(value)


def check_str_seq(
    name: str, value: object, *, optional: bool = True, codes: bool = False,
    error: ErrorFactory = ValidationError,
) -> tuple | None:  # fmt: skip
    """``value`` (a list, tuple or other iterable of ``str``; with ``codes`` also ``int``) as a
    tuple; ``None`` passes when ``optional``. A single ``str`` is refused, not iterated letter
    by letter: the message says to write ``[value]``."""
    if value is None and optional:
        return None
    kinds = "strings or int codes" if codes else "strings"
    if isinstance(value, str | bytes):
        _raise(error, name, value, f"a list of {kinds}", f"; for one value write [{value!r}]")
    try:
        items = tuple(value)  # type: ignore[arg-type]
    except TypeError:
        _raise(error, name, value, f"a list of {kinds}")
    allowed = (str, numbers.Integral) if codes else (str,)
    for i, item in enumerate(items):
        if isinstance(item, bool) or not isinstance(item, allowed):
            _raise(error, f"{name}[{i}]", item, "a str" + (" or an int code" if codes else ""))
    return items


def check_array(
    name: str, value: object, shape: tuple[int | None, ...], *, finite: bool = True,
    min_len: int = 0, error: ErrorFactory = ValidationError,
) -> np.ndarray:  # fmt: skip
    """``value`` as a float64 array of ``shape`` (``None``: any length on that axis), at least
    ``min_len`` long on axis 0, all finite when ``finite``; the message names the first
    non-finite index."""
    want = "(" + ", ".join("T" if d is None else str(d) for d in shape) + ")"
    if isinstance(value, str | bytes) or value is None:
        _raise(error, name, value, f"a numeric array of shape {want}")
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        _raise(error, name, type(value).__name__, f"a numeric array of shape {want}")
    ok = a.ndim == len(shape) and all(
        d is None or d == n for d, n in zip(shape, a.shape, strict=True)
    )
    if not ok or (a.ndim and a.shape[0] < min_len):
        at_least = f" with at least {min_len} rows" if min_len else ""
        msg = f"{name} must be an array of shape {want}{at_least}, got shape {a.shape}"
        raise ValidationError(msg, field=name) if error is ValidationError else error(msg)
    if finite and not np.all(np.isfinite(a)):
        at = tuple(int(i) for i in np.argwhere(~np.isfinite(a))[0])
        msg = f"{name} must be finite, got {a[at]} at index {list(at)}"
        raise ValidationError(msg, field=name) if error is ValidationError else error(msg)
    return a


@functools.cache
def _field_types(cls: type) -> tuple[tuple[str, object], ...]:
    """``(field name, resolved annotation)`` of a dataclass; ``()`` when its annotations do
    not resolve (a name only imported under ``TYPE_CHECKING``)."""
    try:
        hints = typing.get_type_hints(cls)
    except (NameError, TypeError):  # unresolvable annotations: nothing to check by type
        return ()
    return tuple((f.name, hints[f.name]) for f in dataclasses.fields(cls) if f.name in hints)


def check_fields(obj: object, *, error: ErrorFactory = ValidationError) -> None:
    """Check the fields of dataclass ``obj`` whose annotation is ``int``, ``float``, ``bool``,
    ``str`` or a ``Literal`` of strings (each possibly ``| None``) against it: a ``'3'`` for an
    ``int`` is refused, naming ``Class.field``. Values are not changed; other annotations are
    not checked (``__post_init__`` checks ranges and the rest)."""
    owner = type(obj).__name__
    for name, hint in _field_types(type(obj)):
        value = getattr(obj, name)
        args = typing.get_args(hint)
        if typing.get_origin(hint) in (typing.Union, types.UnionType):
            if type(None) in args and value is None:
                continue
            inner = [a for a in args if a is not type(None)]
            if len(inner) != 1:
                continue
            hint = inner[0]
            args = typing.get_args(hint)
        label = f"{owner}.{name}"
        if hint is bool:
            check_bool(label, value, error=error)
        elif hint is int:
            check_int(label, value, error=error)
        elif hint is float:
            check_number(label, value, error=error)
        elif hint is str:
            check_str(label, value, empty=True, error=error)
        elif typing.get_origin(hint) is typing.Literal and all(isinstance(a, str) for a in args):
            check_str(label, value, choices=args, error=error)


def check_type(
    name: str, value: object, kinds: type | tuple[type, ...], *, hint: str = "",
    optional: bool = False, error: ErrorFactory = ValidationError,
) -> object:  # fmt: skip
    """``value`` unchanged if it is an instance of ``kinds`` (``None`` too when ``optional``);
    ``hint`` ends the message (how to make one, e.g. ``"; use get_hand('shadow')"``)."""
    if value is None and optional:
        return None
    if not isinstance(value, kinds):
        ks = kinds if isinstance(kinds, tuple) else (kinds,)
        expected = " or ".join(f"a {k.__name__}" for k in ks) + (" or None" if optional else "")
        _raise(error, name, value, expected, hint)
    return value
