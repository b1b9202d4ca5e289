"""Stress motions: fast rigid moves of a held object reach the asked peaks and keep the grasp."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_capture_import import capture_arrays

from dexcanvas_core.capture.stress import StressMotion, hold_range, peaks, stress_arrays
from dexcanvas_core.errors import ValidationError
from dexcanvas_core.rotations import quat_wxyz_to_matrix


def _in_object_frame(a: dict) -> np.ndarray:
    """(T, 21, 3) the keypoints in the object's frame: constant while the grasp is kept."""
    R = quat_wxyz_to_matrix(a["object_quat_wxyz"])
    rel = np.asarray(a["keypoints"]) - np.asarray(a["object_pos"])[:, None]
    return np.einsum("tji,tkj->tki", R, rel)


def _slow(a: dict) -> dict:
    b = dict(a)
    b["fps"] = np.float64(120.0)
    return b


@pytest.mark.parametrize(
    "motion",
    [
        StressMotion("carry", peak_speed=1.5, distance_m=0.3),
        StressMotion("transport", peak_speed=2.5, distance_m=0.7, direction=(1.0, 0.0)),
        StressMotion("tool_use", peak_speed=4.0, angle_rad=math.radians(60), direction=(1, 0)),
    ],
)
def test_stress_motion_reaches_its_peak_and_keeps_the_grasp(motion):
    a = _slow(capture_arrays())
    h0, _ = hold_range(a)
    b, rep = stress_arrays(a, motion)
    n = len(b["wrist_pos"])
    assert n == len(a["wrist_pos"]) + rep["inserted_frames"]
    moved = peaks(b, slice(h0 + 3, h0 + rep["inserted_frames"]))  # past the lift's own end
    key = "peak_angular_speed_radps" if motion.kind == "tool_use" else "peak_speed_mps"
    assert moved[key] == pytest.approx(motion.peak_speed, rel=0.05)
    assert rep[key] >= moved[key]
    if motion.kind != "tool_use":  # a min-jerk move of D at peak v peaks at 5.774 v²/(1.875² D)
        want = 5.774 * motion.peak_speed**2 / (1.875**2 * motion.distance_m)
        assert moved["peak_accel_mps2"] == pytest.approx(want, rel=0.1)
    # The hand moves with the object: the grasp (keypoints in the object frame) is unchanged.
    rel_a, rel_b = _in_object_frame(a), _in_object_frame(b)
    held = rel_b[h0 : h0 + rep["inserted_frames"]]
    np.testing.assert_allclose(held, np.broadcast_to(rel_a[h0], held.shape), atol=1e-9)
    if motion.kind == "carry":  # it stays at the new place, put down there
        shift = b["object_pos"][-1] - a["object_pos"][-1]
        np.testing.assert_allclose(shift, [0.0, 0.3, 0.0], atol=1e-9)
    else:  # out and back: the rest is the original sequence
        np.testing.assert_allclose(b["object_pos"][-1], a["object_pos"][-1], atol=1e-9)
    assert b["contact_window"][1] == a["contact_window"][1] + rep["inserted_frames"]


def test_fast_lift_and_errors():
    a = _slow(capture_arrays())
    b, rep = stress_arrays(a, StressMotion("fast_lift", time_scale=3.0))
    assert rep["inserted_frames"] < 0
    assert peaks(b)["peak_speed_mps"] > 2.0 * peaks(a)["peak_speed_mps"]
    flat = dict(a, object_pos=np.repeat(a["object_pos"][:1], len(a["object_pos"]), axis=0))
    with pytest.raises(ValidationError, match="never lifts"):
        stress_arrays(flat, StressMotion("carry"))
    with pytest.raises(ValidationError, match="unknown stress motion"):
        StressMotion("juggle")
