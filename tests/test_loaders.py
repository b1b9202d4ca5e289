"""DexCanvasDataset, collate_trajectories and make_dataloader on public-layout datasets."""

from __future__ import annotations

import pickle

import lance
import numpy as np
import pyarrow as pa
import pytest
import torch
from public_layout import public_row, public_schema, write_public_dataset

from dexcanvas_core.errors import DatasetError, UnknownNameError, ValidationError
from dexcanvas_core.io import open_dataset, write_dataset
from dexcanvas_core.loaders import (
    DexCanvasDataset,
    collate_trajectories,
    make_dataloader,
)

# uuid: (T, scene, gesture as stored, operator, has contacts)
ROWS = {
    "u0": (20, "cube2", "tripod", "op0", True),
    "u1": (35, "sphere1", "001-Palmar-Pinch", "op1", True),
    "u2": (27, "cube2H", "01", "op0", True),
    # second fragment (appended): row ids and row positions differ from here on
    "u3": (12, "cube2", "palmar_pinch", "op1", False),
    "u4": (16, "cylinder1", "003-Prismatic-3-Finger", "op2", True),
}


@pytest.fixture(scope="module")
def pub(tmp_path_factory):
    rng = np.random.default_rng(0)
    rows = []
    for uuid, (T, scene, gesture, op, contacts) in ROWS.items():
        row = public_row(rng, uuid=uuid, T=T, scene=scene, gesture=gesture, operator=op)
        if not contacts:
            row["contact"] = None
        rows.append(row)
    path = tmp_path_factory.mktemp("loaders") / "pub.lance"
    write_public_dataset(path, rows[:3])
    lance.write_dataset(
        pa.Table.from_pylist(rows[3:], schema=public_schema()), str(path), mode="append"
    )
    return path


@pytest.fixture(scope="module")
def trajs(pub):
    return {t.uuid: t for t in open_dataset(pub).iter_trajectories()}


@pytest.fixture(scope="module")
def ds(pub):
    return DexCanvasDataset(pub)


def test_len_uuids_and_positions_follow_dataset_order(ds):
    assert len(ds) == 5
    assert ds.uuids == tuple(ROWS)
    np.testing.assert_array_equal(ds.positions, np.arange(5))


def test_item_holds_the_trajectory_as_float32_tensors(ds, trajs):
    for i, uuid in enumerate(ROWS):
        s, t = ds[i], trajs[uuid]
        T = ROWS[uuid][0]
        assert s["finger_pose"].shape == (T, 45) and s["finger_pose"].dtype == torch.float32
        assert s["wrist_pose"].shape == (T, 6) and s["object_pose"].shape == (T, 6)
        assert s["timestamp"].dtype == torch.float64
        np.testing.assert_array_equal(s["finger_pose"].numpy(), t.hand.hand_pose[:, 3:])
        np.testing.assert_array_equal(s["wrist_pose"].numpy(), t.wrist_pose)
        np.testing.assert_array_equal(s["object_pose"].numpy(), t.object_pose)
        np.testing.assert_array_equal(s["timestamp"].numpy(), t.timestamp)
        np.testing.assert_array_equal(s["joint_pos"].numpy(), t.hand.joint_pos)
        if ROWS[uuid][4]:
            assert s["contact_force"].shape == (T, 6, 3)
            np.testing.assert_array_equal(s["contact_force"].numpy(), t.contacts.finger_totals())
            assert s["contact_force"].abs().sum() > 0
        else:
            assert "contact_force" not in s
        assert "object_wrench" not in s
        assert s["meta"]["uuid"] == uuid
        assert s["meta"]["scene"] == ROWS[uuid][1]
        assert s["meta"]["gesture"] == ROWS[uuid][2]
        assert s["meta"]["operator"] == ROWS[uuid][3]
    assert ds[-1]["meta"]["uuid"] == "u4"
    with pytest.raises(IndexError):
        ds[5]


def test_meta_names_the_manipulation_type(ds):
    assert [ds[i]["meta"]["manipulation_type"] for i in range(4)] == [
        "tripod", "palmar_pinch", "palmar_pinch", "palmar_pinch",
    ]  # fmt: skip
    assert ds[4]["meta"]["manipulation_type"] == "003-Prismatic-3-Finger"  # unknown: as stored


def test_collate_pads_with_zeros_and_masks(ds):
    samples = [ds[0], ds[1], ds[2]]  # T = 20, 35, 27
    b = collate_trajectories(samples)
    assert b["finger_pose"].shape == (3, 35, 45)
    assert b["wrist_pose"].shape == (3, 35, 6)
    assert b["object_pose"].shape == (3, 35, 6)
    assert b["contact_force"].shape == (3, 35, 6, 3)
    assert b["attention_mask"].shape == (3, 35) and b["attention_mask"].dtype == torch.bool
    assert b["lengths"].tolist() == [20, 35, 27]
    assert b["attention_mask"].sum(1).tolist() == [20, 35, 27]
    for k, s in enumerate(samples):
        T = s["finger_pose"].shape[0]
        assert b["attention_mask"][k, :T].all() and not b["attention_mask"][k, T:].any()
        for key in ("finger_pose", "wrist_pose", "object_pose", "contact_force", "timestamp"):
            torch.testing.assert_close(b[key][k, :T], s[key], rtol=0, atol=0)
            assert (b[key][k, T:] == 0).all()
    assert b["has_contact_force"].tolist() == [True, True, True]
    assert b["meta"]["uuid"] == ["u0", "u1", "u2"]


def test_collate_with_contacts_on_some_samples_only(ds):
    b = collate_trajectories([ds[0], ds[3]])  # u3 has no contacts
    assert b["contact_force"].shape == (2, 20, 6, 3)
    assert b["has_contact_force"].tolist() == [True, False]
    assert (b["contact_force"][1] == 0).all()
    assert b["contact_force"][0].abs().sum() > 0


def test_dataset_without_contacts_serves_no_contact_force(tmp_path, trajs):
    rng = np.random.default_rng(1)
    src = [trajs["u0"], trajs["u3"]]
    for t in src:
        t.contacts = None
        t.object_wrench_world = rng.normal(size=(t.num_frames, 6)).astype(np.float32)
    path = write_dataset(src, tmp_path / "nocontact.lance")
    d = DexCanvasDataset(path)
    s = d[0]
    assert "contact_force" not in s
    np.testing.assert_array_equal(s["object_wrench"].numpy(), src[0].object_wrench_world)
    b = collate_trajectories([d[0], d[1]])
    assert "contact_force" not in b and "has_contact_force" not in b
    assert b["object_wrench"].shape == (2, 20, 6)
    assert b["has_object_wrench"].tolist() == [True, True]


@pytest.mark.parametrize(
    ("kwargs", "expected"),
    [
        ({"objects": "cube2"}, ["u0", "u3"]),
        ({"objects": ["sphere1", "cylinder1"]}, ["u1", "u4"]),
        ({"operators": ["op1"]}, ["u1", "u3"]),
        ({"operators": ["op0", "op2"]}, ["u0", "u2", "u4"]),
        ({"manipulation_types": "tripod"}, ["u0"]),
        # a stored gesture the catalogue does not know is accepted as stored
        ({"manipulation_types": ["003-Prismatic-3-Finger"]}, ["u4"]),
        ({"objects": "cube2", "operators": "op1"}, ["u3"]),
        ({"manipulation_types": [], "objects": None}, list(ROWS)),
    ],
)
def test_filters_select_the_right_rows(pub, kwargs, expected):
    assert list(DexCanvasDataset(pub, **kwargs).uuids) == expected


@pytest.mark.parametrize("spelling", ["palmar_pinch", "Palmar-Pinch", 1, "01", "pad_pinch"])
def test_manipulation_type_filter_matches_every_stored_spelling(pub, spelling):
    # stored as "001-Palmar-Pinch", "01" and "palmar_pinch": all the same type (code 1)
    d = DexCanvasDataset(pub, manipulation_types=[spelling])
    assert list(d.uuids) == ["u1", "u2", "u3"]
    assert [d[i]["meta"]["uuid"] for i in range(len(d))] == ["u1", "u2", "u3"]


def test_object_filter_goes_through_the_catalogue(pub):
    # stored "cube2H", the paper's spelling (the catalogue's id); any case finds it
    assert list(DexCanvasDataset(pub, objects="cube2h").uuids) == ["u2"]
    assert list(DexCanvasDataset(pub, objects="Cube2H").uuids) == ["u2"]


def test_object_filter_finds_either_spelling_of_a_heavy_id(tmp_path):
    # a release may store the heavy cube as "cube2H" or "cube2h": both rows are that object
    rng = np.random.default_rng(1)
    rows = [
        public_row(rng, uuid=u, T=10, scene=scene, gesture="tripod", operator="op0")
        for u, scene in (("a", "cube2h"), ("b", "cube2H"), ("c", "cube2"))
    ]
    path = tmp_path / "heavy.lance"
    write_public_dataset(path, rows)
    for spelling in ("cube2H", "cube2h", "CUBE2H", "cube2_heavy"):
        assert sorted(DexCanvasDataset(path, objects=spelling).uuids) == ["a", "b"], spelling
    assert list(DexCanvasDataset(path, objects="cube2").uuids) == ["c"]


def test_filter_is_pushed_down_to_lance(pub):
    d = DexCanvasDataset(pub, objects="cube2", operators="op1")
    assert "index.scene IN (" in d.selection.filter
    assert "index.operator IN ('op1')" in d.selection.filter


def test_unknown_names_raise_with_suggestions(pub):
    with pytest.raises(UnknownNameError, match="did you mean 'tripod'"):
        DexCanvasDataset(pub, manipulation_types=["tripd"])
    with pytest.raises(UnknownNameError, match="did you mean 'cube2'"):
        DexCanvasDataset(pub, objects=["cub2"])


def test_unknown_operator_lists_the_datasets_operators(pub):
    with pytest.raises(UnknownNameError, match=r"unknown operator 'op9'.*op0, op1, op2"):
        DexCanvasDataset(pub, operators="op9")


def test_empty_selection_names_filters_and_contents(pub):
    with pytest.raises(DatasetError) as e:
        DexCanvasDataset(pub, manipulation_types="tripod", objects="sphere1")
    msg = str(e.value)
    assert "no trajectory matches" in msg
    assert "tripod" in msg and "sphere1" in msg
    assert "cube2 (2)" in msg and "cylinder1 (1)" in msg  # objects the dataset holds
    assert "op0 (2)" in msg and "op1 (2)" in msg and "op2 (1)" in msg
    assert "palmar_pinch (3)" in msg and "tripod (1)" in msg


def test_catalogue_object_absent_from_dataset_is_an_empty_selection(pub):
    with pytest.raises(DatasetError, match="no trajectory matches"):
        DexCanvasDataset(pub, objects="sphere2")


def test_options_active_only_fps_max_frames(pub, trajs):
    t = trajs["u1"]
    start, stop = t.active_range()
    d = DexCanvasDataset(pub, objects="sphere1", active_only=True)
    assert d[0]["finger_pose"].shape[0] == stop - start
    np.testing.assert_array_equal(d[0]["finger_pose"].numpy(), t.hand.finger_pose[start:stop])
    d = DexCanvasDataset(pub, objects="sphere1", fps=60)
    assert d[0]["finger_pose"].shape[0] == t.resample(60).num_frames
    assert d.trajectory(0).fps == 60 and d.trajectory(0, raw=True).fps == 120
    d = DexCanvasDataset(pub, max_frames=15)
    assert [d[i]["finger_pose"].shape[0] for i in range(len(d))] == [15, 15, 15, 12, 15]
    with pytest.raises(ValidationError):
        DexCanvasDataset(pub, fps=0)
    with pytest.raises(ValidationError):
        DexCanvasDataset(pub, max_frames=0)


def test_dataloader_batches_and_seeded_shuffle(ds):
    def order(seed):
        return [
            u
            for b in make_dataloader(ds, batch_size=2, shuffle=True, seed=seed)
            for u in b["meta"]["uuid"]
        ]

    first = order(3)
    assert sorted(first) == sorted(ROWS)
    assert order(3) == first
    batches = list(make_dataloader(ds, batch_size=2))
    assert [b["finger_pose"].shape[0] for b in batches] == [2, 2, 1]
    assert batches[0]["finger_pose"].shape == (2, 35, 45)
    assert batches[1]["has_contact_force"].tolist() == [True, False]
    assert (batches[0]["attention_mask"].sum(1) == batches[0]["lengths"]).all()


def test_dataset_pickles_and_reopens(ds):
    d2 = pickle.loads(pickle.dumps(ds))
    assert d2.uuids == ds.uuids
    torch.testing.assert_close(d2[1]["finger_pose"], ds[1]["finger_pose"])


def test_default_path_uses_the_builtin_dataset(monkeypatch, pub):
    import dexcanvas_core.builtin as builtin

    monkeypatch.setattr(builtin, "default_dataset_path", lambda: pub)
    assert len(DexCanvasDataset(objects="cube2")) == 2


def test_missing_path_is_a_dataset_error(tmp_path):
    with pytest.raises(DatasetError, match="no such dataset"):
        DexCanvasDataset(tmp_path / "nope.lance")


def test_collate_rejects_bad_input(ds):
    with pytest.raises(ValidationError, match="empty batch"):
        collate_trajectories([])
    s = ds[0]
    bad = dict(s, wrist_pose=s["wrist_pose"][:-1])
    with pytest.raises(ValidationError, match="frames of wrist_pose"):
        collate_trajectories([bad])


@pytest.mark.slow
def test_dataloader_with_a_worker_process(ds):
    batches = list(make_dataloader(ds, batch_size=5, num_workers=1))
    assert batches[0]["meta"]["uuid"] == list(ROWS)
