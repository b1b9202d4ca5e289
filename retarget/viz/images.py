"""Checks and captions on rendered PNGs."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dexcanvas_core.safe_io import atomic_path
from retarget.viz import style

MIN_CONTENT_FRACTION = 0.01
"""A still with less than this fraction of non-background pixels counts as blank."""


def content_fraction(png: Path, background=style.BACKGROUND_RGB, tol: int = 12) -> float:
    """Fraction of pixels farther than ``tol`` (0–255, any channel) from the background."""
    from PIL import Image

    img = np.asarray(Image.open(png).convert("RGB"), dtype=np.int16)
    bg = np.round(255 * np.asarray(background)).astype(np.int16)
    return float((np.abs(img - bg).max(axis=2) > tol).mean())


def caption(png: Path, lines: list[str]) -> None:
    """Write ``lines`` in the top-left corner of ``png`` (in place)."""
    from PIL import Image, ImageDraw, ImageFont

    img = Image.open(png).convert("RGB")
    draw = ImageDraw.Draw(img)
    size = max(11, img.height // 40)
    try:
        font = ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1 has one fixed-size default font
        font = ImageFont.load_default()
    y = 6
    for line in lines:
        draw.text((8, y), line, fill=(30, 30, 30), font=font)
        y += int(size * 1.35)
    with atomic_path(png) as tmp:
        img.save(tmp, format="PNG")
