import numpy as np
import pytest
import torch

from dexcanvas_core.mano import ManoLayer, mirror_axis_angle
from dexcanvas_core.mano.limits import (
    HIGH,
    LOW,
    anatomical_angles,
    joint_frames,
    limit_violation,
    pose_from_anatomical,
)


def test_frames_are_orthonormal_and_finger_flexion_is_plus_z():
    for side in ("right", "left"):
        F = joint_frames(side)
        np.testing.assert_allclose(
            np.einsum("jab,jcb->jac", F, F), np.tile(np.eye(3), (15, 1, 1)), atol=1e-12
        )
    F = joint_frames("right")
    for j in range(12):  # index, middle, pinky, ring
        assert F[j, 0] @ [0, 0, 1] > 0.75  # the little finger splays: its axis tilts


def test_flexion_moves_tip_to_the_palm_side():
    layer = ManoLayer("right")
    angles = np.zeros((15, 3))
    angles[1, 0] = 1.0  # index PIP flexion
    flexed = layer.forward_numpy(hand_pose=pose_from_anatomical(angles)[None]).keypoints[0]
    rest = layer.forward_numpy(hand_pose=np.zeros((1, 45))).keypoints[0]
    tip = 17  # index tip in MANO21
    assert flexed[tip, 1] < rest[tip, 1] - 0.01  # towards -y (volar)


def test_round_trip_and_torch_numpy_agree():
    rng = np.random.default_rng(0)
    a = rng.uniform(LOW, HIGH, size=(4, 15, 3))
    pose = pose_from_anatomical(a)
    np.testing.assert_allclose(anatomical_angles(pose), a, atol=1e-12)
    t = torch.tensor(pose, requires_grad=True)
    v = limit_violation(t * 3.0)
    np.testing.assert_allclose(v.detach().numpy(), limit_violation(pose * 3.0), atol=1e-12)
    v.sum().backward()
    assert t.grad is not None and torch.isfinite(t.grad).all()


def test_violation_is_zero_inside_and_measures_outside():
    a = np.zeros((15, 3))
    assert limit_violation(pose_from_anatomical(a)).max() == 0
    a[3, 0] = HIGH[3, 0] + 0.2  # middle MCP over-flexed by 0.2 rad
    v = limit_violation(pose_from_anatomical(a))
    assert v[3, 0] == pytest.approx(0.2) and v.sum() == pytest.approx(0.2)


def test_mirrored_left_pose_has_same_anatomical_angles():
    rng = np.random.default_rng(1)
    pose = pose_from_anatomical(rng.uniform(LOW, HIGH, size=(15, 3)))
    left = mirror_axis_angle(pose.reshape(15, 3)).reshape(45)
    np.testing.assert_allclose(anatomical_angles(left, "left"), anatomical_angles(pose), atol=1e-12)


def test_bad_shape():
    with pytest.raises(Exception, match=r"\(\.\.\., 45\)"):
        anatomical_angles(np.zeros(44))
