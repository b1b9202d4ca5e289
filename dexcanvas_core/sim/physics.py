"""Object physics shared by the force pipeline and the retargeting: gravity, the captured
object's acceleration and the share of its weight the hand carries.

No MuJoCo here: the robot side (``retarget``) uses these on the reference motion alone.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.sim.signal import CAPTURE_SMOOTH_S, moving_average
from dexcanvas_core.table import DEFAULT_TABLE, Table

GRAVITY = 9.81
"""Standard gravity used throughout [m/s²] (the object weight is ``m · GRAVITY``)."""


def smoothed(x: np.ndarray, fps: float, window_s: float = CAPTURE_SMOOTH_S) -> np.ndarray:
    """``x`` (T, K) moving-averaged over ``window_s`` [s] (default ``CAPTURE_SMOOTH_S``): the
    bandwidth at which captured motion and forces are compared."""
    return moving_average(x, max(1, round(window_s * fps)))


def capture_acceleration(pos: np.ndarray, fps: float) -> np.ndarray:
    """``(T, 3)`` captured object acceleration [m/s²]: central differences of the smoothed
    position track."""
    pos = smoothed(pos, fps)
    acc = np.zeros_like(pos)
    acc[1:-1] = (pos[2:] - 2 * pos[1:-1] + pos[:-2]) * fps**2
    return acc


def carried_load(
    geometry,
    object_pos: np.ndarray,
    object_quat: np.ndarray,
    fps: float,
    *,
    clear_m: tuple[float, float] = (0.001, 0.004),
    lead_s: float = 0.2,
    table: Table = DEFAULT_TABLE,
) -> np.ndarray:
    """``(T,)`` share ``λ`` ∈ [0, 1] of the object's weight the hand carries in the reference.

    ``λ`` ramps from 0 to 1 as the reference object's lowest point rises from ``clear_m[0]`` to
    ``clear_m[1]`` above the table top (1 where the object's origin is beyond the table's
    edges: nothing else holds it there), is then brought forward by ``lead_s`` (the largest
    value over the next ``lead_s`` seconds) and ramped in over ``lead_s / 2`` (moving average),
    so that the grip is built up before lift-off and released after set-down.

    Args:
        geometry: the object's ``ObjectGeometry`` (``lowest_z``).
        object_pos, object_quat: ``(T, 3)`` [m], ``(T, 4)`` (w, x, y, z) reference object pose.
        fps: frame rate [Hz]; clear_m: clearance ramp [m]; lead_s: anticipation [s].
        table: the table (default :data:`~dexcanvas_core.table.DEFAULT_TABLE`).
    """
    p = np.asarray(object_pos, dtype=np.float64)
    q = np.asarray(object_quat, dtype=np.float64)
    lo, hi = clear_m
    if not (0.0 <= lo < hi) or lead_s < 0.0:
        raise ValidationError(
            f"clearance ramp must satisfy 0 ≤ lo < hi and lead ≥ 0, got {clear_m}, {lead_s}",
            field="clear_m",
        )
    R = Rotation.from_quat(q, scalar_first=True).as_matrix()
    low = np.asarray(geometry.lowest_z(R, p), dtype=np.float64)
    h = table.height_above(np.concatenate([p[..., :2], low[..., None]], axis=-1))
    lam = np.clip((h - lo) / (hi - lo), 0.0, 1.0)
    n = round(lead_s * fps)
    T = lam.shape[0]
    if n > 0 and T > 1:
        pad = np.concatenate([lam, np.full(n, lam[-1])])
        lam = np.max(np.lib.stride_tricks.sliding_window_view(pad, n + 1)[:T], axis=1)
        k = max(1, n // 2)
        if k > 1:  # ramp in: a moving average ending at each frame (never later than lam)
            pad = np.concatenate([np.full(k - 1, lam[0]), lam])
            lam = np.convolve(pad, np.ones(k) / k, mode="valid")
    return np.clip(lam, 0.0, 1.0)
