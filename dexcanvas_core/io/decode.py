"""Decoding one row of a DexCanvas-layout Arrow batch into a
:class:`~dexcanvas_core.trajectory.Trajectory` (``row_to_trajectory``), checking shapes and
values on the way; fields the toolkit does not interpret are kept in ``Trajectory.extras``.
"""

from __future__ import annotations

import json
import logging
from typing import Any

import numpy as np
import pyarrow as pa

from dexcanvas_core.errors import DatasetError, ValidationError
from dexcanvas_core.io.schema import REQUIRED_COLUMNS
from dexcanvas_core.table import Table
from dexcanvas_core.trajectory import (
    CONTACT_PAIR_FIELDS,
    CONTACT_TOTAL_FIELDS,
    Contacts,
    HandTrack,
    ObjectMove,
    ObjectTrack,
    Trajectory,
)

log = logging.getLogger(__name__)

# Fields the reader maps onto Trajectory attributes; any other field is kept in `extras`.
_INDEX_KNOWN = {"uuid", "seed_uuid", "capMachine", "operator", "scene", "is_generated"}
_META_KNOWN = {
    "data_fps", "total_frames", "gesture", "hand_names", "object_names", "mano_hand_shapes",
    "trajectory_info",
}  # fmt: skip
_HAND_KNOWN = {
    "hand_name", "mano_global_pos", "mano_global_rot_aa", "mano_hand_pose", "mano_joint_pos",
    "urdf_dof", "urdf_dof_target",
}  # fmt: skip
_TOP_KNOWN = {*REQUIRED_COLUMNS, "contact", "object_wrench_world", "contact_solver", "table"}


def _child(struct_arr: pa.Array, name: str, dataset: str, row: int | None = None) -> pa.Array:
    t = struct_arr.type
    if not pa.types.is_struct(t):
        raise DatasetError(f"expected a struct, got {t}", dataset=dataset, row=row, field=name)
    idx = t.get_field_index(name)
    if idx < 0:
        raise DatasetError(
            f"missing field (has: {', '.join(f.name for f in t)})",
            dataset=dataset,
            row=row,
            field=name,
        )
    return struct_arr.flatten()[idx]


def _has(struct_arr: pa.Array, name: str) -> bool:
    return struct_arr.type.get_field_index(name) >= 0


def _numeric(arr: pa.Array, inner: tuple[int, ...], where: tuple[str, int, str]) -> np.ndarray:
    """Flatten a (nested) list array of length T to ``(T, *inner)`` float array."""
    dataset, row, field = where
    T = len(arr)
    values = arr
    while (
        pa.types.is_list(values.type)
        or pa.types.is_fixed_size_list(values.type)
        or pa.types.is_large_list(values.type)
    ):
        if values.null_count:
            raise DatasetError("contains null entries", dataset=dataset, row=row, field=field)
        values = values.flatten()
    if values.null_count:
        raise DatasetError("contains null values", dataset=dataset, row=row, field=field)
    flat = values.to_numpy(zero_copy_only=False)
    want = T * int(np.prod(inner)) if inner else T
    if flat.shape[0] != want:
        per = flat.shape[0] / T if T else 0
        raise DatasetError(
            f"wrong shape: {flat.shape[0]} values for {T} frames ({per:g} per frame), expected "
            f"(T, {', '.join(map(str, inner))}) per frame",
            dataset=dataset,
            row=row,
            field=field,
        )
    return flat.reshape((T, *inner))


def _list_item(list_arr: pa.Array, i: int) -> pa.Array:
    """Item ``i`` of a list array, as an array (offset-correct)."""
    return list_arr.slice(i, 1).flatten()


def _scalar_dict(struct_arr: pa.Array, i: int, known: set[str], prefix: str) -> dict[str, Any]:
    out = {}
    for j, f in enumerate(struct_arr.type):
        if f.name not in known:
            out[f"{prefix}.{f.name}"] = struct_arr.flatten()[j][i]
    return out


def row_to_trajectory(
    batch: pa.RecordBatch, i: int, *, dataset: str, row: int, validate: bool = True
) -> Trajectory:
    """Convert row ``i`` of a record batch in the DexCanvas layout into a ``Trajectory``."""
    names = batch.schema.names
    for c in REQUIRED_COLUMNS:
        if c not in names:
            raise DatasetError("missing column", dataset=dataset, row=row, field=c)

    def col(name: str) -> pa.Array:
        return batch.column(name)

    index = col("index").slice(i, 1)
    meta = col("trajectory_metadata").slice(i, 1)

    def s(arr: pa.Array, name: str) -> Any:
        return _child(arr, name, dataset, row)[0].as_py()

    def opt(arr: pa.Array, name: str, default: Any) -> Any:
        if not _has(arr, name):
            return default
        v = s(arr, name)
        return default if v is None else v

    ts_arr = _list_item(col("timestamp"), i)
    timestamp = _numeric(ts_arr, (), (dataset, row, "timestamp")).astype(np.float64)
    T = timestamp.shape[0]
    fps = opt(meta, "data_fps", None)
    if fps is None:
        raise DatasetError(
            "missing value", dataset=dataset, row=row, field="trajectory_metadata.data_fps"
        )
    total = opt(meta, "total_frames", T)
    if total != T:
        raise DatasetError(
            f"total_frames is {total} but timestamp has {T} frames",
            dataset=dataset,
            row=row,
            field="trajectory_metadata.total_frames",
        )

    shapes = opt(meta, "mano_hand_shapes", []) or []
    hands_arr = _list_item(col("hands"), i)
    hands = []
    extras: dict[str, Any] = {}
    for j in range(len(hands_arr)):
        h = hands_arr.slice(j, 1)
        where = lambda f, j=j: (dataset, row, f"hands[{j}].{f}")  # noqa: E731

        def arr(name: str, inner: tuple[int, ...], required: bool = True, h=h, where=where):
            if not _has(h, name):
                if required:
                    raise DatasetError(
                        "missing field", dataset=dataset, row=row, field=where(name)[2]
                    )
                return None
            item = _child(h, name, dataset, row)
            if item.null_count:
                if required:
                    raise DatasetError("is null", dataset=dataset, row=row, field=where(name)[2])
                return None
            a = _numeric(_list_item(item, 0), inner, where(name))
            if a.shape[0] != T:
                raise DatasetError(
                    f"has {a.shape[0]} frames, timestamp has {T}",
                    dataset=dataset, row=row, field=where(name)[2],
                )  # fmt: skip
            return a

        dof = None
        for name in ("urdf_dof", "urdf_dof_target"):
            if _has(h, name) and not _child(h, name, dataset, row).null_count:
                item = _list_item(_child(h, name, dataset, row), 0)
                if len(item):
                    dof = len(item.flatten()) // len(item)
                    if dof not in (26, 28):
                        raise DatasetError(
                            f"wrong shape: {dof} values per frame, expected 26 or 28",
                            dataset=dataset, row=row, field=where(name)[2],
                        )  # fmt: skip
                break
        betas = np.asarray(shapes[j] if j < len(shapes) else np.zeros(10), np.float32)
        if betas.shape != (10,):
            raise DatasetError(
                f"wrong shape {betas.shape}, expected (10,)",
                dataset=dataset, row=row, field=f"trajectory_metadata.mano_hand_shapes[{j}]",
            )  # fmt: skip
        try:
            hands.append(
                HandTrack(
                    name=s(h, "hand_name") or "right",
                    global_pos=arr("mano_global_pos", (3,)),
                    global_rot_aa=arr("mano_global_rot_aa", (3,)),
                    hand_pose=arr("mano_hand_pose", (48,)),
                    joint_pos=arr("mano_joint_pos", (21, 3), required=False),
                    urdf_dof=arr("urdf_dof", (dof or 26,), required=False),
                    urdf_dof_target=arr("urdf_dof_target", (dof or 26,), required=False),
                    betas=betas,
                )
            )
        except ValidationError as e:
            raise DatasetError(str(e), dataset=dataset, row=row, field=e.field) from e
        for k, v in _scalar_dict(h, 0, _HAND_KNOWN, f"hands[{j}]").items():
            extras[k] = v

    object_names = opt(meta, "object_names", []) or []
    objs_arr = _list_item(col("objects"), i)
    objects = []
    for j in range(len(objs_arr)):
        o = objs_arr.slice(j, 1)
        where_o = lambda f, j=j: (dataset, row, f"objects[{j}].{f}")  # noqa: E731
        pos = _numeric(_list_item(_child(o, "pos", dataset, row), 0), (3,), where_o("pos"))
        rot = _numeric(_list_item(_child(o, "rot_aa", dataset, row), 0), (3,), where_o("rot_aa"))
        for nm, a in (("pos", pos), ("rot_aa", rot)):
            if a.shape[0] != T:
                raise DatasetError(
                    f"has {a.shape[0]} frames, timestamp has {T}",
                    dataset=dataset, row=row, field=where_o(nm)[2],
                )  # fmt: skip
        name = object_names[j] if j < len(object_names) else f"object{j}"
        objects.append(ObjectTrack(name=name, pos=pos, rot_aa=rot))
        for k, v in _scalar_dict(o, 0, {"pos", "rot_aa"}, f"objects[{j}]").items():
            extras[k] = v

    moves = []
    info = opt(meta, "trajectory_info", None)
    if info and info.get("object_move"):
        for m in info["object_move"]:
            moves.append(ObjectMove(m["object_name"], int(m["start_frame"]), int(m["end_frame"])))
    if info:
        for k in info:
            if k != "object_move":
                extras[f"trajectory_metadata.trajectory_info.{k}"] = _child(
                    _child(meta, "trajectory_info", dataset, row), k, dataset, row
                )[0]

    contacts = None
    if "contact" in names and not col("contact").slice(i, 1).is_null()[0].as_py():
        contacts = _read_contacts(_list_item(col("contact"), i), T, dataset, row)

    wrench = None
    if "object_wrench_world" in names and col("object_wrench_world")[i].is_valid:
        wrench = _numeric(
            _list_item(col("object_wrench_world"), i), (6,), (dataset, row, "object_wrench_world")
        )
    solver = None
    if "contact_solver" in names and col("contact_solver")[i].is_valid:
        solver = json.loads(col("contact_solver")[i].as_py())
    table = None
    if "table" in names and col("table")[i].is_valid:
        try:
            table = Table.from_dict(col("table")[i].as_py())
        except ValidationError as e:
            raise DatasetError(str(e), dataset=dataset, row=row, field="table") from e

    extras.update(_scalar_dict(index, 0, _INDEX_KNOWN, "index"))
    extras.update(_scalar_dict(meta, 0, _META_KNOWN, "trajectory_metadata"))
    for c in names:
        if c not in _TOP_KNOWN and c != "_rowid":
            extras[c] = col(c)[i]

    gesture = opt(meta, "gesture", "")
    try:
        traj = Trajectory(
            uuid=opt(index, "uuid", ""),
            timestamp=timestamp,
            fps=float(fps),
            hands=hands,
            objects=objects,
            gesture=str(gesture),
            operator=opt(index, "operator", ""),
            scene=opt(index, "scene", ""),
            cap_machine=opt(index, "capMachine", ""),
            is_generated=bool(opt(index, "is_generated", False)),
            seed_uuid=opt(index, "seed_uuid", ""),
            object_move=moves,
            contacts=contacts,
            object_wrench_world=wrench,
            solver_settings=solver,
            table=table,
            extras=extras,
        )
        if validate:
            traj.validate()
    except ValidationError as e:
        raise DatasetError(str(e), dataset=dataset, row=row, field=e.field) from e
    return traj


def _read_contacts(frames_arr: pa.Array, T: int, dataset: str, row: int) -> Contacts:
    """``contact`` of one row: a list over frames of lists of part records."""
    if len(frames_arr) != T:
        raise DatasetError(
            f"has {len(frames_arr)} frames, timestamp has {T}",
            dataset=dataset,
            row=row,
            field="contact",
        )
    offsets = frames_arr.offsets.to_numpy()
    counts = np.diff(offsets)
    frame = np.repeat(np.arange(T), counts)
    recs = frames_arr.flatten()
    K = len(recs)

    def strs(name: str) -> np.ndarray:
        return np.asarray(_child(recs, name, dataset, row).to_pylist(), dtype=object)

    def vec(arr: pa.Array, field: str) -> np.ndarray:
        return _numeric(arr, (3,), (dataset, row, field)).astype(np.float32)

    totals = {
        k: vec(_child(recs, k, dataset, row), f"contact.{k}") if K else np.zeros((0, 3), np.float32)
        for k in CONTACT_TOTAL_FIELDS
    }
    pairs_list = _child(recs, "contact_pairs", dataset, row)
    if K:
        po = pairs_list.offsets.to_numpy()
        pair_offsets = (po - po[0]).astype(np.int64)
        pairs_struct = pairs_list.flatten()
    else:
        pair_offsets = np.zeros(1, np.int64)
        pairs_struct = None
    P = int(pair_offsets[-1])
    pairs = {}
    for k in CONTACT_PAIR_FIELDS:
        pairs[k] = (
            vec(_child(pairs_struct, k, dataset, row), f"contact.contact_pairs.{k}")
            if P
            else np.zeros((0, 3), np.float32)
        )
    force_world = None
    if pairs_struct is not None and _has(pairs_struct, "force_world"):
        force_world = vec(
            _child(pairs_struct, "force_world", dataset, row), "contact.contact_pairs.force_world"
        )
    elif (
        P == 0
        and pa.types.is_struct(pairs_list.type.value_type)
        and (pairs_list.type.value_type.get_field_index("force_world") >= 0)
    ):
        force_world = np.zeros((0, 3), np.float32)
    try:
        return Contacts(
            num_frames=T,
            frame=frame,
            hand_name=strs("hand_name") if K else [],
            joint_name=strs("joint_name") if K else [],
            object_name=strs("object_name") if K else [],
            totals=totals,
            pair_offsets=pair_offsets,
            pairs=pairs,
            force_world=force_world,
        )
    except ValidationError as e:
        raise DatasetError(str(e), dataset=dataset, row=row, field="contact") from e
