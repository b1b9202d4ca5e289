"""Value checks shared by the term configs' ``__post_init__`` (each error names the config,
the field, the value and what is allowed)."""

from __future__ import annotations

import typing

import numpy as np

from dexcanvas_core.checks import check_number
from retarget.errors import RetargetError


def check_choice(cfg, name: str, choices) -> None:
    """``cfg.name`` is one of ``choices`` (a ``Literal`` type or a sequence)."""
    allowed = typing.get_args(choices) or tuple(choices)
    value = getattr(cfg, name)
    if value not in allowed:
        raise RetargetError(
            f"{type(cfg).__name__}.{name}: unknown value {value!r}; "
            f"allowed: {', '.join(map(str, allowed))}"
        )


def check_range(
    cfg,
    name: str,
    *,
    positive: bool = False,
    optional: bool = False,
    upper: float | None = None,
    finite: bool = True,
    unit: str = "",
) -> None:
    """``cfg.name`` is ``>= 0`` (``> 0`` when ``positive``), finite unless not ``finite``, at
    most ``upper`` when given; ``None`` passes when ``optional``."""
    v = getattr(cfg, name)
    if v is None and optional:
        return
    if v is not None:  # a '1' or True: refused by type, before the comparisons below
        check_number(f"{type(cfg).__name__}.{name}", v, error=RetargetError)
    ok = v is not None and (np.isfinite(v) or not finite) and (v > 0 if positive else v >= 0)
    if ok and upper is not None:
        ok = v <= upper
    if not ok:
        want = ("finite and " if finite else "") + ("> 0" if positive else ">= 0")
        if upper is not None:
            want += f" and <= {upper}"
        if optional:
            want = f"None or {want}"
        raise RetargetError(
            f"{type(cfg).__name__}.{name} must be {want}{f' [{unit}]' if unit else ''}, got {v}"
        )
