"""Gaps in marker trajectories: find them, fill the short ones, low-pass the rest.

A *gap* is a run of frames in which a marker is missing (NaN). Gaps of at most ``max_gap``
frames with valid samples on both sides are filled by a cubic spline through the marker's valid
samples (the usual mocap "spline fill"; at 100–120 Hz a 10-frame gap is under 0.1 s). Longer
gaps, and gaps touching the start or end of the capture, are left missing and reported as
*long*. Every filled sample is reported as *interpolated*.

``lowpass`` applies a zero-phase Butterworth filter (``filtfilt``, 2nd order run forwards and
backwards: 4th-order magnitude response, no lag) to every contiguous run of valid samples —
the standard treatment of optical marker data before inverse kinematics (cut-offs of 6–15 Hz are
common for hand and body motion). Runs too short for the filter's padding are left as they are.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import butter, filtfilt

from dexcanvas_core.errors import ValidationError


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` of the runs of ``True`` in a 1-D bool array (stop exclusive)."""
    m = np.asarray(mask, dtype=bool).astype(np.int8)
    if m.size == 0:
        return []
    d = np.diff(np.concatenate([[0], m, [0]]))
    starts = np.flatnonzero(d == 1)
    stops = np.flatnonzero(d == -1)
    return list(zip(starts.tolist(), stops.tolist(), strict=True))


@dataclass
class GapFill:
    """Result of :func:`fill_gaps`."""

    positions: np.ndarray
    """(T, M, 3) with the short gaps filled (long gaps still NaN)."""
    interpolated: np.ndarray
    """(T, M) bool: filled samples."""
    long_gap: np.ndarray
    """(T, M) bool: samples inside a gap that was too long (or open-ended) to fill."""


def fill_gaps(positions: np.ndarray, max_gap: int, times: np.ndarray | None = None) -> GapFill:
    """Fill gaps of at most ``max_gap`` frames bounded by valid samples (see module docs).

    Args:
        positions: ``(T, M, 3)`` marker trajectories, NaN where missing.
        max_gap: longest gap [frames] to fill; 0 fills nothing.
        times: ``(T,)`` sample times [s] (default: frame indices).
    """
    X = np.array(positions, dtype=np.float64, copy=True)
    if X.ndim != 3 or X.shape[2] != 3:
        raise ValidationError(f"positions must be (T, M, 3), got {X.shape}", field="positions")
    if max_gap < 0:
        raise ValidationError(f"max_gap must be >= 0 frames, got {max_gap}", field="max_gap")
    T, M, _ = X.shape
    t = np.arange(T, dtype=np.float64) if times is None else np.asarray(times, dtype=np.float64)
    interp = np.zeros((T, M), bool)
    long_gap = np.zeros((T, M), bool)
    valid = np.isfinite(X).all(-1)
    for k in range(M):
        miss = ~valid[:, k]
        if not miss.any():
            continue
        vi = np.flatnonzero(valid[:, k])
        fill_frames: list[np.ndarray] = []
        for a, b in runs(miss):
            bounded = a > 0 and b < T
            if bounded and b - a <= max_gap and vi.size >= 2:
                fill_frames.append(np.arange(a, b))
            else:
                long_gap[a:b, k] = True
        if fill_frames:
            f = np.concatenate(fill_frames)
            if vi.size >= 4:
                X[f, k] = CubicSpline(t[vi], X[vi, k], axis=0)(t[f])
            else:  # too few samples for a cubic: linear
                for d in range(3):
                    X[f, k, d] = np.interp(t[f], t[vi], X[vi, k, d])
            interp[f, k] = True
    return GapFill(X, interp, long_gap)


def lowpass(positions: np.ndarray, fps: float, cutoff_hz: float | None) -> np.ndarray:
    """Zero-phase low-pass of every contiguous valid run of every marker (NaN kept).

    ``cutoff_hz`` of ``None`` or 0, or one at or above the Nyquist frequency, returns a copy.
    """
    X = np.array(positions, dtype=np.float64, copy=True)
    if not cutoff_hz or cutoff_hz <= 0:
        return X
    nyq = 0.5 * fps
    if cutoff_hz >= 0.95 * nyq:
        return X
    b, a = butter(2, cutoff_hz / nyq)
    pad = 3 * max(len(a), len(b))
    M = X.shape[1]
    valid = np.isfinite(X).all(-1)
    for k in range(M):
        for s, e in runs(valid[:, k]):
            if e - s > pad:
                X[s:e, k] = filtfilt(b, a, X[s:e, k], axis=0)
    return X
