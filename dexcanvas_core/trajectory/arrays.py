"""Array checks shared by the trajectory's parts: float32 normalisation with a shape check,
finiteness, axis-angle magnitudes. Each raises ``ValidationError`` naming the field."""

from __future__ import annotations

import numpy as np

from dexcanvas_core.errors import ValidationError


def f32(x, shape: tuple[int | None, ...], name: str) -> np.ndarray:
    """Normalise an array-like to float32 and check its shape (``None`` = any length)."""
    try:
        a = np.asarray(x, dtype=np.float32)
    except (TypeError, ValueError) as e:
        raise ValidationError(f"{name}: cannot convert to a float array ({e})", field=name) from e
    ok = a.ndim == len(shape) and all(
        s is None or s == d for s, d in zip(shape, a.shape, strict=False)
    )
    if not ok:
        want = "(" + ", ".join("T" if s is None else str(s) for s in shape) + ")"
        raise ValidationError(f"{name} must have shape {want}, got {a.shape}", field=name)
    return a


def check_finite(a: np.ndarray, where: str, name: str) -> None:
    """Raise when ``a`` holds NaN or inf (the message names the first bad index)."""
    bad = ~np.isfinite(a)
    if np.any(bad):
        first = np.argwhere(bad)[0]
        raise ValidationError(
            f"{where} contains NaN or inf (first at index {tuple(int(i) for i in first)})",
            field=name,
        )


def check_aa(aa: np.ndarray, limit: float, where: str) -> None:
    """Raise when an axis-angle norm exceeds ``limit`` [rad] (degrees stored as radians?)."""
    norms = np.linalg.norm(aa, axis=-1)
    if np.any(norms > limit + 1e-4):
        first = np.argwhere(norms > limit + 1e-4)[0]
        raise ValidationError(
            f"{where}: axis-angle norm {norms[tuple(first)]:.3f} rad at index "
            f"{tuple(int(i) for i in first)} exceeds {limit:.3f} rad (degrees stored as radians?)",
            field=where.rsplit(".", 1)[-1],
        )
