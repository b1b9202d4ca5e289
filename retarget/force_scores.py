"""Force-profile scores: how a reproduction's per-finger contact-force magnitudes follow a
reference's (the human's), finger by finger and averaged.

Used by the run metrics (:mod:`retarget.metrics`), the force calibration
(:mod:`retarget.force_calibration`) and the force-preservation benchmark. The reasoning behind
``REACH_M``, ``LOAD_BEARING_SHARE`` and the band limit is in ``docs/method.md`` (force metrics).
"""

from __future__ import annotations

import numpy as np

from dexcanvas_core.sim.signal import CAPTURE_SMOOTH_S, moving_average
from retarget.errors import RetargetError


def _corr(a: np.ndarray, b: np.ndarray) -> float | None:
    """Pearson correlation; 0 when one side is constant and the other is not (a robot finger
    that never presses where the human's does reproduces none of its profile: leaving it out
    would flatter the mean), ``None`` when both are constant."""
    sa, sb = a.std() > 0, b.std() > 0
    if not (sa and sb):
        return 0.0 if sa or sb else None
    return float(np.corrcoef(a, b)[0, 1])


REACH_M = 0.005
"""A force-matched finger *reaches* the human's contact when the kinematic plan keeps it within
this distance [m] of the human's contact point (median over the frames the human finger
loads; ``finger_force_profiles``' ``contact_reach_m``). Past it, the robot's profile
correlation falls behind the human replay's (``docs/method.md``, force metrics)."""

LOAD_BEARING_SHARE = 0.1
"""A human finger is *load-bearing* when its mean force over the demonstration is at least this
share of the summed mean force of the fingers the robot maps (the ``*_load_bearing`` means of
:func:`correlation_means`). Lighter touches are lost when the object drifts from its planned
pose (``docs/method.md``, force metrics)."""


def profile_band_frames(fps: float) -> int:
    """Frames of the moving average that band-limits force profiles to the demonstration's
    bandwidth (``profile_correlation_smoothed``): the force pipeline's capture smoothing
    (``dexcanvas_core.sim.signal.CAPTURE_SMOOTH_S``, 50 ms; the captured motion the human's
    forces are simulated from says nothing faster, while re-simulated robots add contact
    chatter above it: ``docs/method.md``, force metrics). ``fps`` [Hz] must be > 0."""
    if not (np.isfinite(fps) and fps > 0):
        raise RetargetError(f"force profiles: fps must be > 0, got {fps}")
    return max(1, round(CAPTURE_SMOOTH_S * fps))


def finger_force_profiles(
    H: np.ndarray,
    R: np.ndarray,
    fingers,
    reach: np.ndarray | None = None,
    band_frames: int | None = None,
) -> dict:
    """Per finger, how the contact-force magnitudes ``R`` (T, F) [N] reproduce the reference
    ``H`` (T, F) [N] (columns named by ``fingers``): ``correlation`` over the frames where
    either exceeds 0.05 N, ``profile_correlation`` over every frame, ``relative_magnitude_error``
    (Σ|r − h| / Σh over the frames the reference carries force), both mean forces and the
    finger's ``load_share`` of the reference's summed mean force. A finger the reference never
    loads (0.05 N on at most 2 frames) has no profile to match: its three scores are ``None``;
    a reproduction that never presses where it does scores 0 (``_corr``).

    ``reach`` (T, F) [m], optional: the kinematic plan's distance from each robot finger to the
    human's contact point (``RobotTrajectory.contact_err``, NaN where inactive); each scored
    finger then also gets ``contact_reach_m``, its median over the frames the reference loads
    (``None`` when the plan has no contact target there). A finger the plan cannot bring onto
    the human's contact presses elsewhere or nowhere: ``REACH_M``.

    ``band_frames`` (:func:`profile_band_frames`), optional: each scored finger then also gets
    ``profile_correlation_smoothed``, the whole-clip correlation of both profiles
    moving-averaged over that many frames (the demonstration's bandwidth)."""
    H = np.asarray(H, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    if H.ndim != 2 or H.shape != R.shape or H.shape[1] != len(fingers):
        raise RetargetError(
            f"force profiles: reference {H.shape} and reproduction {R.shape} must both be "
            f"(frames, {len(fingers)} fingers)"
        )
    if reach is not None and np.shape(reach) != H.shape:
        raise RetargetError(f"force profiles: reach {np.shape(reach)} must be {H.shape}")
    if band_frames is not None and not (
        isinstance(band_frames, int | np.integer) and band_frames >= 1
    ):
        raise RetargetError(f"force profiles: band_frames must be an int >= 1, got {band_frames}")
    if band_frames is not None:
        Hs, Rs = moving_average(H, band_frames), moving_average(R, band_frames)
    per = {}
    total = float(H.mean(axis=0).sum())
    for i, f in enumerate(fingers):
        h, r = H[:, i], R[:, i]
        hm = float(h.mean())
        on = (h > 0.05) | (r > 0.05)
        held = h > 0.05  # where the reference finger carries force
        used = held.sum() > 2
        rel = float(np.abs(r[held] - h[held]).sum() / h[held].sum()) if used else None
        per[f] = {
            "correlation": _corr(h[on], r[on]) if used else None,
            "profile_correlation": _corr(h, r) if used else None,
            "relative_magnitude_error": rel,
            "human_force_mean_n": hm,
            "robot_force_mean_n": float(r.mean()),
            "load_share": hm / total if total > 0 else None,
        }
        if band_frames is not None:
            per[f]["profile_correlation_smoothed"] = _corr(Hs[:, i], Rs[:, i]) if used else None
        if reach is not None and used:
            d = np.asarray(reach, dtype=np.float64)[held, i]
            d = d[np.isfinite(d)]
            per[f]["contact_reach_m"] = float(np.median(d)) if d.size else None
    return per


def correlation_means(per: dict) -> dict:
    """The means of :func:`finger_force_profiles`' correlations over the scored fingers
    (all, and the load-bearing ones: ``LOAD_BEARING_SHARE``); ``None`` where none is scored.
    When the fingers carry ``profile_correlation_smoothed``, also its mean
    (``force_profile_correlation_mean_smoothed``).
    When the fingers carry ``contact_reach_m``, also the whole-clip mean over those whose plan
    reaches the human's contact (``REACH_M``; ``force_profile_correlation_mean_reached``) and
    how many of the scored fingers do (``fingers_reached``, of ``fingers_scored``)."""

    def mean_of(key: str, keep=lambda v: True) -> float | None:
        vals = [v[key] for v in per.values() if v.get(key) is not None and keep(v)]
        return float(np.mean(vals)) if vals else None

    def load_bearing(v: dict) -> bool:
        return v["load_share"] >= LOAD_BEARING_SHARE

    out = {
        "force_correlation_mean": mean_of("correlation"),
        "force_profile_correlation_mean": mean_of("profile_correlation"),
        "force_correlation_mean_load_bearing": mean_of("correlation", load_bearing),
        "force_profile_correlation_mean_load_bearing": mean_of("profile_correlation", load_bearing),
    }
    scored = [v for v in per.values() if v["profile_correlation"] is not None]
    if any("profile_correlation_smoothed" in v for v in scored):
        out["force_profile_correlation_mean_smoothed"] = mean_of("profile_correlation_smoothed")
    if any("contact_reach_m" in v for v in scored):
        reached = [v for v in scored if reaches(v)]
        out["force_profile_correlation_mean_reached"] = mean_of("profile_correlation", reaches)
        out["fingers_reached"] = len(reached)
        out["fingers_scored"] = len(scored)
    return out


def reaches(finger: dict) -> bool:
    """Whether a scored finger's plan reaches the human's contact (``contact_reach_m`` ≤
    ``REACH_M``; a finger without one does not)."""
    d = finger.get("contact_reach_m")
    return d is not None and d <= REACH_M
