"""``dexcanvas import``: mano-npz captures into the DexCanvas layout, their checks, and
retargeting an imported row without a pair."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import trimesh

from dexcanvas_core.capture import ImportConfig, capture_from_arrays, run_import
from dexcanvas_core.capture.export import write_mano_npz
from dexcanvas_core.capture.world import rotation_to_z_up, up_vector
from dexcanvas_core.errors import ValidationError
from dexcanvas_core.io import open_dataset
from dexcanvas_core.keypoints import convert_keypoints
from dexcanvas_core.mano import ManoLayer, mirror_axis_angle
from dexcanvas_core.mano.pose import MANO_HANDS_MEAN_RIGHT
from dexcanvas_core.rotations import (
    aa_to_matrix,
    matrix_to_aa,
    matrix_to_quat_wxyz,
    quat_wxyz_to_matrix,
)
from dexcanvas_core.safe_io import OutputExistsError
from dexcanvas_core.taxonomy import clear_objects

T = 40
FPS = 60.0
EDGE = 0.05


@pytest.fixture(autouse=True)
def _no_objects():
    clear_objects()
    yield
    clear_objects()


def _box():
    m = trimesh.creation.box(extents=[EDGE, EDGE, EDGE])
    return np.asarray(m.vertices), np.asarray(m.faces)


def capture_arrays(seed: int = 0) -> dict:
    """A right hand reaching over a 5 cm box on a table at z = 0.1 and lifting it 10 cm; the
    keypoints are the built-in skeleton's (a 10 % larger hand) so their bone lengths are known."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0.0, 1.0, T)
    u = np.clip((s - 0.3) * 3.0, 0.0, 1.0)
    lift = 0.10 * (10 * u**3 - 15 * u**4 + 6 * u**5)  # smooth, held at the top from s = 2/3
    obj = np.stack([0.4 + 0 * s, 0.05 + 0 * s, 0.1 + EDGE / 2 + lift], axis=1)
    R_palm_down = aa_to_matrix(np.array([np.pi / 2, 0.0, 0.0]))
    go = np.repeat(matrix_to_aa(R_palm_down)[None], T, axis=0) + 0.05 * rng.normal(size=(T, 3))
    hp = 0.3 * rng.random((T, 45))
    wrist = obj + np.array([0.09, 0.0, 0.06])
    from dexcanvas_core.mano import HandSkeleton

    big = HandSkeleton.default("right").scaled(1.1)
    kp = ManoLayer("right", skeleton=big).forward_numpy(global_orient=go, hand_pose=hp).keypoints
    kp = kp - kp[:, :1] + wrist[:, None]
    v, f = _box()
    return {
        "fps": np.float64(FPS),
        "global_orient": go,
        "hand_pose": hp,
        "wrist_pos": wrist,
        "keypoints": convert_keypoints(kp, "mano21", "openpose21"),
        "object_name": np.str_("testbox"),
        "object_pos": obj,
        "object_quat_wxyz": np.repeat([[1.0, 0.0, 0.0, 0.0]], T, axis=0),
        "object_vertices": v,
        "object_faces": f,
        "object_mass_kg": np.float64(0.05),
        "table_height": np.float64(0.1),
        "contact_window": np.array([10, 39]),
        "manipulation_type": np.str_("tripod"),
    }


def _rotate_world(a: dict, Q: np.ndarray) -> dict:
    """The same scene in a world rotated by ``Q`` (points p → Q p)."""
    b = dict(a)
    b["global_orient"] = matrix_to_aa(Q @ aa_to_matrix(a["global_orient"]))
    for k in ("wrist_pos", "object_pos"):
        b[k] = a[k] @ Q.T
    b["keypoints"] = a["keypoints"] @ Q.T
    b["object_quat_wxyz"] = matrix_to_quat_wxyz(Q @ quat_wxyz_to_matrix(a["object_quat_wxyz"]))
    return b


def _mirror(a: dict) -> dict:
    """The same scene mirrored across x = 0 (a left hand)."""
    M = np.diag([-1.0, 1.0, 1.0])
    b = dict(a)
    b["hand_side"] = np.str_("left")
    b["global_orient"] = mirror_axis_angle(a["global_orient"])
    b["hand_pose"] = mirror_axis_angle(a["hand_pose"])
    for k in ("wrist_pos", "object_pos", "keypoints", "object_vertices"):
        b[k] = a[k] @ M
    b["object_faces"] = a["object_faces"][:, ::-1]
    b["object_quat_wxyz"] = matrix_to_quat_wxyz(M @ quat_wxyz_to_matrix(a["object_quat_wxyz"]) @ M)
    return b


def _same_capture(c1, c2, tol=1e-6):
    np.testing.assert_allclose(aa_to_matrix(c1.global_orient), aa_to_matrix(c2.global_orient),
                               atol=tol)  # fmt: skip
    np.testing.assert_allclose(c1.hand_pose, c2.hand_pose, atol=tol)
    np.testing.assert_allclose(c1.wrist_pos, c2.wrist_pos, atol=tol)
    np.testing.assert_allclose(c1.keypoints, c2.keypoints, atol=tol)
    np.testing.assert_allclose(c1.object_pos, c2.object_pos, atol=tol)
    np.testing.assert_allclose(
        quat_wxyz_to_matrix(c1.object_quat_wxyz), quat_wxyz_to_matrix(c2.object_quat_wxyz),
        atol=tol,
    )  # fmt: skip


def test_import_round_trip(tmp_path):
    """Keypoints, object poses, table and mesh survive the import; resampled to 120 Hz."""
    a = capture_arrays()
    write_mano_npz(tmp_path / "grasp.npz", a)
    res = run_import(ImportConfig("mano-npz", (tmp_path / "grasp.npz",), tmp_path / "D.lance"))
    traj = open_dataset(res.out).take([0])[0]
    assert traj.fps == 120.0 and traj.num_frames == 2 * T - 1
    # Every second frame is a source frame: the kinematics with the subject's measured bone
    # lengths reproduce the given keypoints (the skeleton of a 10 % larger hand).
    kp = convert_keypoints(a["keypoints"], "openpose21", "mano21")
    err = np.linalg.norm(traj.hand.joint_pos[::2] - kp, axis=-1)
    assert err.max() < 1e-4, err.max()
    np.testing.assert_allclose(traj.object.pos[::2], a["object_pos"], atol=1e-6)
    assert traj.scene == "testbox" and traj.gesture == "tripod"
    assert traj.table.top_z_m == pytest.approx(0.1)
    assert traj.object_move[0].start_frame == 20 and traj.object_move[0].end_frame == 78
    rep = res.sequences[0]
    assert rep["keypoint_fit_mm"] < 0.1
    assert res.objects["testbox"]["mass_kg"] == pytest.approx(0.05)
    np.testing.assert_allclose(res.objects["testbox"]["extent_m"], [EDGE] * 3, atol=1e-4)
    assert res.manifest == tmp_path / "D.lance.objects" / "manifest.toml"
    # The dataset's objects are found by any later reader of it.
    from dexcanvas_core.loaders.selection import load_row, subject_of

    clear_objects()
    row = load_row(res.out, 0)
    subj = subject_of(row)
    assert subj.object.id == "testbox" and subj.object.mass_kg == pytest.approx(0.05)
    assert str(subj) == "testbox/tripod"


def test_import_conventions_are_equivalent():
    """transl instead of wrist_pos, flat_hand_mean=false, a y-up world and a mirrored left hand
    all give the same normalised capture."""
    a = capture_arrays()
    ref = capture_from_arrays(a, name="ref")
    # MANO translation: wrist = J0(betas) + transl.
    b = dict(a)
    j0 = ManoLayer("right").forward_numpy(hand_pose=np.zeros((1, 45))).keypoints[0, 0]
    b["transl"] = b.pop("wrist_pos") - j0
    _same_capture(ref, capture_from_arrays(b, name="transl"))
    # Poses relative to MANO's mean hand.
    c = dict(a, flat_hand_mean=np.bool_(False), hand_pose=a["hand_pose"] - MANO_HANDS_MEAN_RIGHT)
    _same_capture(ref, capture_from_arrays(c, name="mean"))
    # y up: the scene in a world whose up is +y.
    Q = rotation_to_z_up(up_vector("y")).T  # z-up world → y-up world
    d = _rotate_world(a, Q)
    d["up_axis"] = np.str_("y")
    _same_capture(ref, capture_from_arrays(d, name="yup"))
    # A left hand, mirrored back.
    e = _mirror(a)
    _same_capture(ref, capture_from_arrays(e, name="left", mirror_left=True))
    np.testing.assert_allclose(
        capture_from_arrays(e, name="left", mirror_left=True).mesh_vertices, a["object_vertices"]
    )


@pytest.mark.parametrize(
    "change, words",
    [
        (lambda a: a.pop("object_pos"), ["object_pos", "missing"]),
        (lambda a: a.update(hand_pose=a["hand_pose"][:, :30]), ["hand_pose", "(T, 45)"]),
        (lambda a: a.update(hand_pose=np.c_[a["global_orient"], a["hand_pose"]]), ["48"]),
        (lambda a: a["wrist_pos"].__setitem__((5, 1), np.nan), ["wrist_pos", "NaN"]),
        (lambda a: a.update(hand_side=np.str_("left")), ["left", "--mirror-left"]),
        (lambda a: a.update(object_pos=a["object_pos"] * 1000), ["object_pos", "1000"]),
        (lambda a: a.update(global_orient=np.degrees(a["global_orient"])), ["radians"]),
        (lambda a: a.update(up_axis=np.str_("y")), ["up_axis", "'z'"]),
        (lambda a: a.update(up_axis=np.str_("w")), ["up_axis"]),
        (lambda a: a.update(object_quat_wxyz=2 * a["object_quat_wxyz"]), ["unit quaternions"]),
        (lambda a: a.pop("object_faces"), ["object_faces"]),
        (lambda a: (a.pop("object_faces"), a.pop("object_vertices")), ["mesh is missing"]),
        (lambda a: a.update(object_mesh=np.str_("nope.obj")), ["both"]),
        (lambda a: a.update(contact_window=np.array([5, 400])), ["contact_window"]),
        (lambda a: a.update(keypoints=a["keypoints"] * 1000), ["keypoints"]),
        (lambda a: a.update(fps=np.float64(0)), ["fps"]),
        (lambda a: a.update(transl=a["wrist_pos"]), ["exactly one"]),
    ],
)
def test_bad_captures_name_the_key_and_fix(change, words):
    a = capture_arrays()
    change(a)
    with pytest.raises(ValidationError) as e:
        capture_from_arrays(a, name="bad")
    msg = str(e.value)
    for w in words:
        assert w in msg, msg


def test_missing_mesh_file_and_no_mass(tmp_path):
    a = capture_arrays()
    a.pop("object_vertices"), a.pop("object_faces")
    a["object_mesh"] = np.str_("meshes/box.obj")
    with pytest.raises(ValidationError, match=r"no such file.*relative to the capture file"):
        capture_from_arrays(a, name="m", base_dir=tmp_path)
    (tmp_path / "meshes").mkdir()
    trimesh.Trimesh(*_box()).export(tmp_path / "meshes" / "box.obj")
    cap = capture_from_arrays(a, name="m", base_dir=tmp_path)
    np.testing.assert_allclose(np.ptp(cap.mesh_vertices, axis=0), [EDGE] * 3)
    # No mass anywhere: the error names the three ways to give one; --density estimates it.
    a.pop("object_mass_kg")
    write_mano_npz(tmp_path / "m.npz", a)
    cfg = ImportConfig("mano-npz", (tmp_path / "m.npz",), tmp_path / "D.lance")
    with pytest.raises(ValidationError, match=r"object_mass_kg.*--objects.*--density"):
        run_import(cfg)
    assert not (tmp_path / "D.lance").exists() and not (tmp_path / "D.lance.objects").exists()
    res = run_import(ImportConfig(**{**cfg.__dict__, "density": 400.0}))
    assert res.objects["testbox"]["mass_kg"] == pytest.approx(400.0 * EDGE**3, rel=1e-3)
    with pytest.raises(OutputExistsError, match="--overwrite"):
        run_import(ImportConfig(**{**cfg.__dict__, "density": 400.0}))


def test_table_is_cut_where_the_hand_goes_below_it():
    """A hand that goes below the table top beyond the object (a real table's edge) shrinks the
    table there instead of being held up by it."""
    from dexcanvas_core.capture.convert import capture_to_trajectory

    a = capture_arrays()
    a["wrist_pos"] = a["wrist_pos"].copy()
    a["keypoints"] = a["keypoints"].copy()
    # off the edge and 15 cm down over the last 25 frames (at a human speed), held for 5
    off = np.clip(np.linspace(0.0, 1.25, 25), 0.0, 1.0)[:, None] * np.array([0.3, 0.0, -0.25])
    a["wrist_pos"][-25:] += off
    a["keypoints"][-25:] += off[:, None]
    traj, _ = capture_to_trajectory(capture_from_arrays(a, name="edge"))
    tab = traj.table
    kp = traj.hand.joint_pos
    below = kp[kp[..., 2] < tab.top_z_m - 0.01]
    assert below.size and not tab.over(below).any()
    assert tab.over(traj.object.pos[:1]).all()  # the object still rests on it
    assert tab.size_x_m < 1.0


def test_cli_import_and_retarget_without_pair(tmp_path):
    """The acceptance path: import a file, retarget row 0 with no --pair; metrics name the mesh
    and the table; a bad file exits 2 with one line."""
    write_mano_npz(tmp_path / "grasp.npz", capture_arrays())
    out = tmp_path / "D.lance"
    r = subprocess.run(
        [sys.executable, "-m", "dexcanvas_core.cli", "import", "mano-npz",
         str(tmp_path / "grasp.npz"), "--out", str(out)],
        capture_output=True, text=True,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "testbox" in r.stdout
    bad = capture_arrays()
    bad.pop("hand_pose")
    write_mano_npz(tmp_path / "bad.npz", bad)
    r = subprocess.run(
        [sys.executable, "-m", "dexcanvas_core.cli", "import", "mano-npz",
         str(tmp_path / "bad.npz"), "--out", str(tmp_path / "E.lance")],
        capture_output=True, text=True,
    )  # fmt: skip
    assert r.returncode == 2 and "hand_pose" in r.stderr and "Traceback" not in r.stderr
    from retarget.run import RunConfig, run_retarget

    m = run_retarget(
        RunConfig(hand="shadow", dataset=out, index=0, out=tmp_path / "run", progress=False)
    )
    assert m["pair"] == "testbox/tripod"
    assert m["object"]["id"] == "testbox" and m["object"]["mesh"].endswith("testbox.obj")
    assert m["table"]["top_z_m"] == pytest.approx(0.1)
    on_disk = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert on_disk["frames"] == 2 * T - 1
