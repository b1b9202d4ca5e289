"""Lance I/O against datasets built in the public layout with pyarrow directly."""

from __future__ import annotations

import shutil

import lance
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from public_layout import public_row, public_schema, write_public_dataset

from dexcanvas_core.errors import DatasetError
from dexcanvas_core.io import build_filter, export_parquet, open_dataset, write_dataset
from dexcanvas_core.io.schema import SCHEMA_VERSION_KEY


@pytest.fixture(scope="module")
def public_ds(tmp_path_factory):
    rng = np.random.default_rng(0)
    rows = [
        public_row(
            rng,
            uuid=f"u{i}",
            T=20 + 5 * i,
            scene=["cube2", "sphere1", "cube2H"][i % 3],
            gesture=["tripod", "power_sphere"][i % 2],
            operator=f"op{i % 2}",
        )
        for i in range(6)
    ]
    path = tmp_path_factory.mktemp("pub") / "public.lance"
    write_public_dataset(path, rows)
    return path, rows


def test_reads_public_layout_values(public_ds):
    path, rows = public_ds
    ds = open_dataset(path)
    assert len(ds) == 6
    trajs = list(ds.iter_trajectories())
    for row, t in zip(rows, trajs, strict=False):
        assert t.uuid == row["index"]["uuid"]
        assert t.scene == row["index"]["scene"]
        assert t.fps == 120
        np.testing.assert_allclose(t.timestamp, row["timestamp"])
        h = row["hands"][0]
        np.testing.assert_array_equal(t.hand.hand_pose, np.float32(h["mano_hand_pose"]))
        np.testing.assert_array_equal(t.hand.joint_pos, np.float32(h["mano_joint_pos"]))
        np.testing.assert_array_equal(t.object.pos, np.float32(row["objects"][0]["pos"]))
        np.testing.assert_array_equal(
            t.hand.betas, np.float32(row["trajectory_metadata"]["mano_hand_shapes"][0])
        )
        mv = row["trajectory_metadata"]["trajectory_info"]["object_move"][0]
        assert (t.object_move[0].start_frame, t.object_move[0].end_frame) == (
            mv["start_frame"],
            mv["end_frame"],
        )
        # Contacts: record count, per-pair positions and per-part totals in frame order.
        recs = [r for frame in row["contact"] for r in frame]
        assert t.contacts.num_records == len(recs)
        pairs = [p for r in recs for p in r["contact_pairs"]]
        np.testing.assert_array_equal(
            t.contacts.pairs["pos_world"],
            np.float32([p["pos_world"] for p in pairs]).reshape(-1, 3),
        )
        dense = t.contacts.dense()
        n_per_frame = [sum(len(r["contact_pairs"]) for r in f) for f in row["contact"]]
        np.testing.assert_array_equal(dense["valid"].sum(1), n_per_frame)
        totals = t.contacts.finger_totals()
        for f, frame in enumerate(row["contact"]):
            palm = [r["total_force_world"] for r in frame if r["joint_name"] == "palm"]
            want = np.sum(np.float32(palm), axis=0) if palm else np.zeros(3)
            np.testing.assert_allclose(totals[f, 5], want, rtol=1e-6)


def test_round_trip_is_lossless(public_ds, tmp_path):
    path, _ = public_ds
    ds = open_dataset(path)
    out = write_dataset(ds.iter_trajectories(), tmp_path / "copy.lance", schema=ds.schema)
    a = lance.dataset(str(path)).to_table()
    b = lance.dataset(str(out)).to_table()
    assert a.schema.equals(b.schema, check_metadata=False)
    for name in a.schema.names:
        assert a.column(name).combine_chunks().equals(b.column(name).combine_chunks()), name
    # The contract version is recorded in what we write.
    assert lance.dataset(str(out)).schema.metadata[SCHEMA_VERSION_KEY] == b"1.0"


def test_default_schema_round_trip_keeps_extras(public_ds, tmp_path):
    path, _ = public_ds
    trajs = list(open_dataset(path).iter_trajectories())
    out = write_dataset(trajs, tmp_path / "default.lance")
    again = list(open_dataset(out).iter_trajectories())
    for a, b in zip(trajs, again, strict=False):
        np.testing.assert_array_equal(a.hand.urdf_dof, b.hand.urdf_dof)
        np.testing.assert_array_equal(
            a.contacts.pairs["force_normal"], b.contacts.pairs["force_normal"]
        )
        assert b.extras["trajectory_metadata.capture_notes"].as_py() == (
            a.extras["trajectory_metadata.capture_notes"].as_py()
        )
        assert b.extras["quality_score"].as_py() == a.extras["quality_score"].as_py()


def test_28_dof_rows_read(tmp_path):
    rng = np.random.default_rng(1)
    path = tmp_path / "dof28.lance"
    write_public_dataset(path, [public_row(rng, uuid="a", dof=28)], schema=public_schema(dof=28))
    t = open_dataset(path).get(0)
    assert t.hand.urdf_dof.shape == (30, 28)


def test_filters_are_pushed_down(public_ds):
    path, _ = public_ds
    ds = open_dataset(path)
    f = build_filter(objects=["cube2"], operators=["op0"])
    assert [t.uuid for t in ds.iter_trajectories(filter=f)] == ["u0"]
    f = build_filter(manipulation_types=["power_sphere"])
    assert sorted(t.uuid for t in ds.iter_trajectories(filter=f)) == ["u1", "u3", "u5"]
    plan = ds._ds.scanner(filter=f).explain_plan()
    assert "full_filter" in plan and "gesture" in plan
    # Quotes in values are escaped, not injected.
    assert ds.count_rows(build_filter(objects=["x' OR '1'='1"])) == 0


def test_info(public_ds):
    path, rows = public_ds
    info = open_dataset(path).info()
    assert info.rows == 6
    assert info.frames == sum(r["trajectory_metadata"]["total_frames"] for r in rows)
    assert info.operators == {"op0": 3, "op1": 3}
    assert info.objects == {"cube2": 2, "sphere1": 2, "cube2H": 2}
    assert info.fps == {120: 6}
    assert info.size_bytes > 0
    assert info.has_contacts


def test_streaming_keeps_arrow_memory_flat(tmp_path):
    rng = np.random.default_rng(2)
    path = tmp_path / "big.lance"
    rows = [public_row(rng, uuid=f"r{i}", T=400) for i in range(24)]
    write_public_dataset(path, rows)
    ds = open_dataset(path)
    table_bytes = lance.dataset(str(path)).to_table().nbytes
    base = pa.total_allocated_bytes()
    peak = 0
    for t in ds.iter_trajectories(batch_size=1):
        peak = max(peak, pa.total_allocated_bytes() - base)
        assert t.num_frames == 400
    # One row of 24 at a time: far below the whole table.
    assert peak < table_bytes / 4, (peak, table_bytes)


def test_parquet_export(public_ds, tmp_path):
    path, _ = public_ds
    out = export_parquet(path, tmp_path / "out.parquet", filter=build_filter(objects=["sphere1"]))
    t = pq.read_table(out)
    assert t.num_rows == 2
    assert t.column("index").combine_chunks().field("scene").to_pylist() == ["sphere1"] * 2
    assert not list(tmp_path.glob(".*tmp*"))


# -- bad input -------------------------------------------------------------------------------


def test_missing_dataset(tmp_path):
    with pytest.raises(DatasetError, match=r"nope\.lance: no such dataset"):
        open_dataset(tmp_path / "nope.lance")


def test_partial_dataset_without_manifest(public_ds, tmp_path):
    path, _ = public_ds
    broken = tmp_path / "partial.lance"
    shutil.copytree(path, broken)
    shutil.rmtree(broken / "_versions")
    with pytest.raises(DatasetError, match=r"partial\.lance: not a Lance dataset"):
        open_dataset(broken)


def test_corrupt_data_file(public_ds, tmp_path):
    path, _ = public_ds
    broken = tmp_path / "corrupt.lance"
    shutil.copytree(path, broken)
    for f in (broken / "data").iterdir():
        f.write_bytes(f.read_bytes()[:100])
    with pytest.raises(DatasetError, match=r"corrupt\.lance.*corrupt or partially written"):
        list(open_dataset(broken).iter_trajectories())


def test_missing_column(tmp_path):
    path = tmp_path / "nohands.lance"
    lance.write_dataset(pa.table({"index": [{"uuid": "a"}], "timestamp": [[0.0]]}), str(path))
    with pytest.raises(DatasetError, match=r"nohands\.lance.*field 'trajectory_metadata'.*missing"):
        open_dataset(path)


def test_unknown_major_version(public_ds, tmp_path):
    _path, rows = public_ds
    schema = public_schema().with_metadata({SCHEMA_VERSION_KEY: b"2.0"})
    p = tmp_path / "v2.lance"
    write_public_dataset(p, rows[:1], schema=schema)
    with pytest.raises(DatasetError, match=r"schema version 2\.0 is not supported"):
        open_dataset(p)


def _bad_hand_schema(field: str, width: int) -> pa.Schema:
    s = public_schema()
    hands_t = s.field("hands").type.value_type
    fields = [
        pa.field(f.name, pa.list_(pa.list_(pa.float32(), width))) if f.name == field else f
        for f in hands_t
    ]
    return s.set(s.get_field_index("hands"), pa.field("hands", pa.list_(pa.struct(fields))))


def test_row_with_wrong_shape_names_row_and_field(tmp_path):
    rng = np.random.default_rng(3)
    rows = [public_row(rng, uuid=f"w{i}") for i in range(3)]
    for r in rows:
        r["hands"][0]["mano_hand_pose"] = [p[:45] for p in r["hands"][0]["mano_hand_pose"]]
    p = tmp_path / "shape.lance"
    write_public_dataset(p, rows, schema=_bad_hand_schema("mano_hand_pose", 45))
    with pytest.raises(
        DatasetError, match=r"shape\.lance, row 0, field 'hands\[0\]\.mano_hand_pose': wrong shape"
    ):
        list(open_dataset(p).iter_trajectories())


def test_row_with_frame_count_mismatch(tmp_path):
    rng = np.random.default_rng(4)
    rows = [public_row(rng, uuid=f"m{i}") for i in range(3)]
    rows[2]["objects"][0]["pos"] = rows[2]["objects"][0]["pos"][:-1]
    p = tmp_path / "frames.lance"
    write_public_dataset(p, rows)
    with pytest.raises(DatasetError, match=r"row 2, field 'objects\[0\]\.pos': has 29 frames"):
        list(open_dataset(p).iter_trajectories())


def test_row_with_nan_names_row_and_field(tmp_path):
    rng = np.random.default_rng(5)
    rows = [public_row(rng, uuid=f"n{i}") for i in range(2)]
    rows[1]["hands"][0]["mano_global_pos"][7][1] = float("nan")
    p = tmp_path / "nan.lance"
    write_public_dataset(p, rows)
    with pytest.raises(DatasetError, match=r"row 1, field 'mano_global_pos'.*NaN"):
        list(open_dataset(p).iter_trajectories())


def test_write_refuses_existing_and_is_atomic(public_ds, tmp_path):
    path, _ = public_ds
    trajs = list(open_dataset(path).iter_trajectories())
    out = tmp_path / "w.lance"
    write_dataset(trajs[:2], out)
    with pytest.raises(DatasetError, match="already exists"):
        write_dataset(trajs, out)

    def failing():
        yield trajs[0]
        raise RuntimeError("simulated crash")

    with pytest.raises(RuntimeError, match="simulated crash"):
        write_dataset(failing(), out, mode="overwrite")
    # The old dataset is intact and no temporary directory is left behind.
    assert [t.uuid for t in open_dataset(out).iter_trajectories()] == ["u0", "u1"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w.lance"]
    write_dataset(trajs[2:3], out, mode="append")
    assert len(open_dataset(out)) == 3


def test_write_rejects_invalid_trajectory(public_ds, tmp_path):
    path, _ = public_ds
    t = open_dataset(path).get(0)
    t.timestamp[5] = t.timestamp[4]
    with pytest.raises(Exception, match="strictly increasing"):
        write_dataset([t], tmp_path / "bad.lance")
    assert not (tmp_path / "bad.lance").exists()
