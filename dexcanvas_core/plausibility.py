"""Plausibility checks on input data: units, human motion limits, outliers, frame rates.

The shape and finiteness checks of :meth:`Trajectory.validate` accept any finite numbers; these
checks refuse numbers no human demonstration produces, which almost always mean a unit mistake
(millimetres read as metres), a corrupt frame, or a wrong frame rate. Each failure is an
:class:`ImplausibleDataError` naming the frame (when one frame is to blame), the field, what was
measured, and the fix.

Limits, and why (``LIMITS``):

* **hand length** — wrist → middle MCP → PIP → DIP → fingertip along the skeleton (independent
  of the pose), median over frames: accepted within [0.08, 0.40] m. Adult hands measure
  0.16–0.22 m on this chain (MANO's mean hand: 0.18 m); the band leaves room for children,
  scaled skeletons (synthesis scales hands by ±5 %) and fitting noise. The same hand in
  millimetres measures ~180 (×1000), in centimetres ~18 (×100): the message says which.
* **room** — any position farther than 10 m from the origin: no capture volume is that large.
* **wrist speed** — 10 m/s: the fastest human arm motions (throwing, boxing punches) peak at
  about 10–14 m/s at the wrist, manipulation stays far below (our real-motion benchmark's stress
  motions peak at 2.5 m/s): four times the fastest manipulation we measured.
* **wrist acceleration** — 300 m/s²: after a 20 ms centred moving average, which tames
  marker and fitting noise (1 mm of white noise then reads at most ~16 m/s² at 120 Hz, ~170
  m/s² at 1 kHz); ballistic arm motions reach ~100–200 m/s², the real-motion benchmark's stress
  motions 15 m/s² and the built-in demonstrations 4 m/s² — twenty times the stress motions.
  A wider window would make this check redundant with the speed limit (a window ``w`` bounds
  the acceleration by ``2 · speed / w``).
* **outlier frame** — a frame whose wrist is more than ``max(0.1 m, 10 m/s / fps)`` from both of
  its neighbours while the neighbours are within a fifth of that distance of each other (a
  one-frame spike, e.g. the hand at 1e6 m): named as such before the speed check blames it.
* **frame rate** — 1 to 10 000 Hz: video runs at 15–60 Hz, optical mocap at 60–1000 Hz, gloves
  and IMUs at up to a few kHz.

Real but unusual data (a fast throw, a giant robot teleoperated with human keypoints) can go on
with ``--allow-implausible`` on the command line, or :func:`allowing_implausible` in Python:
every finding is then logged as a warning instead of raised.
"""

from __future__ import annotations

import argparse
import logging
import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.keypoints import MANO21

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Limits:
    """Bounds of plausible human demonstration data (module docstring: the reasons)."""

    hand_length_m: tuple[float, float] = (0.08, 0.40)
    """Wrist-to-middle-fingertip chain length [m], median over frames."""
    room_m: float = 10.0
    """Largest distance of any position from the world origin [m]."""
    wrist_speed_m_s: float = 10.0
    """Largest wrist speed [m/s] after smoothing."""
    wrist_accel_m_s2: float = 300.0
    """Largest wrist acceleration [m/s²] after smoothing."""
    smoothing_s: float = 0.02
    """Width of the centred moving average applied before speeds and accelerations [s]."""
    outlier_floor_m: float = 0.1
    """Smallest jump [m] from both neighbours that makes a frame an outlier."""
    fps_hz: tuple[float, float] = (1.0, 10_000.0)
    """Accepted frame rates [Hz]."""


LIMITS = Limits()
"""The limits used by every check."""

ALLOW_FLAG = "--allow-implausible"
_MIDDLE_CHAIN = [MANO21.index(k) for k in ("wrist", "middle1", "middle2", "middle3", "middle_tip")]
_UNIT_GUESSES = (("millimetres", 1e-3, "mm"), ("centimetres", 1e-2, "cm"))
_warned: set[str] = set()
_allow = [False]  # process-wide, not a ContextVar: datasets are written from Lance's threads


class ImplausibleDataError(ValidationError):
    """Data with valid shapes and finite values that no human demonstration produces.

    ``field`` names the array, ``frame`` the frame to blame (``None``: the whole sequence),
    ``fix`` what to do about it; the message holds all three.
    """

    def __init__(self, message: str, *, field: str, fix: str, frame: int | None = None):
        self.frame = frame
        self.fix = fix
        self.finding = f"{message}; {fix}"
        super().__init__(
            f"{message}; {fix} (or pass {ALLOW_FLAG} if the data is real)", field=field
        )


@contextmanager
def allowing_implausible(allow: bool = True) -> Iterator[None]:
    """Within the block, plausibility findings are logged as warnings instead of raised
    (``allow=False``: raised, the default). The setting is process-wide (it holds in the
    threads that write datasets, and in worker processes forked inside the block)."""
    before = _allow[0]
    _allow[0] = bool(allow)
    try:
        yield
    finally:
        _allow[0] = before


def implausible_allowed() -> bool:
    """Whether findings are currently only warned about (:func:`allowing_implausible`)."""
    return _allow[0]


def add_allow_implausible(parser: argparse.ArgumentParser) -> None:
    """Add ``--allow-implausible`` to a sub-command's parser."""
    parser.add_argument(
        ALLOW_FLAG,
        action="store_true",
        help="go on (with a warning) when the input fails the plausibility checks "
        "(units, human speed limits, outlier frames, frame rate)",
    )


def report(error: ImplausibleDataError) -> None:
    """Raise ``error``, or log it as a warning under :func:`allowing_implausible`."""
    if _allow[0]:
        if error.finding not in _warned:  # data read twice is reported once
            _warned.add(error.finding)
            log.warning("implausible data accepted (%s): %s", ALLOW_FLAG, error.finding)
        return
    raise error


# -- single checks --------------------------------------------------------------------------------


def check_fps(fps: object, what: str = "--fps") -> float:
    """``fps`` as a float when it is a number within ``LIMITS.fps_hz``; a one-line
    :class:`ValidationError` otherwise (NaN, ≤ 0, text, absurd rates). Out-of-range but
    positive rates are implausible (:func:`report`)."""
    if isinstance(fps, bool) or not isinstance(fps, int | float | np.integer | np.floating):
        raise ValidationError(
            f"{what} must be a number [Hz], got {type(fps).__name__} {fps!r}", field="fps"
        )
    x = float(fps)
    if not (math.isfinite(x) and x > 0):
        raise ValidationError(
            f"{what} must be a finite frame rate > 0 [Hz], got {fps!r}", field="fps"
        )
    lo, hi = LIMITS.fps_hz
    if not lo <= x <= hi:
        report(
            ImplausibleDataError(
                f"{what} {x:g} Hz is outside {lo:g}..{hi:g} Hz",
                field="fps",
                fix="give the capture's frame rate in Hz (video 15-60, mocap 60-1000)",
            )
        )
    return x


def hand_length(keypoints: np.ndarray) -> float:
    """Median over frames of the wrist → middle fingertip chain length [input units] of
    ``(T, 21, 3)`` MANO21 keypoints."""
    chain = np.asarray(keypoints, dtype=np.float64)[:, _MIDDLE_CHAIN]
    return float(np.median(np.linalg.norm(np.diff(chain, axis=1), axis=-1).sum(axis=1)))


def check_hand_scale(
    keypoints: np.ndarray, where: str, field: str, units: str | None = None
) -> None:
    """Refuse ``(T, 21, 3)`` MANO21 keypoints [m] whose hand length is no human's: all at one
    point (zeros), or the size of a hand in mm/cm read as m, or in m read as mm (``units``: the
    unit the caller converted from, to name the fix)."""
    length = hand_length(keypoints)
    lo, hi = LIMITS.hand_length_m
    if lo <= length <= hi:
        return
    measured = f"{where}: {field}: the hand is {length:.4g} m long (wrist to middle fingertip)"
    if length < 1e-6:
        report(
            ImplausibleDataError(
                f"{measured}: all keypoints at one point (all zero?)",
                field=field,
                fix="check the file holds keypoints, not an empty or zero-filled array",
            )
        )
        return
    for name, scale, unit in _UNIT_GUESSES:
        if lo <= length * scale <= hi:
            fix = (
                f"pass --units {unit}"
                if units is not None
                else f"divide the positions by {round(1 / scale)}"
            )
            report(
                ImplausibleDataError(
                    f"{measured}, a human hand is {lo:g}-{hi:g} m: looks like {name}",
                    field=field,
                    fix=fix,
                )
            )
            return
    if units not in (None, "m"):
        for factor in (1e3, 1e2):
            if lo <= length * factor <= hi:
                report(
                    ImplausibleDataError(
                        f"{measured} after converting from {units}, a human hand is "
                        f"{lo:g}-{hi:g} m: the file looks like it is already in metres",
                        field=field,
                        fix=f"drop --units {units} (or pass --units m)",
                    )
                )
                return
    report(
        ImplausibleDataError(
            f"{measured}, a human hand is {lo:g}-{hi:g} m",
            field=field,
            fix="check the units and the keypoint order",
        )
    )


def check_room(positions: np.ndarray, where: str, field: str) -> None:
    """Refuse positions (T, ..., 3) [m] farther than ``LIMITS.room_m`` from the origin, naming
    the first such frame."""
    p = np.asarray(positions, dtype=np.float64)
    dist = np.linalg.norm(p.reshape(p.shape[0], -1, 3), axis=-1).max(axis=1)
    far = dist > LIMITS.room_m
    if far.any():
        f = int(np.argmax(far))
        report(
            ImplausibleDataError(
                f"{where}: {field} at frame {f} is {dist[f]:.4g} m from the origin, beyond any "
                f"room ({LIMITS.room_m:g} m)",
                field=field,
                frame=f,
                fix=f"drop or interpolate frame {f}, or check the units (mm read as m?)",
            )
        )


def _outlier_frames(p: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Frames (indices into ``p``) far from both neighbours whose neighbours agree, and the
    smaller of their two jumps [m]."""
    if p.shape[0] < 3:
        return np.zeros(0, int), np.zeros(0)
    d_prev = np.linalg.norm(p[1:-1] - p[:-2], axis=-1)
    d_next = np.linalg.norm(p[1:-1] - p[2:], axis=-1)
    d_nb = np.linalg.norm(p[2:] - p[:-2], axis=-1)
    jump = np.minimum(d_prev, d_next)
    threshold = max(LIMITS.outlier_floor_m, LIMITS.wrist_speed_m_s / fps)
    bad = (jump > threshold) & (d_nb < 0.2 * jump)
    idx = np.flatnonzero(bad)
    return idx + 1, jump[idx]


def check_outliers(positions: np.ndarray, fps: float, where: str, field: str) -> None:
    """Refuse a track (T, 3) [m] with a frame far from both its neighbours (see module doc)."""
    frames, jumps = _outlier_frames(np.asarray(positions, dtype=np.float64), fps)
    if frames.size:
        f = int(frames[0])
        more = f" (and {frames.size - 1} more)" if frames.size > 1 else ""
        report(
            ImplausibleDataError(
                f"{where}: {field} at frame {f} is {jumps[0]:.4g} m from both neighbouring "
                f"frames{more}: a one-frame outlier",
                field=field,
                frame=f,
                fix=f"drop or interpolate frame {f}",
            )
        )


def smooth(positions: np.ndarray, fps: float) -> np.ndarray:
    """Centred moving average over ``LIMITS.smoothing_s`` (an odd number of frames ≥ 1; the
    ends use the available frames)."""
    p = np.asarray(positions, dtype=np.float64)
    half = max(0, round(LIMITS.smoothing_s * fps) // 2)
    if half == 0 or p.shape[0] < 3:
        return p
    c = np.cumsum(np.concatenate([np.zeros((1, *p.shape[1:])), p]), axis=0)
    i = np.arange(p.shape[0])
    lo = np.clip(i - half, 0, p.shape[0])
    hi = np.clip(i + half + 1, 0, p.shape[0])
    return (c[hi] - c[lo]) / (hi - lo)[:, None]


def check_motion(positions: np.ndarray, fps: float, where: str, field: str) -> None:
    """Refuse a wrist track (T, 3) [m] at ``fps`` [Hz] faster than ``LIMITS.wrist_speed_m_s``
    or accelerating beyond ``LIMITS.wrist_accel_m_s2`` after smoothing, naming the frame."""
    p = smooth(positions, fps)
    if p.shape[0] < 3:
        return
    v = np.gradient(p, 1.0 / fps, axis=0)
    speed = np.linalg.norm(v, axis=-1)
    f = int(np.argmax(speed))
    if speed[f] > LIMITS.wrist_speed_m_s:
        report(
            ImplausibleDataError(
                f"{where}: {field} moves at {speed[f]:.4g} m/s at frame {f}, beyond a human "
                f"wrist ({LIMITS.wrist_speed_m_s:g} m/s)",
                field=field,
                frame=f,
                fix="check --fps and the units, or drop the frames around it",
            )
        )
        return
    acc = np.linalg.norm(np.gradient(v, 1.0 / fps, axis=0), axis=-1)
    f = int(np.argmax(acc))
    if acc[f] > LIMITS.wrist_accel_m_s2:
        report(
            ImplausibleDataError(
                f"{where}: {field} accelerates at {acc[f]:.4g} m/s² at frame {f}, beyond a human "
                f"wrist ({LIMITS.wrist_accel_m_s2:g} m/s²)",
                field=field,
                frame=f,
                fix="check --fps and the units, or drop the frames around it",
            )
        )


def check_keypoint_sequence(
    keypoints: np.ndarray, fps: float, where: str, units: str | None = None
) -> None:
    """Every check on a ``(T, 21, 3)`` MANO21 keypoint sequence [m] at ``fps`` [Hz]: hand
    scale, room, outliers, wrist speed and acceleration."""
    kp = np.asarray(keypoints, dtype=np.float64)
    check_hand_scale(kp, where, "keypoints", units)
    check_outliers(kp[:, 0], fps, where, "keypoints (wrist)")
    check_room(kp, where, "keypoints")
    check_motion(kp[:, 0], fps, where, "keypoints (wrist)")


def check_trajectory(traj) -> None:
    """Every plausibility check on a :class:`~dexcanvas_core.trajectory.Trajectory` whose
    shapes and values are already valid: frame rate, each hand's scale, room, outliers and
    wrist motion, each object's room and outliers."""
    where = f"trajectory {traj.uuid!r}"
    check_fps(traj.fps, f"{where}: data_fps")
    for h in traj.hands:
        name = f"hands[{h.name}]"
        wrist = h.joint_pos[:, 0] if h.joint_pos is not None else h.global_pos
        wrist_field = (
            f"{name}.mano_joint_pos (wrist)"
            if h.joint_pos is not None
            else (f"{name}.mano_global_pos")
        )
        if h.joint_pos is not None:
            check_hand_scale(h.joint_pos, where, f"{name}.mano_joint_pos")
        check_outliers(wrist, traj.fps, where, wrist_field)
        if h.joint_pos is not None:
            check_room(h.joint_pos, where, f"{name}.mano_joint_pos")
        check_room(h.global_pos, where, f"{name}.mano_global_pos")
        check_motion(wrist, traj.fps, where, wrist_field)
    for o in traj.objects:
        check_outliers(o.pos, traj.fps, where, f"objects[{o.name}].pos")
        check_room(o.pos, where, f"objects[{o.name}].pos")
