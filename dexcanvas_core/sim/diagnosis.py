"""Why a tracking rollout lost the object: wrist lag, slip, lost contact, or a knock.

At the failure frame ``f`` (the first with object error above the failure threshold) the rollout's
log is read back from the **onset** (the last frame before ``f`` with object error within
:data:`ONSET_M`) and the 0.3 s before ``f``:

* **wrist lag**: the object stayed where the hand holds it (its pose in the simulated wrist's
  frame drifted less than :data:`SLIP_M`), but the simulated wrist trailed its reference by more
  than :data:`WRIST_LAG_M` between 0.1 s before the onset and ``f``: the hand carried the
  object, too slowly;
* **lost contact**: no hand contact during the last :data:`CONTACT_GAP_S` before ``f`` while the
  reference still carries the object: the fingers opened or fell behind;
* **slip**: the hand touched the object but the object moved in the hand's frame by more than
  :data:`SLIP_M`: the grip did not hold against the motion;
* **knocked**: the reference's object has not left its first place (the demonstration does not
  carry it yet) and the simulated hand pushed it away;
* **other**: none of the above.

The numbers behind the call are returned with it, so a reader can judge it.
"""

from __future__ import annotations

import numpy as np

from dexcanvas_core.rotations import quat_wxyz_to_matrix

WINDOW_S = 0.3
"""Look-back before the failure frame [s] (slip)."""
ONSET_M = 0.01
"""The failure's onset is the last frame with object error within this [m]."""
LAG_LOOKBACK_S = 0.1
"""The wrist lag counts from this long [s] before the onset."""
WRIST_LAG_M = 0.02
"""A simulated wrist this far behind its reference [m] at the failure lags."""
SLIP_M = 0.015
"""The object moving this far in the wrist's frame over the window [m] slipped."""
CONTACT_GAP_S = 0.05
"""No hand contact for this long [s] before the failure: contact was lost."""
HELD_MOVED_M = 0.01
"""A reference object this far from its first position [m] is carried by the hand."""

REASONS = ("wrist lag", "lost contact", "slip", "knocked", "other")


def failure_diagnosis(
    failed_at: int | None,
    fps: float,
    wrist_sim: np.ndarray,
    wrist_ref: np.ndarray,
    wrist_rot_sim: np.ndarray,
    object_pos_sim: np.ndarray,
    object_pos_ref: np.ndarray,
    touching: np.ndarray,
) -> dict | None:
    """The diagnosis of a failed rollout (module docstring), or None when it did not fail.

    Args:
        failed_at: the failure frame (None: no failure).
        fps: frame rate [Hz].
        wrist_sim, wrist_ref: ``(T, 3)`` simulated and reference wrist positions [m].
        wrist_rot_sim: ``(T, 3, 3)`` simulated wrist orientation (world).
        object_pos_sim, object_pos_ref: ``(T, 3)`` [m].
        touching: ``(T,)`` bool, a hand part touches the object.

    Returns:
        ``{"reason", "frame", "time_s", "onset_frame", "wrist_lag_mm", "slip_mm",
        "last_contact_frame", "reference_held"}``.
    """
    if failed_at is None:
        return None
    T = len(object_pos_sim)
    f = int(min(failed_at, T - 1))
    w = max(1, round(WINDOW_S * fps))
    f0 = max(0, f - w)
    err = np.linalg.norm(object_pos_sim[: f + 1] - object_pos_ref[: f + 1], axis=1)
    calm = np.flatnonzero(err <= ONSET_M)
    onset = int(calm[-1]) if calm.size else 0
    k0 = max(0, onset - max(1, round(LAG_LOOKBACK_S * fps)))
    lag = float(np.linalg.norm(wrist_sim[k0 : f + 1] - wrist_ref[k0 : f + 1], axis=1).max())
    # The object's position in the simulated wrist's frame: its drift over the window.
    rel = np.einsum("tji,tj->ti", wrist_rot_sim[f0 : f + 1], object_pos_sim[f0 : f + 1]
                    - wrist_sim[f0 : f + 1])  # fmt: skip
    slip = float(np.linalg.norm(rel - rel[0], axis=1).max()) if len(rel) else 0.0
    touched = np.flatnonzero(touching[: f + 1])
    last_contact = int(touched[-1]) if touched.size else None
    gap = max(1, round(CONTACT_GAP_S * fps))
    held = bool(np.linalg.norm(object_pos_ref[f] - object_pos_ref[0]) > HELD_MOVED_M)
    if not held:
        reason = "knocked"
    elif last_contact is None or f - last_contact >= gap:
        reason = "lost contact"
    elif slip < SLIP_M and lag > WRIST_LAG_M:
        reason = "wrist lag"
    elif slip >= SLIP_M:
        reason = "slip"
    else:
        reason = "other"
    return {
        "reason": reason,
        "frame": f,
        "time_s": round(f / fps, 3),
        "onset_frame": onset,
        "wrist_lag_mm": round(1000 * lag, 1),
        "slip_mm": round(1000 * slip, 1),
        "last_contact_frame": last_contact,
        "reference_held": held,
    }


def wrist_rotations(hand_qpos: np.ndarray, R_base: np.ndarray) -> np.ndarray:
    """``(T, 3, 3)`` world wrist orientations from the MANO hand's qpos (slides, then intrinsic
    X-Y-Z hinges in ``R_base``, ``dexcanvas_core.sim.hand``)."""
    from scipy.spatial.transform import Rotation

    e = np.asarray(hand_qpos)[:, 3:6]
    return np.einsum("ij,tjk->tik", R_base, Rotation.from_euler("XYZ", e).as_matrix())


def quat_rotations(q: np.ndarray) -> np.ndarray:
    """``(T, 3, 3)`` from ``(T, 4)`` w-first quaternions."""
    return quat_wxyz_to_matrix(np.asarray(q, dtype=np.float64))
