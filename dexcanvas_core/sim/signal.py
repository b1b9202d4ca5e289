"""Signal helpers shared by the force pipeline and the retargeting (in ``sim``: the force
benchmark's human-simulation cache digests this package's sources)."""

from __future__ import annotations

import numpy as np

CAPTURE_SMOOTH_S = 0.05
"""Bandwidth of the comparison with the captured motion: positions (for the acceleration) and
forces are both moving-averaged over this window [s] (mocap accelerations are meaningless at
higher frequencies). The force pipeline's Newton–Euler check and the retargeting's
band-limited force-profile correlation
(``retarget.force_scores.profile_band_frames``) both use it."""


def moving_average(x: np.ndarray, n: int) -> np.ndarray:
    """Centred moving average of each column of ``x`` (T, K) over ``n`` frames, the edges held
    (padded with the first and last rows); ``x`` itself when ``n <= 1``."""
    if n <= 1:
        return x
    k = np.ones(n) / n
    pad = np.pad(x, ((n // 2, n - 1 - n // 2), (0, 0)), mode="edge")
    return np.stack([np.convolve(pad[:, i], k, mode="valid") for i in range(x.shape[1])], axis=1)
