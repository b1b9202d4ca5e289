"""Reading DexCanvas-layout Lance datasets into :class:`~dexcanvas_core.trajectory.Trajectory`.

``open_dataset(path)`` checks that the path holds a readable Lance dataset in the expected layout
and returns a :class:`LanceTrajectories`: row count, summary (``info``), random access, and a
streaming iterator with filters pushed down to Lance (manipulation type, object, operator), so
memory stays flat on datasets larger than RAM.
"""

from __future__ import annotations

import json
import logging
import os
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from dexcanvas_core.errors import DatasetError, DexCanvasError, ValidationError
from dexcanvas_core.io.schema import (
    REQUIRED_COLUMNS,
    SCHEMA_VERSION_KEY,
    SUPPORTED_MAJOR,
)
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

os.environ.setdefault("LANCE_LOG", "error")

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


def _lance():
    import lance

    return lance


def _escape(s: str) -> str:
    return s.replace("'", "''")


def _in_filter(column: str, values: Sequence[str]) -> str:
    return f"{column} IN ({', '.join(repr_sql(v) for v in values)})"


def repr_sql(v: str) -> str:
    return "'" + _escape(str(v)) + "'"


def build_filter(
    manipulation_types: Sequence[str] | None = None,
    objects: Sequence[str] | None = None,
    operators: Sequence[str] | None = None,
    extra: str | None = None,
) -> str | None:
    """A Lance SQL filter over the nested ``index`` / ``trajectory_metadata`` columns.

    ``manipulation_types`` match ``trajectory_metadata.gesture`` as stored; callers that accept
    names and numeric codes pass every spelling of the same type.
    """
    parts = []
    if manipulation_types:
        parts.append(_in_filter("trajectory_metadata.gesture", manipulation_types))
    if objects:
        parts.append(_in_filter("index.scene", objects))
    if operators:
        parts.append(_in_filter("index.operator", operators))
    if extra:
        parts.append(f"({extra})")
    return " AND ".join(parts) if parts else None


@dataclass(frozen=True)
class DatasetInfo:
    """What ``dexcanvas info`` prints."""

    path: str
    rows: int
    frames: int
    duration_s: float
    fps: dict[int, int]
    pairs: dict[str, int]
    operators: dict[str, int]
    objects: dict[str, int]
    gestures: dict[str, int]
    size_bytes: int
    schema_version: str | None
    has_contacts: bool

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


class LanceTrajectories:
    """A DexCanvas-layout Lance dataset, read lazily. Create with :func:`open_dataset`."""

    def __init__(self, path: str | os.PathLike, ds: Any):
        self.path = str(path)
        self._ds = ds
        self.schema: pa.Schema = ds.schema

    def __len__(self) -> int:
        return self.count_rows()

    def __repr__(self) -> str:
        return f"LanceTrajectories({self.path!r}, rows={self.count_rows()})"

    def count_rows(self, filter: str | None = None) -> int:
        return self._call(lambda: self._ds.count_rows(filter=filter))

    def _call(self, fn):
        try:
            return fn()
        except (OSError, ValueError, RuntimeError) as e:  # lance raises these for broken files
            raise DatasetError(
                f"cannot read: {e}. The dataset is corrupt or partially written; rebuild or "
                "re-download it",
                dataset=self.path,
            ) from e

    def scan_metadata(self, filter: str | None = None) -> pa.Table:
        """The ``index`` and ``trajectory_metadata`` columns with row ids (cheap: no frames)."""
        return self._call(
            lambda: self._ds.to_table(
                columns=["index", "trajectory_metadata"], filter=filter, with_row_id=True
            )
        )

    def row_ids(self, filter: str | None = None) -> np.ndarray:
        """Lance row ids of the rows matching ``filter`` (stable handles for :meth:`take`)."""
        t = self._call(lambda: self._ds.to_table(columns=[], filter=filter, with_row_id=True))
        return t.column("_rowid").to_numpy()

    def iter_batches(
        self, filter: str | None = None, batch_size: int = 8, columns: Sequence[str] | None = None
    ) -> Iterator[pa.RecordBatch]:
        scanner = self._call(
            lambda: self._ds.scanner(
                columns=list(columns) if columns else None,
                filter=filter,
                batch_size=batch_size,
                with_row_id=True,
            )
        )
        it = iter(self._call(lambda: scanner.to_batches()))
        while True:
            try:
                batch = self._call(lambda: next(it))
            except StopIteration:
                return
            yield batch

    def iter_trajectories(
        self, filter: str | None = None, batch_size: int = 8, validate: bool = True
    ) -> Iterator[Trajectory]:
        """Stream every matching row as a ``Trajectory``; memory holds one batch at a time."""
        position = 0
        for batch in self.iter_batches(filter=filter, batch_size=batch_size):
            # Without a filter the scan order is the dataset order: report positions. With a
            # filter, report Lance row ids (stable handles of the rows).
            ids = batch.column("_rowid").to_numpy()
            for i in range(batch.num_rows):
                row = position if filter is None else int(ids[i])
                position += 1
                yield row_to_trajectory(batch, i, dataset=self.path, row=row, validate=validate)

    def __iter__(self) -> Iterator[Trajectory]:
        return self.iter_trajectories()

    def take(self, positions: Iterable[int], validate: bool = True) -> list[Trajectory]:
        """Trajectories at the given 0-based row positions (in dataset order)."""
        pos = [int(i) for i in positions]
        if not pos:
            return []
        n = self.count_rows()
        bad = [i for i in pos if not 0 <= i < n]
        if bad:
            raise DatasetError(
                f"row {bad[0]} out of range: the dataset has {n} rows", dataset=self.path
            )
        tbl = self._call(lambda: self._ds.take(pos))
        batch = tbl.combine_chunks().to_batches()[0]
        return [
            row_to_trajectory(batch, k, dataset=self.path, row=p, validate=validate)
            for k, p in enumerate(pos)
        ]

    def get(self, index: int, validate: bool = True) -> Trajectory:
        """The trajectory at 0-based row position ``index``."""
        return self.take([index], validate=validate)[0]

    def info(self) -> DatasetInfo:
        meta = self.scan_metadata()
        idx = meta.column("index").combine_chunks()
        md = meta.column("trajectory_metadata").combine_chunks()
        scenes = _child(idx, "scene", self.path).to_pylist()
        ops = _child(idx, "operator", self.path).to_pylist()
        gestures = _child(md, "gesture", self.path).to_pylist()
        fps = _child(md, "data_fps", self.path).to_pylist()
        frames = _child(md, "total_frames", self.path).to_pylist()
        dur = sum(f / r for f, r in zip(frames, fps, strict=False) if r)
        version = (self.schema.metadata or {}).get(SCHEMA_VERSION_KEY)
        return DatasetInfo(
            path=self.path,
            rows=meta.num_rows,
            frames=int(sum(frames)),
            duration_s=float(dur),
            fps=dict(Counter(int(f) for f in fps)),
            pairs=dict(
                Counter(f"{s}/{_gesture_name(g)}" for s, g in zip(scenes, gestures, strict=True))
            ),
            operators=dict(Counter(ops)),
            objects=dict(Counter(scenes)),
            gestures=dict(Counter(_gesture_name(g) for g in gestures)),
            size_bytes=_dir_size(self.path),
            schema_version=version.decode() if version else None,
            has_contacts="contact" in self.schema.names,
        )

    # -- row conversion ----------------------------------------------------------------------


def _gesture_name(g: Any) -> str:
    """Manipulation type name for a stored gesture value, or the value itself if unknown."""
    from dexcanvas_core.taxonomy import manipulation_type

    try:
        return manipulation_type(g).name
    except DexCanvasError:  # a code the catalogue leaves open: reported as stored
        return str(g)


def _dir_size(path: str) -> int:
    total = 0
    for root, _dirs, files in os.walk(path):
        for f in files:
            try:
                total += os.path.getsize(os.path.join(root, f))
            except OSError:
                pass
    return total


def open_dataset(path: str | os.PathLike) -> LanceTrajectories:
    """Open a DexCanvas-layout Lance dataset, checking that it exists, opens and has the layout.

    Raises:
        DatasetError: the path is missing, is not a Lance dataset, cannot be opened (corrupt or
            partially written), misses a required column, or names an unsupported contract major
            version.
    """
    p = Path(path).expanduser()
    name = str(p)
    if not p.exists():
        raise DatasetError(
            "no such dataset; pass the path of a DexCanvas Lance dataset (a directory ending in "
            "'.lance'), or build one with `dexcanvas example --out PATH`",
            dataset=name,
        )
    if not p.is_dir() or not (p / "_versions").is_dir():
        raise DatasetError(
            "not a Lance dataset (no _versions/ directory): the copy is partial or the path is "
            "wrong",
            dataset=name,
        )
    try:
        ds = _lance().dataset(name)
        schema = ds.schema
    except (OSError, ValueError, RuntimeError) as e:
        raise DatasetError(
            f"cannot open: {e}. The dataset is corrupt or partially written; rebuild or "
            "re-download it",
            dataset=name,
        ) from e
    missing = [c for c in REQUIRED_COLUMNS if c not in schema.names]
    if missing:
        raise DatasetError(
            f"missing column(s) {', '.join(missing)}: not a DexCanvas-layout dataset "
            f"(columns: {', '.join(schema.names)})",
            dataset=name,
            field=missing[0],
        )
    version = (schema.metadata or {}).get(SCHEMA_VERSION_KEY)
    if version is not None:
        try:
            major = int(version.decode().split(".")[0])
        except ValueError as e:
            raise DatasetError(f"unreadable schema version {version!r}", dataset=name) from e
        if major != SUPPORTED_MAJOR:
            raise DatasetError(
                f"schema version {version.decode()} is not supported by this toolkit (reads "
                f"{SUPPORTED_MAJOR}.x); upgrade dexcanvas-retarget",
                dataset=name,
            )
    return LanceTrajectories(name, ds)


# ---------------------------------------------------------------------------------------------
# Arrow → numpy helpers (positional slicing keeps offsets right for nested lists).


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
