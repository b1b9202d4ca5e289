"""Readers of published dataset formats (dexcanvas_core.capture.formats) and the up estimate.

Every file here is synthetic, written in the datasets' layouts with known ground truth (a hand
posed by our ManoLayer, a box object on a tilted table); no dataset file is used or stored.
"""

from __future__ import annotations

import os
import pickle
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from dexcanvas_core.capture.formats import READERS, read_dexycb, read_ho3d, read_taco
from dexcanvas_core.capture.formats._common import valid_runs
from dexcanvas_core.capture.formats.ho3d import dexycb_export_rotation
from dexcanvas_core.capture.up import consensus_up, estimate_up
from dexcanvas_core.errors import UnknownNameError, ValidationError
from dexcanvas_core.keypoints import FINGERS, convert_keypoints
from dexcanvas_core.mano import MANO_MODEL_DIR_ENV, MANO_TIP_VERTEX_IDS, ManoLayer
from dexcanvas_core.safe_pickle import load_pickle

BOX = (0.06, 0.04, 0.10)  # extents [m]; rests on its -z face (object frame)
UP = np.array([0.25, -0.8, -0.55]) / np.linalg.norm([0.25, -0.8, -0.55])  # a camera-frame up
TABLE = -0.7  # table height along UP [m]


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(
        np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))
    )


def box_vertices() -> np.ndarray:
    return np.asarray(trimesh.creation.box(extents=BOX).vertices)


def write_box(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    trimesh.creation.box(extents=BOX).export(path)
    return path


def object_track(T: int = 24, rest: int = 6, up: np.ndarray = UP, lift_tilt_deg: float = 30.0):
    """A box resting on its -z face on a table (normal ``up``, height ``TABLE``) for ``rest``
    frames, then lifted 0.25 m along a direction ``lift_tilt_deg`` off ``up``, turning a little.
    Returns positions (T, 3) and rotations (T, 3, 3)."""
    spin = Rotation.from_rotvec([0, 0, 0.7])
    align, _ = Rotation.align_vectors([up], [[0.0, 0.0, 1.0]])
    R0 = align * spin
    side = np.cross(up, [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    tilt = np.radians(lift_tilt_deg)
    lift = np.cos(tilt) * up + np.sin(tilt) * side
    s = np.clip((np.arange(T) - rest + 1) / max(T - rest, 1), 0, 1) * 0.25
    centre0 = up * (TABLE + BOX[2] / 2) + 0.3 * side
    pos = centre0 + s[:, None] * lift
    turn = Rotation.from_rotvec(np.outer(s, [0.3, 0.0, 0.5]))
    rots = (turn * R0).as_matrix()
    return pos, rots


def hand_sequence(side: str, T: int, seed: int = 0):
    """Global orientation, 45-D pose, translation, keypoints (MANO21) of a moving hand."""
    rng = np.random.default_rng(seed)
    go = rng.normal(0, 0.4, 3) + np.linspace(0, 0.3, T)[:, None]
    pose = rng.normal(0, 0.2, 45) + np.linspace(0, 0.2, T)[:, None]
    transl = np.array([0.05, -0.1, 0.6]) + np.linspace(0, 0.1, T)[:, None]
    out = ManoLayer(side=side).forward_numpy(global_orient=go, hand_pose=pose, transl=transl)
    return go, pose, transl, out.keypoints


def dump(obj, path: Path, protocol: int = 4) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(pickle.dumps(obj, protocol=protocol))


# -- restricted pickles ------------------------------------------------------------------------


class _Evil:
    def __reduce__(self):
        return (os.system, ("true",))


def test_restricted_pickle_reads_arrays(tmp_path):
    data = {"a": np.arange(6.0).reshape(2, 3), "b": np.float32(2.5), "s": "x", "n": None}
    for protocol in (2, 4, 5):
        dump(data, tmp_path / f"p{protocol}.pkl", protocol)
        back = load_pickle(tmp_path / f"p{protocol}.pkl")
        np.testing.assert_array_equal(back["a"], data["a"])
        assert back["s"] == "x" and back["n"] is None and back["b"] == np.float32(2.5)


def test_restricted_pickle_refuses_os_system(tmp_path):
    path = tmp_path / "evil.pkl"
    dump({"handPose": _Evil()}, path)
    with pytest.raises(ValidationError, match=r"refusing to load global (posix|os|nt)\.system"):
        load_pickle(path, what="HO-3D meta file")
    # the same file as a frame of a sequence: refused, naming the file
    dump({"handPose": _Evil()}, tmp_path / "seq" / "meta" / "0000.pkl")
    with pytest.raises(ValidationError, match=r"0000\.pkl.*refusing to load global"):
        read_ho3d(tmp_path / "seq", models_dir=tmp_path)


def test_restricted_pickle_missing_and_garbage(tmp_path):
    with pytest.raises(ValidationError, match="not found"):
        load_pickle(tmp_path / "nope.pkl")
    (tmp_path / "bad.pkl").write_bytes(b"not a pickle")
    with pytest.raises(ValidationError, match=r"bad\.pkl"):
        load_pickle(tmp_path / "bad.pkl")


# -- up estimate --------------------------------------------------------------------------------


def test_estimate_up_box_on_tilted_table():
    pos, rots = object_track()
    quat = Rotation.from_matrix(rots).as_quat(scalar_first=True)
    e = estimate_up(box_vertices(), pos, quat)
    assert angle_deg(e.up, UP) < 0.1
    assert e.table_height == pytest.approx(TABLE, abs=1e-6)
    assert e.lift_up_angle_deg == pytest.approx(30.0, abs=8.0)  # the turn skews the centroid
    assert e.support_area_m2 == pytest.approx(BOX[0] * BOX[1], rel=1e-6)
    assert e.confidence > 0.7 and "stable" in e.reason


def test_estimate_up_static_object_needs_up():
    pos, rots = object_track(T=10, rest=10)
    quat = Rotation.from_matrix(rots).as_quat(scalar_first=True)
    with pytest.raises(ValidationError, match=r"moves at most 0\.0 mm.*give the up direction"):
        estimate_up(box_vertices(), pos, quat, where="seq7")
    e = estimate_up(box_vertices(), pos, quat, up=UP * 3)
    assert np.allclose(e.up, UP) and e.table_height == pytest.approx(TABLE)


def test_estimate_up_flags_hand_below_table():
    pos, rots = object_track()
    quat = Rotation.from_matrix(rots).as_quat(scalar_first=True)
    hand = np.repeat((pos[:, None] - UP * 0.2), 2, axis=1)  # 15 cm under the table
    e = estimate_up(box_vertices(), pos, quat, hand_points=hand)
    assert e.hand_below_table_m == pytest.approx(0.15, abs=1e-6)
    assert "below the table" in e.reason


def test_estimate_up_checks_inputs():
    with pytest.raises(ValidationError, match="object_quat_wxyz must have shape"):
        estimate_up(box_vertices(), np.zeros((3, 3)), np.zeros((2, 4)))
    with pytest.raises(ValidationError, match="no 3-D convex hull"):
        flat = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float) * 0.1
        pos, rots = object_track()
        estimate_up(flat, pos, Rotation.from_matrix(rots).as_quat(scalar_first=True))


def test_consensus_up_ignores_outliers_and_missing():
    rng = np.random.default_rng(1)
    ups = [UP + rng.normal(0, 0.02, 3) for _ in range(8)]
    ups += [np.array([1.0, 0, 0]), np.array([0, 0, 1.0]), None]
    shared = consensus_up(ups)
    assert angle_deg(shared.up, UP) < 1.0
    assert shared.supporters.tolist() == [True] * 8 + [False] * 3
    assert np.isnan(shared.angles_deg[-1])
    with pytest.raises(ValidationError, match="no shared up direction: 1 of 3"):
        consensus_up([UP, np.array([1.0, 0, 0]), np.array([0, 0, 1.0])], where="subject-1")


def test_valid_runs():
    assert valid_runs(np.array([0, 1, 1, 0, 1, 1, 1, 0, 1], bool)) == [(1, 3), (4, 7)]
    assert valid_runs(np.ones(4, bool), min_frames=5) == []


# -- ho3d ---------------------------------------------------------------------------------------


def exporter_rotvec(quat_xyzw: np.ndarray) -> np.ndarray:
    """What the DexYCB-to-HO-3D exporter stores: the quaternion (x, y, z, w) read as (w, x, y, z)
    and turned into a rotation vector (angle 2·atan(|v|/w))."""
    e0, e = quat_xyzw[:, 0], quat_xyzw[:, 1:]
    n = np.linalg.norm(e, axis=1)
    return e / n[:, None] * (2 * np.arctan(n / e0))[:, None]


def write_ho3d_sequence(
    folder: Path,
    *,
    side: str = "right",
    export: bool = False,
    T: int = 24,
    blank: int = 2,
    static: bool = False,
    seed: int = 0,
    pca: tuple[np.ndarray, np.ndarray] | None = None,
) -> dict:
    """Write ``folder/meta/NNNN.pkl`` with a posed hand and the box; the first ``blank`` frames
    carry no hand (HO-3D: None values; DexYCB export: zeros). Returns the ground truth."""
    go, pose, transl, kp = hand_sequence(side, T, seed)
    pos, rots = object_track(T=T, rest=T if static else 6)
    quat_xyzw = Rotation.from_matrix(rots).as_quat()
    stored_pose = pose
    if export:
        comps, mean = pca
        stored_pose = (pose - mean) @ np.linalg.inv(comps)  # PCA coefficients of the pose
        rot = exporter_rotvec(quat_xyzw)
    else:
        rot = Rotation.from_quat(quat_xyzw).as_rotvec()
    betas = np.linspace(-0.5, 0.5, 10)
    for i in range(T):
        d = {
            "handPose": np.concatenate([go[i], stored_pose[i]]).astype(np.float32),
            "handTrans": transl[i].astype(np.float32),
            "handBeta": betas.astype(np.float32),
            "handJoints3D": kp[i],
            "objRot": rot[i] if export else rot[i].reshape(3, 1),
            "objTrans": pos[i],
            "objName": "010_box",
        }
        if export:
            d.update(side=side, frame=i, order="HO3D", seqName=str(folder))
            if i < blank:
                d["handPose"] = np.zeros(48, np.float32)
                d["handTrans"] = np.zeros(3, np.float32)
        elif i < blank:
            d.update(handPose=None, handTrans=None, handJoints3D=None)
        dump(d, folder / "meta" / f"{i:04d}.pkl")
    return dict(go=go, pose=pose, transl=transl, kp=kp, pos=pos, quat_xyzw=quat_xyzw, betas=betas)


def fake_mano_pca(folder: Path, side: str, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """A tiny stand-in for MANO_<SIDE>.pkl holding only the PCA basis (random, orthogonal)."""
    rng = np.random.default_rng(seed)
    comps = np.linalg.qr(rng.normal(size=(45, 45)))[0] * 0.5
    mean = rng.normal(0, 0.2, 45)
    dump({"hands_components": comps, "hands_mean": mean}, folder / f"MANO_{side.upper()}.pkl", 2)
    return comps, mean


def test_read_ho3d_synthetic_sequence(tmp_path):
    truth = write_ho3d_sequence(tmp_path / "train" / "ABF10")
    write_box(tmp_path / "models" / "010_box" / "textured_simple.obj")
    (d,) = read_ho3d(tmp_path / "train" / "ABF10", models_dir=tmp_path / "models")
    k = slice(2, None)  # the two frames without a hand are dropped
    assert d["source"].endswith("ABF10#2-24") and d["source"].startswith("ho3d:")
    np.testing.assert_allclose(d["global_orient"], truth["go"][k], atol=1e-6)
    np.testing.assert_allclose(d["hand_pose"], truth["pose"][k], atol=1e-6)
    np.testing.assert_allclose(d["transl"], truth["transl"][k], atol=1e-6)
    np.testing.assert_allclose(d["keypoints"], convert_keypoints(truth["kp"][k], "mano21",
                                                                 "openpose21"))  # fmt: skip
    np.testing.assert_allclose(d["betas"], truth["betas"], atol=1e-6)
    np.testing.assert_allclose(d["object_pos"], truth["pos"][k])
    q = Rotation.from_quat(d["object_quat_wxyz"], scalar_first=True)
    assert (q.inv() * Rotation.from_quat(truth["quat_xyzw"][k])).magnitude().max() < 1e-9
    assert d["flat_hand_mean"] is True and d["hand_side"] == "right" and d["fps"] == 30.0
    assert d["object_name"] == "010_box" and d["object_mesh"].endswith("textured_simple.obj")
    assert angle_deg(d["up_axis"], UP) < 0.1 and d["table_height"] == pytest.approx(TABLE)
    # the hand keypoints are MANO21 joints of the pose with wrist = J0 + transl
    fk = ManoLayer(side="right").forward_numpy(
        global_orient=d["global_orient"], hand_pose=d["hand_pose"], transl=d["transl"]
    )
    np.testing.assert_allclose(
        fk.keypoints, convert_keypoints(d["keypoints"], "openpose21", "mano21"), atol=1e-6
    )  # float32 pose


def test_read_ho3d_dexycb_export(tmp_path, monkeypatch):
    monkeypatch.delenv(MANO_MODEL_DIR_ENV, raising=False)
    pca = fake_mano_pca(tmp_path / "mano", "left")
    subject = tmp_path / "left" / "20200709-subject-01"
    truths = [
        write_ho3d_sequence(subject / f"seq{i}", side="left", export=True, seed=i, pca=pca)
        for i in range(3)
    ]
    # a fourth sequence whose object never moves: its up comes from the other three
    truths.append(
        write_ho3d_sequence(subject / "seq3", side="left", export=True, static=True, pca=pca)
    )
    write_box(tmp_path / "models" / "010_box" / "textured_meshlab.obj")
    out = read_ho3d(tmp_path / "left", models_dir=tmp_path / "models", mano_dir=tmp_path / "mano")
    assert [d["source"].split("/")[-1] for d in out] == [f"seq{i}#2-24" for i in range(4)]
    for d, truth in zip(out, truths, strict=True):
        np.testing.assert_allclose(d["hand_pose"], truth["pose"][2:], atol=1e-5)
        q = Rotation.from_quat(d["object_quat_wxyz"], scalar_first=True)
        assert (q.inv() * Rotation.from_quat(truth["quat_xyzw"][2:])).magnitude().max() < 1e-6
        assert d["hand_side"] == "left" and d["flat_hand_mean"] is True
        assert angle_deg(d["up_axis"], UP) < 0.1 and d["table_height"] == pytest.approx(TABLE)
    # the same files read as HO-3D keep the stored (wrong) rotation: the fix is the export's
    raw = exporter_rotvec(truths[0]["quat_xyzw"])
    np.testing.assert_allclose(
        Rotation.from_quat(dexycb_export_rotation(raw), scalar_first=True).as_quat(canonical=True),
        Rotation.from_quat(truths[0]["quat_xyzw"]).as_quat(canonical=True),
        atol=1e-9,
    )
    # a single static sequence has no estimate of its own
    with pytest.raises(ValidationError, match="seq3: cannot estimate the up direction"):
        read_ho3d(subject / "seq3", models_dir=tmp_path / "models", mano_dir=tmp_path / "mano")
    d = read_ho3d(
        subject / "seq3", models_dir=tmp_path / "models", mano_dir=tmp_path / "mano", up_axis=UP
    )[0]
    assert np.allclose(d["up_axis"], UP)


def test_read_ho3d_pca_without_mano_fits_the_pose(tmp_path, monkeypatch, caplog):
    """Without the MANO model that expands PCA poses, the reader gives the joints alone (and
    says so) and the import fits a pose that reproduces them."""
    from dexcanvas_core.capture import capture_from_arrays

    monkeypatch.delenv(MANO_MODEL_DIR_ENV, raising=False)
    pca = fake_mano_pca(tmp_path / "mano", "left")
    truth = write_ho3d_sequence(tmp_path / "s", side="left", export=True, pca=pca)
    write_box(tmp_path / "models" / "010_box.obj")
    with caplog.at_level("WARNING"):
        (d,) = read_ho3d(tmp_path / "s", models_dir=tmp_path / "models")
    assert "PCA coefficients" in caplog.text and "MANO_MODEL_DIR" in caplog.text
    assert "hand_pose" not in d and "global_orient" not in d and "transl" not in d
    cap = capture_from_arrays(d, name="s", mirror_left=True)
    assert cap.pose_fit_mm < 2.0
    # the fitted right hand is the mirror of the captured left one: same joints, x negated
    kp = convert_keypoints(d["keypoints"], "openpose21", "mano21")
    assert np.allclose(truth["kp"][2:], kp)


def test_read_ho3d_bad_input(tmp_path):
    write_ho3d_sequence(tmp_path / "s", blank=0)
    write_box(tmp_path / "models" / "010_box" / "textured_simple.obj")
    meta = tmp_path / "s" / "meta"
    with pytest.raises(ValidationError, match=r"no mesh for object '010_box': looked for .*"):
        read_ho3d(tmp_path / "s", models_dir=tmp_path / "elsewhere")
    with pytest.raises(ValidationError, match=r"needs its mesh.*--models-dir"):
        read_ho3d(tmp_path / "s")
    with pytest.raises(ValidationError, match=r"unknown option\(s\) \['colour'\]"):
        read_ho3d(tmp_path / "s", models_dir=tmp_path / "models", colour=1)

    def broken(change):
        d = load_pickle(meta / "0005.pkl")
        keep = dict(d)
        change(d)
        dump(d, meta / "0005.pkl")
        try:
            read_ho3d(tmp_path / "s", models_dir=tmp_path / "models")
        finally:
            dump(keep, meta / "0005.pkl")

    with pytest.raises(ValidationError, match=r"0005\.pkl: key 'handPose' has shape \(45,\)"):
        broken(lambda d: d.update(handPose=d["handPose"][:45]))
    with pytest.raises(ValidationError, match=r"0005\.pkl: no key 'handJoints3D'"):
        broken(lambda d: d.pop("handJoints3D"))
    with pytest.raises(ValidationError, match=r"0005\.pkl: key 'objTrans' has NaN"):
        broken(lambda d: d.update(objTrans=np.array([0.0, np.nan, 0.0])))
    (meta / "0007.pkl").rename(tmp_path / "moved.pkl")
    with pytest.raises(ValidationError, match=r"frames \[7\] are missing"):
        read_ho3d(tmp_path / "s", models_dir=tmp_path / "models")
    with pytest.raises(ValidationError, match="no HO-3D sequence found"):
        read_ho3d(tmp_path / "models", models_dir=tmp_path / "models")


# -- taco ---------------------------------------------------------------------------------------


def write_taco_clip(path: Path, *, side: str = "left", verts: bool = True, obj: bool = True):
    T = 20
    go, pose, transl, _ = hand_sequence(side, T, seed=4)
    layer = ManoLayer(side=side)
    out = layer.forward_numpy(global_orient=go, hand_pose=pose)
    wrist = transl  # TACO's hand_trans is the wrist joint
    z_up = np.array([0.0, 0.0, 1.0])
    pos, rots = object_track(T=T, up=z_up)
    V = box_vertices()
    box = trimesh.creation.box(extents=BOX)
    data = {
        "hand_pose": np.concatenate([go, pose], axis=1).astype(np.float32),
        "hand_trans": wrist.astype(np.float32),
        "hand_shape": np.zeros(10, np.float32),
        "obj_pose": np.concatenate(
            [
                np.concatenate([rots, pos[:, :, None]], axis=2),
                np.tile([[[0, 0, 0, 1.0]]], (T, 1, 1)),
            ],
            axis=1,
        ).astype(np.float32),
        "obj_verts": (np.einsum("tij,vj->tvi", rots, V) + pos[:, None]).astype(np.float32),
        "obj_faces": np.asarray(box.faces, np.int32),
    }
    if verts:  # only the fingertip vertices matter to the reader (side check)
        hv = np.zeros((T, 778, 3))
        tips = out.keypoints[:, 16:] - out.joints[:, :1] + wrist[:, None]
        hv[:, [MANO_TIP_VERTEX_IDS[f] for f in FINGERS]] = tips
        data["hand_verts"] = hv.astype(np.float32)
    dump(data, path)
    if obj:
        box.export(path.with_suffix(".obj"))
    return dict(go=go, pose=pose, wrist=wrist, pos=pos, rots=rots, V=V)


def test_read_taco_synthetic_clip(tmp_path):
    truth = write_taco_clip(tmp_path / "clips" / "20231104_017.pkl")
    (d,) = read_taco(tmp_path / "clips")
    assert d["hand_side"] == "left" and d["source"].startswith("taco:")
    np.testing.assert_allclose(d["global_orient"], truth["go"], atol=1e-6)
    np.testing.assert_allclose(d["hand_pose"], truth["pose"], atol=1e-6)
    np.testing.assert_allclose(d["wrist_pos"], truth["wrist"], atol=1e-6)
    assert "transl" not in d and d["flat_hand_mean"] is True and d["fps"] == 30.0
    np.testing.assert_allclose(d["object_pos"], truth["pos"], atol=1e-6)
    R = Rotation.from_quat(d["object_quat_wxyz"], scalar_first=True).as_matrix()
    np.testing.assert_allclose(R, truth["rots"], atol=1e-6)
    assert d["object_mesh"].endswith("20231104_017.obj")
    assert d["up_axis"] == "z" and d["table_height"] == pytest.approx(TABLE, abs=1e-5)
    # estimated instead of given: the same up
    (e,) = read_taco(tmp_path / "clips" / "20231104_017.pkl", up_axis=None)
    assert angle_deg(e["up_axis"], np.array([0, 0, 1.0])) < 0.1


def test_read_taco_mesh_from_frame_zero(tmp_path):
    truth = write_taco_clip(tmp_path / "c.pkl", obj=False)
    (d,) = read_taco(tmp_path / "c.pkl", side="left")
    assert "object_mesh" not in d
    np.testing.assert_allclose(d["object_vertices"], truth["V"], atol=1e-5)
    assert d["object_faces"].shape == (12, 3)


def test_read_taco_bad_input(tmp_path):
    write_taco_clip(tmp_path / "c.pkl", verts=False)
    with pytest.raises(ValidationError, match=r"no 'hand_verts'.*side='left'"):
        read_taco(tmp_path / "c.pkl")
    trimesh.creation.box(extents=(0.1, 0.1, 0.1)).export(tmp_path / "c.obj")  # not this object
    with pytest.raises(ValidationError, match=r"obj_verts differ from obj_pose applied to"):
        read_taco(tmp_path / "c.pkl", side="left")
    write_taco_clip(tmp_path / "r.pkl", side="right")
    assert read_taco(tmp_path / "r.pkl")[0]["hand_side"] == "right"
    data = load_pickle(tmp_path / "r.pkl")
    data["obj_pose"][3, :3, :3] *= 2.0
    dump(data, tmp_path / "r.pkl")
    with pytest.raises(ValidationError, match=r"r\.pkl: obj_pose is not a rigid transform"):
        read_taco(tmp_path / "r.pkl")
    data.pop("hand_trans")
    dump(data, tmp_path / "r.pkl")
    with pytest.raises(ValidationError, match=r"r\.pkl: no key 'hand_trans'"):
        read_taco(tmp_path / "r.pkl")


# -- dexycb (original release) ----------------------------------------------------------------


def write_dexycb(root: Path, pca, *, seq: str = "20200709_141754", tag: bool = True) -> dict:
    """A DexYCB data folder with one left-hand sequence grasping object id 10 (of 3 on the
    table), its calibration (betas, extrinsics with the table's AprilTag) and the model."""
    import yaml

    T = 20
    go, pose, transl, _ = hand_sequence("left", T, seed=7)
    pos, rots = object_track(T=T)
    comps, mean = pca
    pose_m = np.concatenate([go, (pose - mean) @ np.linalg.inv(comps), transl], axis=1)
    pose_m[:3] = 0.0  # no hand yet
    pose_y = np.zeros((T, 3, 7))
    pose_y[:, :, 3] = 1.0  # the other objects: untracked (identity at the origin)
    pose_y[:, 1, :4] = Rotation.from_matrix(rots).as_quat()  # x, y, z, w
    pose_y[:, 1, 4:] = pos
    folder = root / "20200709-subject-01" / seq
    folder.mkdir(parents=True)
    np.savez(folder / "pose.npz", pose_m=pose_m[:, None].astype(np.float32), pose_y=pose_y)
    meta = {
        "serials": ["836212060125"],
        "num_frames": T,
        "mano_sides": ["left"],
        "mano_calib": ["20200709-subject-01"],
        "ycb_ids": [4, 10, 13],
        "ycb_grasp_ind": 1,
        "extrinsics": "20200702_151821",
    }
    (folder / "meta.yml").write_text(yaml.safe_dump(meta))
    calib = root / "calibration"
    (calib / "mano_20200709-subject-01").mkdir(parents=True, exist_ok=True)
    betas = np.linspace(0.2, -0.2, 10)
    (calib / "mano_20200709-subject-01" / "mano.yml").write_text(
        yaml.safe_dump({"betas": betas.tolist()})
    )
    align, _ = Rotation.align_vectors([UP], [[0.0, 0.0, 1.0]])
    tag_pose = np.concatenate([align.as_matrix(), (UP * TABLE)[:, None]], axis=1)
    ext = {"master": "836212060125", "extrinsics": {"836212060125": np.eye(3, 4).ravel().tolist()}}
    if tag:
        ext["extrinsics"]["apriltag"] = tag_pose.ravel().tolist()
    (calib / "extrinsics_20200702_151821").mkdir(parents=True, exist_ok=True)
    (calib / "extrinsics_20200702_151821" / "extrinsics.yml").write_text(yaml.safe_dump(ext))
    write_box(root / "models" / "011_banana" / "textured_simple.obj")
    return dict(go=go, pose=pose, transl=transl, pos=pos, rots=rots, betas=betas)


def test_read_dexycb_synthetic(tmp_path, monkeypatch):
    monkeypatch.delenv(MANO_MODEL_DIR_ENV, raising=False)
    pca = fake_mano_pca(tmp_path / "mano", "left")
    truth = write_dexycb(tmp_path / "data", pca)
    (d,) = read_dexycb(tmp_path / "data", mano_dir=tmp_path / "mano")
    k = slice(3, None)
    assert d["source"].endswith("20200709_141754#3-20") and d["object_name"] == "011_banana"
    np.testing.assert_allclose(d["global_orient"], truth["go"][k], atol=1e-6)
    np.testing.assert_allclose(d["hand_pose"], truth["pose"][k], atol=1e-5)
    np.testing.assert_allclose(d["transl"], truth["transl"][k], atol=1e-6)
    np.testing.assert_allclose(d["betas"], truth["betas"])
    np.testing.assert_allclose(d["object_pos"], truth["pos"][k])
    R = Rotation.from_quat(d["object_quat_wxyz"], scalar_first=True).as_matrix()
    np.testing.assert_allclose(R, truth["rots"][k], atol=1e-9)
    assert d["hand_side"] == "left" and d["flat_hand_mean"] is True and d["fps"] == 30.0
    assert np.allclose(d["up_axis"], UP) and d["table_height"] == pytest.approx(TABLE)
    assert d["object_mesh"].endswith("011_banana/textured_simple.obj")
    # estimated from the object instead of the tag: the same plane
    (e,) = read_dexycb(
        tmp_path / "data" / "20200709-subject-01", mano_dir=tmp_path / "mano", up_axis=None
    )
    assert angle_deg(e["up_axis"], UP) < 0.1 and e["table_height"] == pytest.approx(TABLE)


def test_read_dexycb_errors(tmp_path, monkeypatch):
    monkeypatch.delenv(MANO_MODEL_DIR_ENV, raising=False)
    pca = fake_mano_pca(tmp_path / "mano", "left")
    write_dexycb(tmp_path / "data", pca, tag=False)
    with pytest.raises(ValidationError, match=r"PCA coefficients.*--mano-dir.*MANO_MODEL_DIR"):
        read_dexycb(tmp_path / "data", up_axis=None)
    with pytest.raises(ValidationError, match=r"extrinsics\.yml: no 'apriltag' pose"):
        read_dexycb(tmp_path / "data", mano_dir=tmp_path / "mano")
    with pytest.raises(ValidationError, match=r"no mesh for object '011_banana'"):
        read_dexycb(tmp_path / "data", models_dir=tmp_path, mano_dir=tmp_path / "mano", up_axis="z")
    with pytest.raises(ValidationError, match=r"no DexYCB sequence found"):
        read_dexycb(tmp_path / "mano")


def test_registry():
    from dexcanvas_core.capture.formats import read_mano_npz, reader_for, sequence_name

    assert READERS == {
        "mano-npz": read_mano_npz, "ho3d": read_ho3d, "taco": read_taco, "dexycb": read_dexycb
    }  # fmt: skip
    assert reader_for("MANO_NPZ") is read_mano_npz
    with pytest.raises(UnknownNameError, match="did you mean 'taco'"):
        reader_for("tako")
    assert sequence_name("ho3d:/d/left/subj/seq1#2-24", "x") == "subj_seq1_2-24"
    assert sequence_name("taco:/d/source_data/20231104_017.pkl", "x") == "source_data_20231104_017"
