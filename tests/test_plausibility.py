"""Plausibility checks on input data (units, human motion limits, outliers, truncated files,
keypoint units, frame rates) and MuJoCo's warnings recorded as data."""

import dataclasses
import logging

import mujoco
import numpy as np
import pytest

from dexcanvas_core import load_demonstration, object_geometry
from dexcanvas_core.errors import ValidationError
from dexcanvas_core.io import write_dataset
from dexcanvas_core.mocap.readers import c3d_header_frames, read_c3d
from dexcanvas_core.plausibility import (
    LIMITS,
    ImplausibleDataError,
    allowing_implausible,
    check_fps,
    check_keypoint_sequence,
    check_motion,
    hand_length,
)
from dexcanvas_core.sim.mj_warnings import WarningCounter, blew_up, describe
from dexcanvas_core.sim.pipeline import SimConfig, simulate
from dexcanvas_core.sim.tracker import TrackingEnv
from dexcanvas_core.trajectory import ObjectTrack
from retarget import Retargeter, get_hand
from retarget.cli import main as retarget_main
from retarget.errors import RetargetError
from retarget.keypoint_input import load_keypoints
from retarget.validate import Resimulator, _WristStepper


@pytest.fixture(scope="module")
def demo():
    return load_demonstration("cube2/tripod").slice(200, 260)


def scaled(traj, k: float):
    """``traj`` with every position multiplied by ``k`` (k = 1000: metres written as mm)."""
    h = traj.hand
    hand = dataclasses.replace(h, global_pos=h.global_pos * k, joint_pos=h.joint_pos * k)
    objs = [ObjectTrack(o.name, o.pos * k, o.rot_aa) for o in traj.objects]
    return dataclasses.replace(
        traj, hands=[hand], objects=objs, contacts=None, object_wrench_world=None
    )


def with_wrist(traj, frame: int, offset):
    """``traj`` with the hand (keypoints and MANO translation) moved by ``offset`` [m] at
    ``frame`` only."""
    h = traj.hand
    kp, gp = h.joint_pos.copy(), h.global_pos.copy()
    kp[frame] += np.asarray(offset, np.float32)
    gp[frame] += np.asarray(offset, np.float32)
    return dataclasses.replace(traj, hands=[dataclasses.replace(h, joint_pos=kp, global_pos=gp)])


def test_real_demonstration_passes_with_margins(demo):
    demo.validate()
    assert LIMITS.hand_length_m[0] < hand_length(demo.hand.joint_pos) < LIMITS.hand_length_m[1]
    assert 0.15 < hand_length(demo.hand.joint_pos) < 0.25  # an adult hand, in metres


def test_millimetres_are_named_with_the_fix(demo):
    with pytest.raises(ImplausibleDataError, match="looks like millimetres; divide the") as e:
        scaled(demo, 1000.0).validate()
    assert e.value.field == "hands[right].mano_joint_pos"
    assert "--allow-implausible" in str(e.value)


def test_one_outlier_frame_is_named(demo):
    with pytest.raises(ImplausibleDataError, match=r"frame 17 is .* from both neighbouring") as e:
        with_wrist(demo, 17, (1e6, 0.0, 0.0)).validate()
    assert e.value.frame == 17 and "drop or interpolate frame 17" in str(e.value)


def test_too_fast_and_too_accelerated_are_named(demo):
    # the hand thrown 1 m along x in 10 frames (12 m/s) from frame 20
    h = demo.hand
    shift = 0.1 * np.clip(np.arange(demo.num_frames) - 20, 0, 10)[:, None] * [1.0, 0.0, 0.0]
    hand = dataclasses.replace(
        h, joint_pos=h.joint_pos + shift[:, None], global_pos=h.global_pos + shift
    )
    with pytest.raises(ImplausibleDataError, match=r"moves at 12 m/s at frame 2\d") as e:
        dataclasses.replace(demo, hands=[hand]).validate()
    assert 20 <= e.value.frame <= 30 and "check --fps" in str(e.value)
    # a reversal from +6 to -6 m/s at frame 30 (120 Hz): ~480 m/s²
    t = np.arange(60) / 120.0
    x = np.where(t < 0.25, 6 * t, 1.5 - 6 * (t - 0.25))[:, None] * [1.0, 0.0, 0.0]
    with pytest.raises(ImplausibleDataError, match="accelerates at 480 m/s² at frame 30"):
        check_motion(x, 120.0, "track", "wrist")
    check_motion(x / 2, 120.0, "track", "wrist")  # 240 m/s²: passes


def test_far_beyond_a_room(demo):
    pos = demo.object.pos + np.array([20.0, 0.0, 0.0])
    far = dataclasses.replace(demo, objects=[ObjectTrack("cube2", pos, demo.object.rot_aa)])
    with pytest.raises(ImplausibleDataError, match=r"objects\[cube2\]\.pos at frame 0 is"):
        far.validate()


def test_allow_implausible_goes_on_with_one_warning(demo, caplog):
    bad = with_wrist(demo, 17, (1e6, 0.0, 0.0))
    with caplog.at_level(logging.WARNING), allowing_implausible():
        bad.validate()
        bad.validate()
    hits = [r.getMessage() for r in caplog.records if "frame 17" in r.getMessage()]
    assert any("drop or interpolate frame 17" in h for h in hits)
    assert all("implausible data accepted" in h for h in hits)
    assert len(hits) == len(set(hits))  # each finding once, though read twice
    with pytest.raises(ImplausibleDataError):
        bad.validate()  # only inside the block


# -- frame rates and keypoints --------------------------------------------------------------------


@pytest.mark.parametrize("fps", [0, -5.0, float("nan"), float("inf"), "120", True])
def test_fps_that_is_no_rate_is_refused(fps):
    with pytest.raises(ValidationError, match="--fps must be"):
        check_fps(fps)


@pytest.mark.parametrize("fps", [1e-6, 0.5, 2e4])
def test_absurd_fps_is_implausible(fps):
    with pytest.raises(ImplausibleDataError, match=r"outside 1\.\.10000 Hz"):
        check_fps(fps)
    with allowing_implausible():
        assert check_fps(fps) == fps


def test_keypoint_units(demo):
    kp = demo.hand.joint_pos.astype(np.float64)
    check_keypoint_sequence(kp, 120.0, "kp.npy", units="m")
    with pytest.raises(ImplausibleDataError, match="looks like millimetres; pass --units mm"):
        check_keypoint_sequence(kp * 1000, 120.0, "kp.npy", units="m")
    with pytest.raises(ImplausibleDataError, match="already in metres; drop --units mm"):
        check_keypoint_sequence(kp * 1e-3, 120.0, "kp.npy", units="mm")
    with pytest.raises(ImplausibleDataError, match="all keypoints at one point"):
        check_keypoint_sequence(np.zeros_like(kp), 120.0, "kp.npy", units="m")


def test_empty_keypoint_files(tmp_path):
    (tmp_path / "empty.npy").write_bytes(b"")
    (tmp_path / "empty.npz").write_bytes(b"")
    np.save(tmp_path / "none.npy", np.zeros((0, 21, 3)))
    np.savez(tmp_path / "nokey.npz")
    with pytest.raises(RetargetError, match=r"empty\.npy: the file is empty"):
        load_keypoints(tmp_path / "empty.npy")
    with pytest.raises(RetargetError, match=r"empty\.npz: the file is empty"):
        load_keypoints(tmp_path / "empty.npz")
    with pytest.raises(RetargetError, match=r"T >= 2.*got \(0, 21, 3\)"):
        load_keypoints(tmp_path / "none.npy")
    with pytest.raises(RetargetError, match="no 'keypoints' array"):
        load_keypoints(tmp_path / "nokey.npz")


def test_cli_keypoints_in_mm_and_bad_fps_are_one_line_errors(demo, tmp_path, capsys):
    p = tmp_path / "kp.npy"
    np.save(p, demo.hand.joint_pos * 1000.0)
    args = ["keypoints", "--hand", "leap", "--input", str(p), "--out", str(tmp_path / "o")]
    assert retarget_main([*args, "--fps", "120"]) == 2
    err = capsys.readouterr().err.strip()
    assert "looks like millimetres; pass --units mm" in err and len(err.splitlines()) == 1
    assert retarget_main([*args, "--fps", "0"]) == 2
    assert "--fps must be a finite frame rate > 0" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


# -- truncated C3D ----------------------------------------------------------------------------


def test_truncated_c3d_is_refused_with_the_frame_count(tmp_path, caplog):
    import ezc3d

    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [120.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = ("a", "b")
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    c["data"]["points"] = np.ones((4, 2, 120))
    c.write(str(tmp_path / "full.c3d"))
    data = (tmp_path / "full.c3d").read_bytes()
    (tmp_path / "trunc.c3d").write_bytes(data[: len(data) // 2])
    assert c3d_header_frames(tmp_path / "trunc.c3d") == 120
    with pytest.raises(ImplausibleDataError, match="announces 120 frames but the file holds 40"):
        read_c3d(tmp_path / "trunc.c3d")
    with caplog.at_level(logging.WARNING), allowing_implausible():
        with pytest.raises(Exception) as e:  # goes on to the (unmapped) labels
            read_c3d(tmp_path / "trunc.c3d")
    assert "announces" not in str(e.value) and "announces 120 frames" in caplog.text


# -- MuJoCo warnings --------------------------------------------------------------------------


def test_warning_counter_records_type_count_and_first_frame():
    m = mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body><joint type='slide'/><geom size='.1'/></body></worldbody>"
        "</mujoco>"
    )
    d = mujoco.MjData(m)
    w = WarningCounter()
    for frame in range(6):
        if frame in (3, 5):
            d.qvel[0] = np.nan  # a blow-up: MuJoCo warns and resets the data
        mujoco.mj_step(m, d)
        w.update(d, frame)
    assert w.to_dict() == {"BADQVEL": {"count": 2, "first_frame": 3}}
    assert w.blew_up and blew_up(w.to_dict())
    assert describe(w.to_dict()) == "BADQVEL ×2 (from frame 3)"
    assert WarningCounter().to_dict() == {}


def test_blown_up_resimulation_is_recorded_and_a_failure(demo, monkeypatch):
    human = load_demonstration("cube2/tripod").slice(0, 20)
    hand, obj = get_hand("shadow"), object_geometry("cube2")
    q = Retargeter(hand, obj).retarget(human).q_command
    sim = Resimulator(hand, obj)
    ok = sim.run(q, human)
    assert ok.success and ok.metrics()["mujoco_warnings"] == {}

    calls = {"n": 0}
    step = _WristStepper.step
    at = round(sim.cfg.settle_s / sim.model.opt.timestep) + 4 * 10  # frame 10 (4 steps each)

    def step_with_blow_up(self, d, *a):
        step(self, d, *a)
        calls["n"] += 1
        if calls["n"] == at:  # what MuJoCo's bad-acceleration check leaves in the counters
            d.warning[int(mujoco.mjtWarning.mjWARN_BADQACC)].number += 1

    monkeypatch.setattr(_WristStepper, "step", step_with_blow_up)
    bad = sim.run(q, human)
    w = bad.metrics()["mujoco_warnings"]
    assert list(w) == ["BADQACC"] and w["BADQACC"]["count"] == 1
    assert w["BADQACC"]["first_frame"] == 10
    assert not bad.success and bad.first_failure_frame is None  # the object was kept


def test_dataset_in_millimetres_exit_codes(demo, tmp_path, capsys):
    """``retarget run`` on a dataset in mm: refused (exit 2) naming the unit; forced with
    --allow-implausible it runs and fails validation (exit 3)."""
    with allowing_implausible():
        write_dataset([scaled(demo.slice(0, 30), 1000.0)], tmp_path / "mm.lance")
    args = ["run", "--hand", "leap", "--dataset", str(tmp_path / "mm.lance"), "--quiet"]
    assert retarget_main([*args, "--out", str(tmp_path / "a")]) == 2
    assert "looks like millimetres" in capsys.readouterr().err
    assert retarget_main([*args, "--out", str(tmp_path / "b"), "--allow-implausible"]) == 3


def test_blown_up_force_pipeline_is_recorded_and_a_failure(monkeypatch):
    human = load_demonstration("cube2/tripod").slice(0, 30)
    cfg = SimConfig(tracker="open_loop")
    assert simulate(human, cfg).metrics["mujoco_warnings"] == {}
    step = TrackingEnv.step

    def step_with_blow_up(self, a):
        r = step(self, a)
        if self.t == 10:  # counted at the next frame's end
            self.scene.data.warning[int(mujoco.mjtWarning.mjWARN_BADQACC)].number += 1
        return r

    monkeypatch.setattr(TrackingEnv, "step", step_with_blow_up)
    res = simulate(human, cfg)
    assert res.metrics["mujoco_warnings"] == {"BADQACC": {"count": 1, "first_frame": 11}}
    assert not res.success and res.metrics["failed_at_frame"] is None
