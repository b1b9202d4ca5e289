"""``retarget export``: each format read back by its consumer's reader (MuJoCo, h5py, pyarrow)
and checked against the run it was made from; whole-or-nothing writing."""

from __future__ import annotations

import json
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import mujoco
import numpy as np
import pyarrow.parquet as pq
import pytest

import retarget.export as export_pkg
from dexcanvas_core import load_demonstration
from dexcanvas_core.exits import EXIT_OK
from dexcanvas_core.io import write_dataset
from dexcanvas_core.rotations import aa_to_quat_wxyz
from dexcanvas_core.safe_io import OutputExistsError
from retarget.batch import BatchConfig, run_batch
from retarget.cli import main
from retarget.cli_args import EXPORT_FORMATS
from retarget.export import FORMATS, ExportError, export, load_export_source
from retarget.hands import get_hand

FRAMES = 60


@pytest.fixture(scope="session")
def clip(tmp_path_factory) -> Path:
    """The first 60 frames of the built-in cube2/tripod demonstration, as a dataset."""
    data = tmp_path_factory.mktemp("export_data") / "clip.lance"
    write_dataset([load_demonstration("cube2/tripod").slice(0, FRAMES)], data)
    return data


@pytest.fixture(scope="session")
def run_dir(clip, tmp_path_factory) -> Path:
    """A ``retarget run`` directory: panda on ``clip``."""
    data = clip
    out = tmp_path_factory.mktemp("export_run") / "run"
    argv = ["run", "--hand", "panda", "--pair", "cube2/tripod", "--dataset", str(data)]
    assert main([*argv, "--out", str(out), "--quiet"]) == EXIT_OK
    return out


@pytest.fixture(scope="session")
def source(run_dir):
    return load_export_source(run_dir)


def test_source_reads_the_run(source, run_dir):
    z = np.load(run_dir / "robot_trajectory.npz")
    assert source.hand == "panda" and source.num_frames == FRAMES
    np.testing.assert_array_equal(source.q_command, z["q_command"])
    np.testing.assert_array_equal(source.q_sim, z["q_sim"])
    assert source.joint_names == list(z["joint_names"]) and source.object_id == "cube2"


def test_source_errors(tmp_path):
    with pytest.raises(ExportError, match="does not exist"):
        load_export_source(tmp_path / "nothing")
    with pytest.raises(ExportError, match="exactly one"):
        load_export_source()
    with pytest.raises(ExportError, match="exactly one"):
        load_export_source(tmp_path, dataset=tmp_path / "b.lance", row=0)


@pytest.fixture(scope="session")
def batch_dataset(clip, tmp_path_factory) -> Path:
    """A ``retarget batch`` robot dataset of the same clip and hand as ``run_dir``."""
    out = tmp_path_factory.mktemp("export_batch") / "B.lance"
    summary = run_batch(BatchConfig(hands=("panda",), out=out, dataset=clip, progress=False))
    assert summary["ran"] == 1 and summary["failed"] == 0
    return out


@pytest.fixture(scope="session")
def batch_source(batch_dataset):
    return load_export_source(dataset=batch_dataset, row=0)


def test_robot_dataset_row_is_the_same_source_as_the_run(batch_source, source, batch_dataset):
    """``retarget batch`` and ``retarget run`` of one clip: the export sources agree."""
    for name in ("q", "q_command", "q_sim", "object_pos", "object_rot_aa", "tip_pos",
                 "finger_force", "timestamp"):  # fmt: skip
        np.testing.assert_array_equal(getattr(batch_source, name), getattr(source, name), name)
    assert (batch_source.hand, batch_source.joint_names, batch_source.object_id) == (
        source.hand, source.joint_names, source.object_id,
    )  # fmt: skip
    with pytest.raises(ExportError, match="rows"):
        load_export_source(dataset=batch_dataset, row=5)


def test_cli_exports_a_robot_dataset_row(batch_dataset, tmp_path, capsys):
    """``retarget export --dataset B.lance --row 0``; a row that is not there is exit 2."""
    out = tmp_path / "row0.hdf5"
    argv = ["export", "--dataset", str(batch_dataset), "--format", "robomimic"]
    assert main([*argv, "--row", "0", "--out", str(out)]) == EXIT_OK
    with h5py.File(out, "r") as f:
        assert f["data/demo_0/actions"].shape[0] == FRAMES
    assert main([*argv, "--row", "3", "--out", str(tmp_path / "x.hdf5")]) == 2
    assert "--row 3 is not one of them" in capsys.readouterr().err


@pytest.mark.parametrize("fmt", FORMATS)
def test_robot_dataset_row_exports_to_every_format(fmt, batch_source, tmp_path):
    out = export(batch_source, fmt, tmp_path / f"row.{'hdf5' if fmt == 'robomimic' else 'd'}")
    if fmt == "mujoco":
        m = mujoco.MjModel.from_xml_path(str(out / "scene.xml"))
        assert m.nkey == FRAMES
        np.testing.assert_array_equal(m.key_qpos[:, : len(batch_source.joint_names)],
                                      batch_source.q_sim)  # fmt: skip
    elif fmt == "robomimic":
        with h5py.File(out, "r") as f:
            np.testing.assert_array_equal(f["data/demo_0/actions"][()], batch_source.q_command)
    else:
        t = pq.read_table(next((out / "data").rglob("*.parquet")))
        assert t.num_rows == FRAMES


# ---------------------------------------------------------------------------- mujoco


@pytest.fixture(scope="session")
def mujoco_dir(source, tmp_path_factory) -> Path:
    """The MuJoCo export, moved away from where it was written (self-contained)."""
    out = export(source, "mujoco", tmp_path_factory.mktemp("mj") / "scene")
    moved = tmp_path_factory.mktemp("mj_moved") / "scene"
    shutil.move(out, moved)
    return moved


def test_mujoco_scene_loads_with_a_key_per_frame(mujoco_dir, source):
    m = mujoco.MjModel.from_xml_path(str(mujoco_dir / "scene.xml"))
    nq_hand = len(source.joint_names)
    assert m.nkey == FRAMES and m.nq == nq_hand + 7  # the hand, then the object's free joint
    np.testing.assert_array_equal(m.key_qpos[:, :nq_hand], source.q_sim)
    np.testing.assert_array_equal(m.key_qpos[:, nq_hand : nq_hand + 3], source.object_pos)
    np.testing.assert_allclose(
        m.key_qpos[:, nq_hand + 3 :], aa_to_quat_wxyz(source.object_rot_aa), atol=1e-15
    )
    np.testing.assert_array_equal(m.key_time, source.timestamp)
    z = np.load(mujoco_dir / "trajectory.npz")
    np.testing.assert_array_equal(z["qpos"], m.key_qpos)
    np.testing.assert_array_equal(z["ctrl"], m.key_ctrl)
    assert all((mujoco_dir / f.get("file")).is_file() for f in _meshes(mujoco_dir))


def _meshes(d: Path):
    return [e for e in ET.parse(d / "scene.xml").getroot().iter("mesh") if e.get("file")]


def test_mujoco_fingertips_where_the_run_says(mujoco_dir, source):
    """A key's fingertip sites sit where the hand model puts them at ``q_sim``; the
    retargeted ``q_kinematic`` puts them at the run's ``tip_pos_world`` (within 1e-6 m)."""
    m = mujoco.MjModel.from_xml_path(str(mujoco_dir / "scene.xml"))
    d = mujoco.MjData(m)
    hm = get_hand(source.hand).compile()
    hd = mujoco.MjData(hm)
    sites = [m.site(s).id for s in source.tip_sites]
    hsites = [hm.site(s).id for s in source.tip_sites]
    z = np.load(mujoco_dir / "trajectory.npz")
    nq_hand = len(source.joint_names)
    for t in range(0, FRAMES, 5):
        mujoco.mj_resetDataKeyframe(m, d, t)
        mujoco.mj_forward(m, d)
        hd.qpos[:] = source.q_sim[t]
        mujoco.mj_kinematics(hm, hd)
        np.testing.assert_allclose(d.site_xpos[sites], hd.site_xpos[hsites], atol=1e-6)
        np.testing.assert_allclose(d.xpos[m.body("object").id], source.object_pos[t], atol=1e-12)
        d.qpos[:nq_hand] = z["q_kinematic"][t]
        mujoco.mj_forward(m, d)
        np.testing.assert_allclose(d.site_xpos[sites], source.tip_pos[t], atol=1e-6)


# ---------------------------------------------------------------------------- robomimic


def test_robomimic_layout(source, tmp_path):
    """The fields robomimic's SequenceDataset reads: data.attrs total and env_args (JSON with
    env_name, type, env_kwargs), demo_i.attrs num_samples, actions, rewards, dones, states,
    obs/<key> and next_obs/<key> of num_samples rows; mask/<split> the demo names."""
    path = export(source, "robomimic", tmp_path / "demo.hdf5")
    with h5py.File(path, "r") as f:
        data = f["data"]
        assert list(data.keys()) == ["demo_0"] and int(data.attrs["total"]) == FRAMES
        env = json.loads(data.attrs["env_args"])
        assert {"env_name", "type", "env_kwargs"} <= env.keys()
        assert env["env_kwargs"]["joint_names"] == source.joint_names
        demo = data["demo_0"]
        n = int(demo.attrs["num_samples"])
        assert n == FRAMES
        np.testing.assert_array_equal(demo["actions"][()], source.q_command)
        assert demo["rewards"].shape == (n,) and demo["dones"].shape == (n,)
        assert demo["dones"][-1] == 1 and demo["dones"][:-1].sum() == 0
        assert demo["states"].shape == (n, len(source.joint_names) + 7)
        nq = len(source.joint_names)
        shapes = {
            "joint_pos": (n, nq),
            "joint_vel": (n, nq),
            "object_pos": (n, 3),
            "object_quat": (n, 4),
            "fingertip_pos": (n, len(source.tip_sites), 3),
        }
        for group in ("obs", "next_obs"):
            for k, shape in shapes.items():
                assert demo[f"{group}/{k}"].shape == shape, (group, k)
        np.testing.assert_array_equal(demo["obs/joint_pos"][()], source.q_sim)
        np.testing.assert_array_equal(demo["next_obs/joint_pos"][:-1], source.q_sim[1:])
        np.testing.assert_array_equal(demo["obs/fingertip_pos"][()], source.tip_pos)
        assert [s.decode() for s in f["mask/train"][()]] == ["demo_0"]


# ---------------------------------------------------------------------------- lerobot


def test_lerobot_v3_layout(source, tmp_path):
    """meta/info.json, stats.json, tasks.parquet, episodes and data parquet files at the
    paths of LeRobot v3.0, their columns the features info.json declares."""
    root = export(source, "lerobot", tmp_path / "ds")
    info = json.loads((root / "meta/info.json").read_text())
    assert info["codebase_version"] == "v3.0" and info["fps"] == 120
    assert info["total_episodes"] == 1 and info["total_frames"] == FRAMES
    data_path = root / info["data_path"].format(chunk_index=0, file_index=0)
    assert data_path == root / "data/chunk-000/file-000.parquet"
    table = pq.read_table(data_path)
    assert table.num_rows == FRAMES
    assert set(table.column_names) == set(info["features"])
    for name, ft in info["features"].items():
        typ = table.schema.field(name).type
        if ft["shape"] != [1]:  # a vector per frame: a fixed-size list of the feature's dtype
            assert np.stack(table.column(name).to_pylist()).shape == (FRAMES, *ft["shape"])
            typ = typ.value_type
        assert typ.to_pandas_dtype() == np.dtype(ft["dtype"]), name
    nq = len(source.joint_names)
    assert info["features"]["observation.state"]["shape"] == [nq]
    assert info["features"]["action"]["names"] == source.joint_names
    state = np.stack(table.column("observation.state").to_pylist())
    action = np.stack(table.column("action").to_pylist())
    np.testing.assert_array_equal(state, source.q_sim.astype(np.float32))
    np.testing.assert_array_equal(action, source.q_command.astype(np.float32))
    np.testing.assert_array_equal(table.column("index").to_numpy(), np.arange(FRAMES))
    ts = table.column("timestamp").to_numpy()  # LeRobot: per episode from 0, 1/fps apart
    assert ts[0] == 0 and np.abs(np.diff(ts) - 1 / info["fps"]).max() < 1e-4
    episodes = pq.read_table(root / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    assert len(episodes) == 1
    ep = episodes[0]
    assert ep["episode_index"] == 0 and ep["length"] == FRAMES
    assert (ep["dataset_from_index"], ep["dataset_to_index"]) == (0, FRAMES)
    assert (ep["data/chunk_index"], ep["data/file_index"]) == (0, 0)
    tasks = pq.read_table(root / "meta/tasks.parquet")
    assert tasks.column("task_index").to_pylist() == [0]
    assert tasks.column("__index_level_0__").to_pylist() == ep["tasks"]
    assert b"pandas" in tasks.schema.metadata  # read by pandas with the task as the index
    stats = json.loads((root / "meta/stats.json").read_text())
    assert set(stats) == set(info["features"])
    assert len(stats["action"]["mean"]) == nq and stats["action"]["count"] == [FRAMES]


# ---------------------------------------------------------------------------- writing


@pytest.mark.parametrize("fmt", FORMATS)
def test_existing_output_kept_without_overwrite(fmt, source, tmp_path):
    out = tmp_path / ("o.hdf5" if fmt == "robomimic" else "o")
    export(source, fmt, out)
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    with pytest.raises(OutputExistsError, match="--overwrite"):
        export(source, fmt, out)
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before
    export(source, fmt, out, overwrite=True)
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before


def test_failed_export_leaves_the_old_output(source, tmp_path, monkeypatch):
    out = export(source, "lerobot", tmp_path / "ds")
    info = (out / "meta/info.json").read_text()

    def broken(src, root):
        (root / "half.parquet").write_text("half")
        raise OSError("disk full")

    monkeypatch.setattr(export_pkg, "write_lerobot", broken)
    with pytest.raises(OSError, match="disk full"):
        export(source, "lerobot", out, overwrite=True)
    assert (out / "meta/info.json").read_text() == info
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]  # no temporary left


def test_cli(run_dir, tmp_path, capsys):
    assert EXPORT_FORMATS == FORMATS
    out = tmp_path / "demo.hdf5"
    assert main(["export", str(run_dir), "--format", "robomimic", "--out", str(out)]) == 0
    assert out.is_file() and str(out) in capsys.readouterr().out
    assert main(["export", str(run_dir), "--format", "robomimic", "--out", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main(["export", str(tmp_path / "x"), "--format", "mujoco", "--out", "y"]) == 2
    assert "does not exist" in capsys.readouterr().err
