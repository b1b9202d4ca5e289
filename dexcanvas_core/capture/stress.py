"""Real-like fast motions made from a demonstration: the stress cases of ``benchmarks/real_motion``.

Real wrists carry objects at up to 2.5–3 m/s and 15 m/s², several times faster than the built-in
demonstrations. Each stress case takes a demonstration as ``mano-npz`` arrays (z up; e.g.
:func:`~dexcanvas_core.capture.export.trajectory_to_arrays`), finds its **hold** (the frames
where the object is held at the top of its lift), inserts frames there and moves the hand and the
object together, rigidly (the grasp is kept), along a minimum-jerk profile:

* ``carry``: a horizontal move of ``distance_m`` that stays: the object is put down at a new place.
* ``transport``: in the air, out by ``distance_m`` and back (a pause of 0.1 s between the legs).
* ``tool_use``: a turn of ``angle_rad`` about a horizontal axis through the object's centre and
  back (pouring, swinging a tool).
* ``fast_lift``: the lift itself ``time_scale`` times faster (frames dropped; nothing inserted).

A minimum-jerk move of length ``D`` over ``τ`` seconds peaks at ``1.875 D/τ`` [m/s] and
``5.774 D/τ²`` [m/s²]; ``τ`` is chosen from the peak speed asked for. The peaks actually reached
(finite differences of the wrist at the frame rate) are returned with the arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.rotations import (
    aa_to_matrix,
    matrix_to_aa,
    matrix_to_quat_wxyz,
    quat_wxyz_to_matrix,
)

STRESS_KINDS: tuple[str, ...] = ("carry", "transport", "tool_use", "fast_lift")

HOLD_BAND_M = 0.005
"""Frames whose object height is within this of its highest [m] are the hold."""


@dataclass(frozen=True)
class StressMotion:
    """One stress case (module docstring)."""

    kind: str
    peak_speed: float = 2.5
    """[m/s] (``carry``, ``transport``) or [rad/s] (``tool_use``)."""
    distance_m: float = 0.5
    """Length of the move [m] (``carry``, ``transport``)."""
    direction: tuple[float, float] = (0.0, 1.0)
    """Horizontal direction of the move (normalised)."""
    angle_rad: float = 1.0
    """Turn of ``tool_use`` [rad]."""
    time_scale: float = 3.0
    """Speed-up of ``fast_lift``."""

    def __post_init__(self) -> None:
        if self.kind not in STRESS_KINDS:
            raise ValidationError(
                f"unknown stress motion {self.kind!r}; one of {', '.join(STRESS_KINDS)}"
            )
        for name in ("peak_speed", "distance_m", "angle_rad", "time_scale"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValidationError(f"stress motion {name} must be > 0, got {v!r}")

    @property
    def name(self) -> str:
        if self.kind in ("carry", "transport"):
            return f"{self.kind}-{self.distance_m:g}m-{self.peak_speed:g}mps"
        if self.kind == "tool_use":
            return f"tool_use-{math.degrees(self.angle_rad):.0f}deg-{self.peak_speed:g}radps"
        return f"fast_lift-x{self.time_scale:g}"


def min_jerk(n: int) -> np.ndarray:
    """(n,) the minimum-jerk profile from 0 to 1 sampled at ``s = (i + 1) / n``."""
    s = np.arange(1, n + 1, dtype=np.float64) / n
    return 10 * s**3 - 15 * s**4 + 6 * s**5


def hold_range(arrays: dict) -> tuple[int, int]:
    """(first, last) frame of the hold: the object within :data:`HOLD_BAND_M` of its top height,
    after it left the table by more than 2 cm.

    Raises:
        ValidationError: the object is never lifted.
    """
    z = np.asarray(arrays["object_pos"])[:, 2]
    top = z.max()
    if top - z[0] < 0.02:
        raise ValidationError("the demonstration never lifts its object: no hold to move in")
    held = np.flatnonzero(z >= top - HOLD_BAND_M)
    first = int(held[0])
    last = first
    while last + 1 < len(z) and z[last + 1] >= top - HOLD_BAND_M:
        last += 1
    return first, last


_PER_FRAME = ("global_orient", "hand_pose", "wrist_pos", "keypoints", "object_pos",
              "object_quat_wxyz")  # fmt: skip


def _insert(arrays: dict, at: int, n: int) -> dict:
    """``n`` copies of frame ``at`` inserted before it (a still hold)."""
    out = dict(arrays)
    for k in _PER_FRAME:
        if k in arrays:
            a = np.asarray(arrays[k])
            out[k] = np.concatenate([a[:at], np.repeat(a[at : at + 1], n, axis=0), a[at:]])
    if "contact_window" in arrays:
        w = np.asarray(arrays["contact_window"]).copy()
        w[w >= at] += n
        w[1] = max(w[1], at + n)
        out["contact_window"] = w
    return out


def _apply(arrays: dict, frames: np.ndarray, R: np.ndarray, p: np.ndarray, centre: np.ndarray):
    """Move the hand and the object of ``frames`` rigidly: x → R (x − c) + c + p (per frame)."""
    out = dict(arrays)

    def pts(a):  # (F, ..., 3)
        a = np.asarray(a, dtype=np.float64).copy()
        rel = a[frames] - centre
        a[frames] = (
            np.einsum("fij,f...j->f...i", R, rel)
            + centre
            + p.reshape((len(frames),) + (1,) * (rel.ndim - 2) + (3,))
        )
        return a

    out["wrist_pos"] = pts(arrays["wrist_pos"])
    out["object_pos"] = pts(arrays["object_pos"])
    if "keypoints" in arrays:
        out["keypoints"] = pts(arrays["keypoints"])
    go = np.asarray(arrays["global_orient"], dtype=np.float64).copy()
    go[frames] = matrix_to_aa(R @ aa_to_matrix(go[frames]))
    out["global_orient"] = go
    q = np.asarray(arrays["object_quat_wxyz"], dtype=np.float64).copy()
    q[frames] = matrix_to_quat_wxyz(R @ quat_wxyz_to_matrix(q[frames]))
    out["object_quat_wxyz"] = q
    return out


def peaks(arrays: dict, frames: slice | None = None) -> dict:
    """Peak wrist speed [m/s] and acceleration [m/s²], peak angular speed [rad/s] (over
    ``frames``, default all)."""
    fps = float(arrays["fps"])
    sel = frames if frames is not None else slice(None)
    w = np.asarray(arrays["wrist_pos"], dtype=np.float64)[sel]
    v = np.gradient(w, axis=0) * fps
    a = np.gradient(v, axis=0) * fps
    R = aa_to_matrix(np.asarray(arrays["global_orient"], dtype=np.float64)[sel])
    dR = np.einsum("tji,tjk->tik", R[:-1], R[1:])
    ang = np.arccos(np.clip((np.trace(dR, axis1=1, axis2=2) - 1) / 2, -1, 1)) * fps
    return {
        "peak_speed_mps": float(np.linalg.norm(v, axis=1).max()),
        "peak_accel_mps2": float(np.linalg.norm(a, axis=1).max()),
        "peak_angular_speed_radps": float(ang.max()) if ang.size else 0.0,
    }


def stress_arrays(arrays: dict, motion: StressMotion) -> tuple[dict, dict]:
    """The stress case ``motion`` of a demonstration's ``mano-npz`` arrays (module docstring).

    Returns:
        ``(arrays, report)``: the new sequence, and its hold, inserted frames and :func:`peaks`.
    """
    fps = float(arrays["fps"])
    h0, h1 = hold_range(arrays)
    centre = np.asarray(arrays["object_pos"], dtype=np.float64)[h0]
    out = dict(arrays)
    inserted = 0
    if motion.kind in ("carry", "transport"):
        d = np.array([*motion.direction, 0.0], dtype=np.float64)
        d /= np.linalg.norm(d)
        tau = 1.875 * motion.distance_m / motion.peak_speed
        n = max(2, round(tau * fps))
        prof = min_jerk(n)
        if motion.kind == "carry":
            out = _insert(out, h0, n)
            T = len(out["wrist_pos"])
            shift = np.concatenate([prof, np.ones(T - h0 - n)])
            frames = np.arange(h0, T)
        else:
            pause = max(1, round(0.1 * fps))
            out = _insert(out, h0, 2 * n + pause)
            shift = np.concatenate([prof, np.ones(pause), 1.0 - prof])
            frames = np.arange(h0, h0 + len(shift))
        inserted = len(frames) if motion.kind == "transport" else n
        p = motion.distance_m * shift[:, None] * d
        R = np.repeat(np.eye(3)[None], len(frames), axis=0)
        out = _apply(out, frames, R, p, centre)
    elif motion.kind == "tool_use":
        tau = 1.875 * motion.angle_rad / motion.peak_speed
        n = max(2, round(tau * fps))
        prof = min_jerk(n)
        pause = max(1, round(0.1 * fps))
        ang = motion.angle_rad * np.concatenate([prof, np.ones(pause), 1.0 - prof])
        out = _insert(out, h0, len(ang))
        frames = np.arange(h0, h0 + len(ang))
        axis = np.array([*motion.direction, 0.0], dtype=np.float64)
        axis /= np.linalg.norm(axis)
        R = aa_to_matrix(ang[:, None] * axis)
        out = _apply(out, frames, R, np.zeros((len(frames), 3)), centre)
        inserted = len(frames)
    else:  # fast_lift: keep every time_scale-th frame of the lift
        start = int(np.flatnonzero(np.linalg.norm(
            np.asarray(arrays["object_pos"]) - np.asarray(arrays["object_pos"])[0], axis=1
        ) > 0.002)[0])  # fmt: skip
        lift = np.arange(start, h0)
        keep = lift[:: max(1, round(motion.time_scale))]
        idx = np.concatenate([np.arange(start), keep, np.arange(h0, len(arrays["wrist_pos"]))])
        for k in _PER_FRAME:
            if k in arrays:
                out[k] = np.asarray(arrays[k])[idx]
        inserted = -(len(lift) - len(keep))
        if "contact_window" in arrays:
            w = np.asarray(arrays["contact_window"]).copy()
            w[w >= h0] += inserted
            out["contact_window"] = np.clip(w, 0, len(idx) - 1)
    report = {"case": motion.name, "hold": [h0, h1], "inserted_frames": inserted, **peaks(out)}
    return out, report
