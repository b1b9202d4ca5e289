"""The wrist offset (``HandModel.wrist_offset``) and its calibration (``calibrate-wrist``)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from robot_poses import coupled, human_from_robot_poses
from scipy.spatial.transform import Rotation

from dexcanvas_core.example import example_trajectories
from dexcanvas_core.rotations import aa_to_matrix
from retarget.calibration import calibrate_wrist, calibration_demos, wrist_in_target_frame
from retarget.cli import main
from retarget.config import RetargetConfig, WristConfig
from retarget.errors import HandModelError, RetargetError
from retarget.hands import WristOffset, available_hands, get_hand
from retarget.retargeter import Retargeter

KNOWN = WristOffset(rotvec=(0.10, -0.25, 0.30), translation=(0.012, -0.020, 0.015))


def test_offset_apply_and_its_inverse_compose_poses():
    rng = np.random.default_rng(0)
    R_h = Rotation.random(5, random_state=1).as_matrix()
    p_h = rng.normal(size=(5, 3))
    R, p = KNOWN.apply(R_h, p_h)
    # R* = R_h exp(rotvec): the offset is a rotation in the human wrist frame, not the world's.
    np.testing.assert_allclose(R, R_h @ Rotation.from_rotvec(KNOWN.rotvec).as_matrix())
    np.testing.assert_allclose(p, p_h + np.einsum("tij,j->ti", R_h, KNOWN.translation))
    # The robot wrist seen from the human wrist frame is the offset itself, on every frame.
    np.testing.assert_allclose(np.einsum("tji,tjk->tik", R_h, R), np.tile(KNOWN.R, (5, 1, 1)))
    R_back, p_back = KNOWN.human_wrist(R, p)
    np.testing.assert_allclose(R_back, R_h, atol=1e-12)
    np.testing.assert_allclose(p_back, p_h, atol=1e-12)


@pytest.mark.parametrize(
    "kwargs", [{"rotvec": (0.0, np.nan, 0.0)}, {"translation": (0.0, 0.0)}, {"rotvec": [[0.0]]}]
)
def test_offset_rejects_malformed_values(kwargs):
    with pytest.raises(HandModelError, match="WristOffset"):
        WristOffset(**kwargs)


def test_calibrated_hands_have_offsets_the_gripper_none():
    """Every dexterous hand carries a measured offset (the gripper's calibration is ill-posed:
    see retarget/hands/README.md); none is implausibly large."""
    for name in available_hands():
        off = get_hand(name).wrist_offset
        if name == "panda":
            assert off is None
            continue
        assert off is not None and "calibrate-wrist" in off.source, name
        assert (
            np.degrees(np.linalg.norm(off.rotvec)) < 30 and np.linalg.norm(off.translation) < 0.05
        )


def test_targets_follow_the_offset_and_the_switch_turns_it_off():
    traj = next(t for t in example_trajectories(seed=0) if t.scene == "cube2").slice(100, 130)
    hand = dataclasses.replace(get_hand("shadow"), wrist_offset=KNOWN)
    on = Retargeter(hand, None, RetargetConfig())  # on by default
    off = Retargeter(hand, None, RetargetConfig(wrist=WristConfig(use_offset=False)))
    t_on, t_off = on.human_targets(traj), off.human_targets(traj)
    R_h = aa_to_matrix(traj.hand.global_rot_aa.astype(np.float64))
    np.testing.assert_allclose(t_off["wrist_R"], R_h)
    np.testing.assert_allclose(t_off["wrist_p"], traj.hand.joint_pos[:, 0], atol=1e-6)
    R, p = KNOWN.apply(t_off["wrist_R"], t_off["wrist_p"])
    np.testing.assert_allclose(t_on["wrist_R"], R)
    np.testing.assert_allclose(t_on["wrist_p"], p)
    # Only the wrist moves: keypoint and vector targets are the human's either way.
    np.testing.assert_allclose(t_on["keypoints"], t_off["keypoints"])
    np.testing.assert_allclose(t_on["vectors"], t_off["vectors"])


def _robot_motion(rt: Retargeter, rng, frames: int = 120) -> np.ndarray:
    """A smooth robot motion (1 s) between two random reachable poses (joint ranges,
    couplings). A hand's own wrist joints (Shadow's WRJ1/WRJ0) stay at their default: with the
    floating wrist they are redundant for the finger keypoints, and the posture term holds them
    there in the calibration's solve."""
    m = rt.scene.model
    wrist_joints = np.array([m.joint(j).name.startswith("WRJ") for j in range(6, rt.nq)])
    ends = []
    while len(ends) < 2:
        q = rt.q_default.copy()
        q[:3] = rng.uniform(-0.1, 0.1, 3)
        q[3:6] = rng.uniform(-0.6, 0.6, 3)
        lo, hi = rt.lower[6:], rt.upper[6:]
        fin = np.isfinite(lo) & np.isfinite(hi) & ~wrist_joints
        q[6:][fin] = lo[fin] + rng.uniform(0.2, 0.6, fin.sum()) * (hi - lo)[fin]
        q = coupled(rt.scene.model, q)
        if rt.self_distance_query.min_distance(q) > 0.002:
            ends.append(q)
    s = np.linspace(0.0, 1.0, frames)[:, None]
    return np.array([coupled(rt.scene.model, q) for q in (1 - s) * ends[0] + s * ends[1]])


@pytest.mark.parametrize("name", ["shadow", "inspire"])
def test_calibration_recovers_a_known_offset(name):
    """A 'human' made from robot poses whose wrist is the robot's taken back through a known
    offset: the wrist-free solve puts the robot wrist back on the robot's poses, and the
    calibration returns that offset (the hand's own offset plays no part)."""
    truth = dataclasses.replace(get_hand(name), wrist_offset=KNOWN)
    maker = Retargeter(truth, None, RetargetConfig(wrist=WristConfig(use_offset=True)))
    rng = np.random.default_rng(4)
    demos = [
        (f"motion{k}", human_from_robot_poses(maker, _robot_motion(maker, rng))) for k in (0, 1)
    ]
    seen = []
    cal = calibrate_wrist(get_hand(name), demos, on_pair=seen.append)
    assert seen == ["motion0", "motion1"] and cal.frames == 240
    assert cal.keypoint_err_free_m < 1e-3  # the robot's keypoints are reachable exactly
    err_deg = np.degrees(
        (Rotation.from_rotvec(cal.rotvec).inv() * Rotation.from_rotvec(KNOWN.rotvec)).magnitude()
    )
    assert err_deg < 0.5, (cal.rotvec, KNOWN.rotvec)
    np.testing.assert_allclose(cal.translation, KNOWN.translation, atol=1e-3)
    assert cal.rotation_spread_deg[1] < 0.5 and (cal.translation_sd_m < 1e-3).all()
    # The printed field is valid Python giving the same offset.
    off = eval(cal.as_python().removeprefix("wrist_offset="), {"WristOffset": WristOffset})
    np.testing.assert_allclose(off.rotvec, cal.rotvec, atol=1e-4)
    # Retargeted with the default weights, the offset the calibration found puts the wrist
    # near the robot's own and the keypoints closer than no offset does.
    traj = demos[0][1]
    err = {}
    for label, o in (("calibrated", off), ("none", None)):
        hand = dataclasses.replace(get_hand(name), wrist_offset=o)
        rt = Retargeter(hand, None, RetargetConfig(wrist=WristConfig(use_offset=True)))
        out = rt.retarget(traj)
        err[label] = out.keypoint_err.mean()
        if o is not None:
            R_rel, p_rel = wrist_in_target_frame(rt, traj, out.q)
            assert np.linalg.norm(p_rel, axis=1).max() < 0.01
            assert np.degrees(Rotation.from_matrix(R_rel).magnitude()).max() < 5.0
    # (Measured 0.33 vs 8.3 mm on Inspire; 1.4 vs 2.6 mm on Shadow, whose own wrist joints
    # take up part of a missing offset.)
    assert err["calibrated"] < 0.7 * err["none"], err


def test_wrist_in_target_frame_checks_the_joint_trajectory():
    rt = Retargeter(get_hand("shadow"), None, RetargetConfig())
    traj = human_from_robot_poses(rt, np.tile(rt.q_default, (3, 1)))
    with pytest.raises(RetargetError, match="shape"):
        wrist_in_target_frame(rt, traj, np.zeros((2, rt.nq)))


def test_calibration_demos_are_feasible_cropped_and_skip_the_benchmark_pairs():
    from benchmarks._common import select_pairs  # noqa: F401  (the benchmarks' order is this)
    from dexcanvas_core.demos import feasible_pairs, spread_pairs

    hand = get_hand("allegro")
    demos = calibration_demos(hand, 2, max_frames=50)
    order = [str(p) for p in spread_pairs(feasible_pairs())]
    assert len(demos) == 2
    for pair, traj in demos:
        assert traj.num_frames == 50 and order.index(str(pair)) >= 40
    with pytest.raises(RetargetError, match="at least one"):
        calibration_demos(hand, 0)


def test_cli_calibrate_wrist_json_and_errors(capsys):
    rc = main(["calibrate-wrist", "--hand", "leap", "--pairs", "1", "--max-frames", "40", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["hand"] == "leap" and out["frames"] == 40 and len(out["pairs"]) == 1
    assert "1 generated pair of operator2" in out["source"]
    assert main(["calibrate-wrist", "--hand", "nope"]) == 2
    assert "unknown hand 'nope'" in capsys.readouterr().err
    assert main(["calibrate-wrist", "--hand", "leap", "--operator", "bob"]) == 2
    assert "unknown operator 'bob'" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["calibrate-wrist", "--hand", "leap", "--pairs", "0"])
    assert e.value.code == 2 and "expected a whole number >= 1" in capsys.readouterr().err
