"""Mocap markers → MANO fit: layout, rendering, readers, registration, calibration, the fit."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
import torch

from dexcanvas_core.errors import MissingDependencyError, ValidationError
from dexcanvas_core.mano import HandSkeleton, ManoLayer
from dexcanvas_core.mano.limits import HIGH, LOW, pose_from_anatomical
from dexcanvas_core.mocap import (
    DORSUM_MARKERS,
    FIT_QUALITY_COLUMN,
    HAND_MARKER_NAMES,
    HAND_MARKERS,
    MARKER_NAMES,
    OBJECT_MARKER_NAMES,
    FitConfig,
    FitOptions,
    HandMarkerModel,
    MarkerDataError,
    MarkerFileError,
    MarkerStream,
    MocapFrame,
    calibrate_subject,
    fit_flags,
    fit_markers,
    kabsch,
    load_mapping,
    object_marker_positions,
    object_marker_table,
    read_csv,
    read_markers,
    register_object,
    render_markers,
    run_fit,
    write_csv,
)
from dexcanvas_core.mocap.layout import (
    MIN_DISTANCE_GAP_M,
    distance_gap_m,
    hand_marker_offsets,
    hand_marker_parents,
    hand_marker_rest_positions,
)
from dexcanvas_core.rotations import aa_to_matrix, rotation_angle_between_aa
from dexcanvas_core.safe_io import OutputExistsError
from dexcanvas_core.taxonomy import OBJECTS
from dexcanvas_core.trajectory import HandTrack, ObjectMove, ObjectTrack, Trajectory

FPS = 120.0


def _synthetic_demo(
    T: int = 180, scale: float = 1.05, seed: int = 0, object_id: str = "cube2", side="right"
) -> Trajectory:
    """A smooth grasp-like motion driving the anatomical DoFs a demonstration drives."""
    rng = np.random.default_rng(seed)
    t = np.arange(T) / FPS
    s = (0.5 - 0.5 * np.cos(2 * np.pi * t / t[-1]))[:, None, None]  # open → closed → open
    target = np.zeros((15, 3))
    for j in range(15):
        level = j % 3
        target[j, 0] = rng.uniform(0.15, 0.75) * HIGH[j, 0]
        if level == 0:
            target[j, 1] = rng.uniform(0.5 * LOW[j, 1], 0.5 * HIGH[j, 1])
    target[12] = rng.uniform(0.6 * LOW[12], 0.6 * HIGH[12])  # thumb CMC: flex, abd, twist
    target[13, 1] = rng.uniform(0.5 * LOW[13, 1], 0.5 * HIGH[13, 1])  # thumb MCP abduction
    pose = pose_from_anatomical(s * target, side)
    rot = np.stack([1.2 + 0.3 * np.sin(t), 0.2 * np.cos(1.3 * t), 0.4 * np.sin(0.7 * t)], 1)
    transl = np.stack([0.3 + 0.05 * t, 0.02 * np.sin(2 * t), 0.15 + 0.03 * np.cos(t)], 1)
    layer = ManoLayer(side, skeleton=HandSkeleton.default(side).scaled(scale))
    kp = layer.forward_numpy(global_orient=rot, hand_pose=pose, transl=transl).keypoints
    obj_pos = np.stack([0.45 + 0.02 * t, 0.01 * t, 0.05 + 0.04 * s[:, 0, 0]], 1)
    obj_rot = np.stack([0.3 * s[:, 0, 0], 0.1 * t, 0.5 + 0.2 * np.sin(t)], 1)
    return Trajectory(
        uuid=f"synthetic-{seed}",
        timestamp=t,
        fps=FPS,
        hands=[
            HandTrack(
                side,
                global_pos=transl,
                global_rot_aa=rot,
                hand_pose=np.concatenate([rot, pose], 1),
                joint_pos=kp,
            )
        ],
        objects=[ObjectTrack(object_id, obj_pos, obj_rot)],
        scene=object_id,
        gesture="tripod",
        object_move=[ObjectMove(object_id, 0, T - 1)],
    )


@pytest.fixture(scope="module")
def demo() -> Trajectory:
    return _synthetic_demo()


@pytest.fixture(scope="module")
def clean_fit(demo):
    frame = MocapFrame.y_up("mm", (0.3, -0.2, 0.01))
    stream = render_markers(
        demo, noise_mm=0.0, dropout=0.0, gap_rate=0.0, swap_rate=0.0, frame=frame, seed=1
    )
    return stream, fit_markers(stream)


def _kp_err_mm(fit, traj) -> np.ndarray:
    return np.linalg.norm(fit.trajectory.hand.joint_pos - traj.hand.joint_pos, axis=-1) * 1000


# -- layout -------------------------------------------------------------------------------------


def test_layout_has_14_hand_and_4_asymmetric_object_markers():
    assert len(HAND_MARKERS) == len(set(HAND_MARKER_NAMES)) == 14
    assert len(OBJECT_MARKER_NAMES) == 4 and len(MARKER_NAMES) == 18
    assert len(DORSUM_MARKERS) == 3
    rest = HandSkeleton.default().rest_keypoints
    palm = hand_marker_rest_positions(rest)[:3]
    assert distance_gap_m(palm) > MIN_DISTANCE_GAP_M  # a scalene triangle: labels recoverable
    table = object_marker_table()
    assert len(table) == 29 and set(table) == set(OBJECTS)  # the paper's table: 29 objects
    for oid, P in table.items():
        assert P.shape == (4, 3), oid
        d = sorted(np.linalg.norm(P[i] - P[j]) for i, j in itertools.combinations(range(4), 2))
        assert min(np.diff(d)) >= MIN_DISTANCE_GAP_M - 1e-12, oid
    np.testing.assert_array_equal(object_marker_positions("cube2"), table["cube2"])


def test_left_layout_mirrors_right():
    right = HandSkeleton.default("right").rest_keypoints
    left = HandSkeleton.default("left").rest_keypoints
    mr = hand_marker_rest_positions(right, "right")
    ml = hand_marker_rest_positions(left, "left")
    np.testing.assert_allclose(ml, mr * np.array([-1.0, 1.0, 1.0]), atol=1e-12)


def test_marker_jacobian_matches_finite_differences():
    sk = HandSkeleton.default().scaled(1.03)
    model = HandMarkerModel(
        sk.rest_keypoints, hand_marker_offsets(sk.rest_keypoints), hand_marker_parents()
    )
    x = torch.tensor(np.random.default_rng(0).normal(size=(3, 51)) * 0.4)
    J = model.jacobian(model.forward(x)).reshape(3, -1, 51)
    eps = 1e-6
    for i in range(51):
        dx = torch.zeros_like(x)
        dx[:, i] = eps
        num = (model.forward(x + dx).markers - model.forward(x - dx).markers) / (2 * eps)
        np.testing.assert_allclose(J[:, :, i], num.reshape(3, -1), atol=1e-7)


# -- rigid registration --------------------------------------------------------------------------


def test_kabsch_and_object_registration_repair_swaps_and_outliers():
    P = object_marker_positions("cylinder3")
    rng = np.random.default_rng(3)
    R = aa_to_matrix(rng.normal(size=(50, 3)))
    t = rng.normal(size=(50, 3)) * 0.1
    Q = np.einsum("tij,kj->tki", R, P) + t[:, None]
    Rk, tk = kabsch(P, Q)
    np.testing.assert_allclose(Rk, R, atol=1e-9)
    np.testing.assert_allclose(tk, t, atol=1e-9)
    bad = Q.copy()
    bad[5, [0, 2]] = bad[5, [2, 0]]  # label swap
    bad[9, 1] += 0.03  # 30 mm outlier
    bad[12, :2] = np.nan  # only two markers: no pose
    reg = register_object(P, bad)
    assert reg.swapped[5] and reg.swapped.sum() == 1
    assert reg.outliers[9] == 1 and not reg.used[9, 1]
    assert not reg.valid[12]
    ok = reg.valid
    np.testing.assert_allclose(reg.t[ok], t[ok], atol=1e-9)


# -- fit -----------------------------------------------------------------------------------------


def test_round_trip_noise0_recovers_keypoints_and_object(demo, clean_fit):
    stream, fit = clean_fit
    err = _kp_err_mm(fit, demo)
    assert err.mean() < 0.1 and np.percentile(err, 99) < 0.5, (err.mean(), err.max())
    assert err.max() < 0.5
    pos = np.linalg.norm(fit.trajectory.object.pos - demo.object.pos, axis=-1) * 1000
    ang = np.rad2deg(rotation_angle_between_aa(fit.trajectory.object.rot_aa, demo.object.rot_aa))
    assert pos.max() < 0.1 and ang.max() < 0.05
    assert fit.calibration.scale == pytest.approx(1.05, abs=2e-3)
    assert fit.trajectory.num_frames == stream.num_frames
    assert not fit.flags.interpolated.any() and not fit.flags.long_gap.any()
    moves = fit.trajectory.object_move
    assert len(moves) == 1 and moves[0].object_name == "cube2"
    assert np.nanmax(fit.flags.residual_mm) < 0.2


def test_round_trip_noise0_on_a_generated_demonstration():
    from dexcanvas_core import demos

    traj = demos.generate_demo("cube2/tripod", "operator2", seed=1).trajectory
    stream = render_markers(traj, noise_mm=0.0, dropout=0.0, gap_rate=0.0, swap_rate=0.0)
    fit = fit_markers(stream)
    err = _kp_err_mm(fit, traj)
    assert err.mean() < 0.1 and np.percentile(err, 99) < 0.5, (err.mean(), err.max())
    pos = np.linalg.norm(fit.trajectory.object.pos - traj.object.pos, axis=-1) * 1000
    assert pos.max() < 0.1


def test_noise_dropouts_gaps_and_swaps_stay_bounded(demo):
    stream = render_markers(demo, noise_mm=1.0, dropout=0.1, gap_rate=0.001, swap_rate=0.01, seed=4)
    truth_swaps = stream.truth.swapped.any(1)
    assert truth_swaps.any()
    fit = fit_markers(stream)
    err = _kp_err_mm(fit, demo)
    ok = ~fit.flags.long_gap
    assert err[ok].mean() < 2.0, err[ok].mean()
    pos = np.linalg.norm(fit.trajectory.object.pos - demo.object.pos, axis=-1) * 1000
    ang = np.rad2deg(rotation_angle_between_aa(fit.trajectory.object.rot_aa, demo.object.rot_aa))
    assert pos.mean() < 1.0 and ang.mean() < 1.0
    # most swapped frames are found and repaired (the rest are flagged by their residual)
    found = fit.flags.swapped[truth_swaps].mean()
    assert found > 0.5, found
    assert fit.flags.interpolated.any()


def test_too_few_object_markers_and_nan_frames_are_flagged(demo):
    stream = render_markers(demo, noise_mm=0.0, dropout=0.0, gap_rate=0.0, swap_rate=0.0)
    pos = stream.positions.copy()
    k = stream.labels.index("obj1")
    pos[40:44, k : k + 2] = np.nan  # 2 object markers for 4 frames: short gap
    pos[100:103] = np.nan  # whole frames missing
    s = MarkerStream(stream.labels, pos, stream.fps, stream.frame, stream.timestamp, "cube2")
    fit = fit_markers(s)
    f = fit.flags
    assert f.num_frames == stream.num_frames  # nothing dropped
    assert f.nan_frame[100:103].all() and f.nan_frame.sum() == 3
    assert (f.object_markers_visible[40:44] == 2).all()
    assert f.interpolated[40:44].all() and f.interpolated[100:103].all()
    assert (f.missing_markers[100:103] == 18).all()
    assert np.isfinite(fit.trajectory.hand.joint_pos).all()
    err = _kp_err_mm(fit, demo)
    assert err[100:103].max() < 2.0
    # an object that never shows three markers is an error that says so
    pos2 = stream.positions.copy()
    pos2[:, k : k + 2] = np.nan
    s2 = MarkerStream(stream.labels, pos2, stream.fps, stream.frame, stream.timestamp, "cube2")
    with pytest.raises(MarkerDataError, match="never has 3 visible markers"):
        fit_markers(s2)
    # object markers without an object id
    s3 = MarkerStream(stream.labels, stream.positions, stream.fps, stream.frame)
    with pytest.raises(MarkerDataError, match="no object id"):
        fit_markers(s3)


def test_left_hand_round_trip():
    traj = _synthetic_demo(T=90, scale=1.0, seed=7, side="left")
    stream = render_markers(traj, noise_mm=0.0, dropout=0.0, gap_rate=0.0, swap_rate=0.0)
    assert stream.side == "left"
    fit = fit_markers(stream)
    assert fit.trajectory.hand.name == "left"
    assert _kp_err_mm(fit, traj).mean() < 0.1


def test_limit_prior_is_the_shared_limit_violation():
    from dexcanvas_core.mano.limits import limit_violation
    from dexcanvas_core.mocap.fit import HandFitter, SolverOptions

    sk = HandSkeleton.default()
    model = HandMarkerModel(
        sk.rest_keypoints, hand_marker_offsets(sk.rest_keypoints), hand_marker_parents()
    )
    opts = SolverOptions()
    fitter = HandFitter(model, "right", opts)
    x = torch.tensor(np.random.default_rng(2).normal(size=(4, 51)) * 1.2)
    obs = model.forward(x).markers
    w = torch.zeros(4, 14, dtype=torch.float64)
    with_limits = fitter._linearize(x, obs, w, None).cost
    fitter.priors.w2_lim = 0.0
    without = fitter._linearize(x, obs, w, None).cost
    v = limit_violation(x[:, 6:], "right")
    expected = 0.5 * (v**2).sum(dim=(1, 2)) / opts.limit_sigma_rad**2
    torch.testing.assert_close(with_limits - without, expected)


def test_calibration_recovers_hand_size():
    traj = _synthetic_demo(T=120, scale=0.92, seed=5)
    stream = render_markers(traj, noise_mm=0.0, dropout=0.0, gap_rate=0.0, swap_rate=0.0)
    cal = calibrate_subject(stream.hand_world(), stream.times, mode="scale")
    assert cal.scale == pytest.approx(0.92, abs=1e-3)
    bones = calibrate_subject(stream.hand_world(), stream.times, mode="bones")
    assert bones.scale == pytest.approx(0.92, abs=0.01)
    assert bones.residual_mm < 0.5


# -- files ---------------------------------------------------------------------------------------


def test_csv_round_trip_wide_and_long(demo, tmp_path):
    stream = render_markers(demo.slice(0, 30), noise_mm=0.5, dropout=0.1, seed=2)
    for layout in ("wide", "long"):
        p = write_csv(stream, tmp_path / f"m_{layout}.csv", layout=layout)
        back = read_csv(p, object_id="cube2")
        assert back.labels == stream.labels
        np.testing.assert_allclose(back.positions, stream.positions, atol=1e-6)
        assert back.fps == pytest.approx(stream.fps)
        assert back.frame.unit_m == pytest.approx(0.001)


def test_c3d_round_trip_with_mapping_file(demo, tmp_path):
    import ezc3d

    stream = render_markers(demo.slice(0, 40), noise_mm=0.5, dropout=0.1, seed=3)
    capture = [f"Subj:{n.upper()}" for n in stream.labels] + ["Subj:LASI"]
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [stream.fps]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(capture)
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    pts = np.ones((4, len(capture), stream.num_frames))
    pts[:3, :-1] = np.transpose(stream.positions, (2, 1, 0))
    pts[:3, -1] = 5.0
    c["data"]["points"] = pts
    c.write(str(tmp_path / "cap.c3d"))
    mapping = {
        "markers": {f"Subj:{n.upper()}": n for n in stream.labels},
        "ignore": ["LASI"],
        "object": "cube2",
    }
    (tmp_path / "map.json").write_text(json.dumps(mapping))
    back = read_markers(tmp_path / "cap.c3d", mapping=tmp_path / "map.json")
    assert back.labels == stream.labels and back.object_id == "cube2"
    assert back.ignored_labels == ("Subj:LASI",)
    np.testing.assert_allclose(back.positions, stream.positions, atol=1e-3)  # float32 in C3D
    assert np.array_equal(np.isnan(back.positions), np.isnan(stream.positions))
    # without the mapping: every unknown label is listed
    with pytest.raises(MarkerFileError, match="unknown marker labels") as e:
        read_markers(tmp_path / "cap.c3d")
    assert "Subj:LASI" in e.value.labels and len(e.value.labels) == len(capture)


def test_mapping_file_errors(tmp_path):
    p = tmp_path / "bad.json"
    p.write_text(json.dumps({"markers": {"A": "index_nial"}}))
    with pytest.raises(MarkerFileError, match="not layout marker names"):
        load_mapping(p)
    p.write_text(json.dumps({"markers": {"A": "index_nail", "B": "index_nail"}}))
    with pytest.raises(MarkerFileError, match="two capture labels map to one"):
        load_mapping(p)
    p.write_text(json.dumps({"markers": {}, "colour": "red"}))
    with pytest.raises(MarkerFileError, match="unknown keys"):
        load_mapping(p)
    q = tmp_path / "map.csv"
    q.write_text("capture_label,layout_name\nRIDX,index_nail\nJUNK,ignore\n")
    m = load_mapping(q)
    assert m.markers == {"RIDX": "index_nail"} and m.ignore == ("JUNK",)


def test_csv_with_unknown_labels_and_no_rate_fails_clearly(tmp_path):
    p = tmp_path / "m.csv"
    p.write_text("frame,foo_x,foo_y,foo_z\n0,1,2,3\n1,1,2,3\n")
    with pytest.raises(MarkerFileError, match=r"unknown marker labels \['foo'\]"):
        read_csv(p, fps=100.0)
    p.write_text("frame,index_nail_x,index_nail_y,index_nail_z\n0,1,2,3\n")
    with pytest.raises(MarkerFileError, match="frame rate is unknown"):
        read_csv(p)
    p.write_text("frame,index_nail_x,index_nail_y,index_nail_z\n0,1,zz,3\n")
    with pytest.raises(MarkerFileError, match="row 2, column 'index_nail_y'"):
        read_csv(p, fps=100.0)


def test_run_fit_writes_a_dataset_with_flags(demo, tmp_path):
    from dexcanvas_core.io import open_dataset

    stream = render_markers(demo, noise_mm=0.5, dropout=0.05, seed=6)
    path = write_csv(stream, tmp_path / "take.csv")
    cfg = FitConfig(markers=path, out=tmp_path / "fit.lance", object_id="cube2")
    report = run_fit(cfg)
    assert report.frames == demo.num_frames and report.object_id == "cube2"
    traj = open_dataset(tmp_path / "fit.lance").get(0)
    assert FIT_QUALITY_COLUMN in traj.extras
    flags = fit_flags(traj)
    assert flags.num_frames == demo.num_frames
    assert report.flags["frames_interpolated"] == int(flags.interpolated.sum())
    err = np.linalg.norm(traj.hand.joint_pos - demo.hand.joint_pos, axis=-1) * 1000
    assert err.mean() < 1.5
    with pytest.raises(OutputExistsError, match="already exists"):
        run_fit(cfg)


def test_missing_ezc3d_is_a_clear_error(monkeypatch, tmp_path):
    import builtins

    real = builtins.__import__

    def fake(name, *a, **k):
        if name == "ezc3d":
            raise ImportError(name)
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", fake)
    (tmp_path / "x.c3d").write_bytes(b"")
    with pytest.raises(MissingDependencyError, match="ezc3d"):
        read_markers(tmp_path / "x.c3d")


def test_options_validate():
    with pytest.raises(ValidationError, match="calibrate"):
        FitOptions(calibrate="shape").validate()  # type: ignore[arg-type]
    with pytest.raises(ValidationError, match="lowpass_hz"):
        FitOptions(lowpass_hz=-1.0).validate()
