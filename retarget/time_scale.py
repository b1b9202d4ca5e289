"""Executing a demonstration slower than it was demonstrated (``retarget run --time-scale``):
its timestamps stretched, its frames unchanged."""

from __future__ import annotations

import dataclasses

import numpy as np

from retarget.errors import RetargetError

MAX_TIME_SCALE = 10.0
"""The slowest execution ``RunConfig.time_scale`` allows (a 6 s demonstration in a minute)."""


def check_time_scale(scale) -> float:
    """``scale`` (a number or its text) as a float if it is a finite number from 1 to
    ``MAX_TIME_SCALE``; else a one-line :class:`RetargetError` saying so."""
    try:
        s = float(scale)
    except (TypeError, ValueError):
        s = float("nan")
    if not (np.isfinite(s) and 1.0 <= s <= MAX_TIME_SCALE):
        raise RetargetError(
            f"--time-scale must be a finite number from 1 to {MAX_TIME_SCALE:g} (the "
            f"demonstration is executed that many times slower), got {str(scale)!r}"
        )
    return s


def time_scaled(traj, scale: float):
    """``traj`` executed ``scale`` (≥ 1) times slower: timestamps stretched about the first,
    frame rate divided by ``scale``, everything else (frames, poses, contact records, uuid)
    unchanged. ``scale`` 1: ``traj`` itself."""
    scale = check_time_scale(scale)
    if scale == 1.0:
        return traj
    t0 = traj.timestamp[0]
    return dataclasses.replace(
        traj, timestamp=t0 + scale * (traj.timestamp - t0), fps=traj.fps / scale
    )
