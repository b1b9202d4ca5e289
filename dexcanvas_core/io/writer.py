"""Writing trajectories as DexCanvas-layout Lance datasets (and Parquet for other tools).

The writer is schema-driven: every field of the target schema is filled from the trajectory
attribute it maps to, or from ``Trajectory.extras`` for fields this toolkit does not interpret.
Passing the source dataset's schema therefore writes rows back exactly as they were read.

Writes are atomic: a new dataset is written next to the destination and renamed into place, so a
crash leaves either the old dataset or none, never a partial one. Appends use Lance's own
atomic commits.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import uuid as uuidlib
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Literal

import numpy as np
import pyarrow as pa

from dexcanvas_core.errors import DatasetError
from dexcanvas_core.io.schema import SCHEMA_VERSION, SCHEMA_VERSION_KEY, default_schema
from dexcanvas_core.trajectory import CONTACT_PAIR_FIELDS, Trajectory

log = logging.getLogger(__name__)

os.environ.setdefault("LANCE_LOG", "error")


def schema_for(traj: Trajectory) -> pa.Schema:
    """The default schema fitting a trajectory: ``urdf_dof`` width, contacts, wrench, and one
    extra field per entry of ``traj.extras`` (so rows read from another layout keep them)."""
    dof = 26
    for h in traj.hands:
        for a in (h.urdf_dof, h.urdf_dof_target):
            if a is not None:
                dof = a.shape[1]
    c = traj.contacts
    schema = default_schema(
        urdf_dof=dof,
        contact=c is not None,
        contact_force_world=c is not None and c.force_world is not None,
        wrench=traj.object_wrench_world is not None,
        table=traj.table is not None,
    )
    return _add_extras(schema, traj.extras)


def _add_extras(schema: pa.Schema, extras: dict) -> pa.Schema:
    """Append the fields named by ``extras`` keys (``index.x``, ``hands[0].x``, ``x``, …)."""

    def typ(v) -> pa.DataType:
        return v.type if isinstance(v, pa.Scalar) else pa.scalar(v).type

    def add(struct_t: pa.StructType, path: list[str], t: pa.DataType) -> pa.StructType:
        head, rest = path[0], path[1:]
        fields = list(struct_t)
        i = struct_t.get_field_index(head)
        if not rest:
            if i < 0:
                fields.append(pa.field(head, t))
            return pa.struct(fields)
        fields[i] = pa.field(head, add(fields[i].type, rest, t))
        return pa.struct(fields)

    for key, v in extras.items():
        parts = key.split(".")
        top = parts[0].split("[", 1)[0]
        if len(parts) == 1:
            if top not in schema.names:
                schema = schema.append(pa.field(top, typ(v)))
            continue
        i = schema.get_field_index(top)
        if i < 0:
            continue
        f = schema.field(i)
        if pa.types.is_list(f.type):  # hands[j].x / objects[j].x
            new_t = pa.list_(add(f.type.value_type, parts[1:], typ(v)))
        else:
            new_t = add(f.type, parts[1:], typ(v))
        schema = schema.set(i, pa.field(top, new_t))
    return schema


# ---------------------------------------------------------------------------------------------
# numpy → Arrow builders


def _numeric_array(values: np.ndarray, typ: pa.DataType) -> pa.Array:
    """Arrow array of ``typ`` (nested fixed/variable lists of numbers) from ``(N, ...)`` values."""
    if pa.types.is_fixed_size_list(typ):
        n = typ.list_size
        inner = values.reshape((-1, *values.shape[2:])) if values.ndim > 2 else values.reshape(-1)
        if values.ndim < 2 or values.shape[1] != n:
            raise DatasetError(f"cannot write shape {values.shape} as {typ}")
        return pa.FixedSizeListArray.from_arrays(_numeric_array(inner, typ.value_type), type=typ)
    if pa.types.is_list(typ) or pa.types.is_large_list(typ):
        n = values.shape[1]
        inner = values.reshape((-1, *values.shape[2:])) if values.ndim > 2 else values.reshape(-1)
        offsets = pa.array(np.arange(values.shape[0] + 1, dtype=np.int32) * n, pa.int32())
        return pa.ListArray.from_arrays(offsets, _numeric_array(inner, typ.value_type), type=typ)
    return pa.array(np.ascontiguousarray(values.reshape(-1)).astype(typ.to_pandas_dtype()), typ)


def _list_of(items: list[pa.Array | None], typ: pa.DataType) -> pa.Array:
    """A list array with one entry per item (``None`` → null entry)."""
    lengths = [0 if a is None else len(a) for a in items]
    offsets = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int32)
    present = [a for a in items if a is not None]
    values = pa.concat_arrays(present) if present else pa.array([], type=typ.value_type)
    mask = pa.array([a is None for a in items]) if any(a is None for a in items) else None
    return pa.ListArray.from_arrays(pa.array(offsets, pa.int32()), values, type=typ, mask=mask)


def _per_frame(values: np.ndarray | None, list_type: pa.DataType) -> pa.Array | None:
    """A ``(T, ...)`` array as the values of a per-frame list (length T), or None."""
    if values is None:
        return None
    return _numeric_array(values, list_type.value_type)


def _struct(children: dict[str, pa.Array], typ: pa.StructType, mask=None) -> pa.Array:
    return pa.StructArray.from_arrays([children[f.name] for f in typ], fields=list(typ), mask=mask)


def _extra(traj: Trajectory, key: str, typ: pa.DataType) -> pa.Array:
    v = traj.extras.get(key)
    if v is None:
        return pa.nulls(1, typ)
    if isinstance(v, pa.Scalar):
        return pa.array([v.as_py()], type=typ)
    return pa.array([v], type=typ)


def _index_array(trajs: list[Trajectory], typ: pa.StructType) -> pa.Array:
    known = {
        "uuid": lambda t: t.uuid,
        "seed_uuid": lambda t: t.seed_uuid,
        "capMachine": lambda t: t.cap_machine,
        "operator": lambda t: t.operator,
        "scene": lambda t: t.scene,
        "is_generated": lambda t: t.is_generated,
    }
    children = {}
    for f in typ:
        if f.name in known:
            children[f.name] = pa.array([known[f.name](t) for t in trajs], type=f.type)
        else:
            children[f.name] = pa.concat_arrays(
                [_extra(t, f"index.{f.name}", f.type) for t in trajs]
            )
    return _struct(children, typ)


def _metadata_array(trajs: list[Trajectory], typ: pa.StructType) -> pa.Array:
    children = {}
    for f in typ:
        if f.name == "data_fps":
            vals = [t.fps for t in trajs]
            if pa.types.is_integer(f.type):
                vals = [round(v) for v in vals]
            children[f.name] = pa.array(vals, type=f.type)
        elif f.name == "total_frames":
            children[f.name] = pa.array([t.num_frames for t in trajs], type=f.type)
        elif f.name == "gesture":
            children[f.name] = pa.array([t.gesture for t in trajs], type=f.type)
        elif f.name == "hand_names":
            children[f.name] = pa.array([[h.name for h in t.hands] for t in trajs], type=f.type)
        elif f.name == "object_names":
            children[f.name] = pa.array([[o.name for o in t.objects] for t in trajs], type=f.type)
        elif f.name == "mano_hand_shapes":
            items = [
                _numeric_array(np.stack([h.betas for h in t.hands]), f.type.value_type)
                if t.hands
                else pa.array([], type=f.type.value_type)
                for t in trajs
            ]
            children[f.name] = _list_of(items, f.type)
        elif f.name == "trajectory_info":
            children[f.name] = _trajectory_info(trajs, f.type)
        else:
            children[f.name] = pa.concat_arrays(
                [_extra(t, f"trajectory_metadata.{f.name}", f.type) for t in trajs]
            )
    return _struct(children, typ)


def _trajectory_info(trajs: list[Trajectory], typ: pa.StructType) -> pa.Array:
    children = {}
    for f in typ:
        if f.name == "object_move":
            children[f.name] = pa.array(
                [
                    [
                        {"object_name": m.object_name, "start_frame": m.start_frame,
                         "end_frame": m.end_frame}
                        for m in t.object_move
                    ]
                    for t in trajs
                ],
                type=f.type,
            )  # fmt: skip
        else:
            children[f.name] = pa.concat_arrays(
                [_extra(t, f"trajectory_metadata.trajectory_info.{f.name}", f.type) for t in trajs]
            )
    return _struct(children, typ)


def _hands_array(trajs: list[Trajectory], typ: pa.ListType) -> pa.Array:
    st: pa.StructType = typ.value_type
    per_row = []
    for t in trajs:
        children: dict[str, list[pa.Array]] = {f.name: [] for f in st}
        for j, h in enumerate(t.hands):
            src = {
                "mano_global_pos": h.global_pos,
                "mano_global_rot_aa": h.global_rot_aa,
                "mano_hand_pose": h.hand_pose,
                "mano_joint_pos": h.joint_pos,
                "urdf_dof": h.urdf_dof,
                "urdf_dof_target": h.urdf_dof_target,
            }
            for f in st:
                if f.name == "hand_name":
                    children[f.name].append(pa.array([h.name], f.type))
                elif f.name in src:
                    vals = src[f.name]
                    if vals is not None and pa.types.is_fixed_size_list(f.type.value_type):
                        width = f.type.value_type.list_size
                        if vals.shape[1] != width:
                            raise DatasetError(
                                f"trajectory {t.uuid}: hands[{j}].{f.name} has {vals.shape[1]} "
                                f"columns, the schema has {width}; write 26- and 28-DoF hands to "
                                "separate datasets",
                                field=f.name,
                            )
                    children[f.name].append(_list_of([_per_frame(vals, f.type)], f.type))
                else:
                    children[f.name].append(_extra(t, f"hands[{j}].{f.name}", f.type))
        arrays = {
            k: pa.concat_arrays(v) if v else pa.array([], type=st.field(k).type)
            for k, v in children.items()
        }
        per_row.append(_struct(arrays, st))
    return _list_of(per_row, typ)


def _objects_array(trajs: list[Trajectory], typ: pa.ListType) -> pa.Array:
    st: pa.StructType = typ.value_type
    per_row = []
    for t in trajs:
        children: dict[str, list[pa.Array]] = {f.name: [] for f in st}
        for j, o in enumerate(t.objects):
            for f in st:
                if f.name in ("pos", "rot_aa"):
                    vals = o.pos if f.name == "pos" else o.rot_aa
                    children[f.name].append(_list_of([_per_frame(vals, f.type)], f.type))
                else:
                    children[f.name].append(_extra(t, f"objects[{j}].{f.name}", f.type))
        arrays = {
            k: pa.concat_arrays(v) if v else pa.array([], type=st.field(k).type)
            for k, v in children.items()
        }
        per_row.append(_struct(arrays, st))
    return _list_of(per_row, typ)


def _contact_array(trajs: list[Trajectory], typ: pa.ListType) -> pa.Array:
    frames_type: pa.ListType = typ.value_type
    rec_type: pa.StructType = frames_type.value_type
    pairs_list_type: pa.ListType = rec_type.field("contact_pairs").type
    pair_type: pa.StructType = pairs_list_type.value_type
    per_row: list[pa.Array | None] = []
    for t in trajs:
        c = t.contacts
        if c is None:
            per_row.append(None)
            continue
        pair_children = {}
        for f in pair_type:
            if f.name in CONTACT_PAIR_FIELDS:
                pair_children[f.name] = _numeric_array(c.pairs[f.name], f.type)
            elif f.name == "force_world":
                fw = c.force_world if c.force_world is not None else np.zeros((c.num_pairs, 3))
                pair_children[f.name] = _numeric_array(fw, f.type)
            else:
                raise DatasetError(f"cannot write unknown contact pair field {f.name!r}")
        pairs = _struct(pair_children, pair_type)
        pairs_list = pa.ListArray.from_arrays(
            pa.array(c.pair_offsets.astype(np.int32)), pairs, type=pairs_list_type
        )
        rec_children = {}
        for f in rec_type:
            if f.name in ("hand_name", "joint_name", "object_name"):
                rec_children[f.name] = pa.array(list(getattr(c, f.name)), type=f.type)
            elif f.name in c.totals:
                rec_children[f.name] = _numeric_array(c.totals[f.name], f.type)
            elif f.name == "contact_pairs":
                rec_children[f.name] = pairs_list
            else:
                raise DatasetError(f"cannot write unknown contact record field {f.name!r}")
        recs = _struct(rec_children, rec_type)
        counts = (
            np.bincount(c.frame, minlength=c.num_frames)
            if c.num_records
            else np.zeros(c.num_frames, np.int64)
        )
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
        per_row.append(pa.ListArray.from_arrays(pa.array(offsets), recs, type=frames_type))
    return _list_of(per_row, typ)


def _table_array(trajs: list[Trajectory], typ: pa.StructType) -> pa.Array:
    """The ``table`` column: one struct per trajectory, null where it names no table."""
    rows = [None if t.table is None else t.table.to_dict() for t in trajs]
    return pa.array(rows, type=typ)


def trajectories_to_batch(trajs: list[Trajectory], schema: pa.Schema) -> pa.RecordBatch:
    """Arrow record batch of ``trajs`` in ``schema`` (DexCanvas layout plus extras)."""
    if "table" not in schema.names:
        for t in trajs:
            if t.table is not None:
                raise DatasetError(
                    f"trajectory {t.uuid} names its table but the target schema has no "
                    "'table' column (it would be lost); write with a schema that has one, e.g. "
                    "io.default_schema(table=True), or put the trajectory with a table first"
                )
    cols = []
    for f in schema:
        if f.name == "index":
            cols.append(_index_array(trajs, f.type))
        elif f.name == "trajectory_metadata":
            cols.append(_metadata_array(trajs, f.type))
        elif f.name == "timestamp":
            cols.append(
                _list_of([_numeric_array(t.timestamp, f.type.value_type) for t in trajs], f.type)
            )
        elif f.name == "hands":
            cols.append(_hands_array(trajs, f.type))
        elif f.name == "objects":
            cols.append(_objects_array(trajs, f.type))
        elif f.name == "contact":
            cols.append(_contact_array(trajs, f.type))
        elif f.name == "object_wrench_world":
            cols.append(
                _list_of([_per_frame(t.object_wrench_world, f.type) for t in trajs], f.type)
            )
        elif f.name == "contact_solver":
            cols.append(
                pa.array(
                    [None if t.solver_settings is None
                     else json.dumps(t.solver_settings, sort_keys=True)
                     for t in trajs],
                    type=f.type,
                )
            )  # fmt: skip
        elif f.name == "table":
            cols.append(_table_array(trajs, f.type))
        else:
            cols.append(pa.concat_arrays([_extra(t, f.name, f.type) for t in trajs]))
    return pa.RecordBatch.from_arrays(cols, schema=schema)


def _with_version(schema: pa.Schema) -> pa.Schema:
    meta = dict(schema.metadata or {})
    meta[SCHEMA_VERSION_KEY] = SCHEMA_VERSION.encode()
    return schema.with_metadata(meta)


class _Encoder:
    """Encodes trajectories batch by batch; remembers the first error so that it can be re-raised
    as itself after Lance (which wraps Python errors from a stream in an OSError) gives up."""

    def __init__(self) -> None:
        self.error: BaseException | None = None


def _batches(
    trajs: Iterable[Trajectory],
    schema: pa.Schema | None,
    batch_rows: int,
    validate: bool,
    enc: _Encoder,
) -> tuple[pa.Schema, Iterator[pa.RecordBatch]]:
    it = iter(trajs)
    try:
        first = next(it)
    except StopIteration:
        raise DatasetError("nothing to write: no trajectories") from None
    schema = _with_version(schema if schema is not None else schema_for(first))

    def gen() -> Iterator[pa.RecordBatch]:
        try:
            chunk = [first]
            for t in it:
                chunk.append(t)
                if len(chunk) >= batch_rows:
                    yield _encode(chunk)
                    chunk = []
            if chunk:
                yield _encode(chunk)
        except BaseException as e:
            enc.error = e
            raise

    def _encode(chunk: list[Trajectory]) -> pa.RecordBatch:
        if validate:
            for t in chunk:
                t.validate()
        return trajectories_to_batch(chunk, schema)

    return schema, gen()


def write_dataset(
    trajectories: Iterable[Trajectory],
    path: str | os.PathLike,
    *,
    mode: Literal["create", "overwrite", "append"] = "create",
    schema: pa.Schema | None = None,
    batch_rows: int = 16,
    validate: bool = True,
) -> Path:
    """Write trajectories as a DexCanvas-layout Lance dataset, streaming ``batch_rows`` at a time.

    Args:
        trajectories: any iterable (a generator keeps memory flat).
        path: destination directory, conventionally ending in ``.lance``.
        mode: ``create`` refuses an existing path; ``overwrite`` replaces it atomically;
            ``append`` adds rows (the schema must match).
        schema: target Arrow schema; pass ``LanceTrajectories.schema`` to write rows back in their
            source layout. Default: the toolkit's layout fitted to the first trajectory.
        validate: run ``Trajectory.validate()`` on every row before writing.
    """
    import lance

    dest = Path(path).expanduser()
    if mode not in ("create", "overwrite", "append"):
        raise DatasetError(f"unknown write mode {mode!r}; use create, overwrite or append")
    if mode == "create" and dest.exists():
        raise DatasetError("already exists; pass mode='overwrite' to replace it", dataset=str(dest))
    if mode == "append":
        if not dest.exists():
            raise DatasetError("cannot append: no dataset here", dataset=str(dest))
        existing = lance.dataset(str(dest)).schema
        if schema is None:
            schema = existing
        enc = _Encoder()
        schema, batches = _batches(trajectories, schema, batch_rows, validate, enc)
        _lance_write(lance, pa.RecordBatchReader.from_batches(schema, batches), dest, "append", enc)
        return dest
    enc = _Encoder()
    schema, batches = _batches(trajectories, schema, batch_rows, validate, enc)
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = dest.with_name(f".{dest.name}.tmp-{uuidlib.uuid4().hex[:8]}")
    try:
        _lance_write(lance, pa.RecordBatchReader.from_batches(schema, batches), tmp, "create", enc)
        _replace_dir(tmp, dest)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    log.info("wrote %s", dest)
    return dest


def _lance_write(lance, reader: pa.RecordBatchReader, dest: Path, mode: str, enc: _Encoder) -> None:
    try:
        lance.write_dataset(reader, str(dest), mode=mode)
    except (OSError, ValueError, RuntimeError) as e:
        if enc.error is not None:
            raise enc.error from None
        raise DatasetError(f"writing failed: {e}", dataset=str(dest)) from e


def _replace_dir(src: Path, dest: Path) -> None:
    """Move ``src`` to ``dest``; an existing ``dest`` is swapped out first, then removed."""
    if not dest.exists():
        os.replace(src, dest)
        return
    old = dest.with_name(f".{dest.name}.old-{uuidlib.uuid4().hex[:8]}")
    os.replace(dest, old)
    try:
        os.replace(src, dest)
    except OSError:
        os.replace(old, dest)
        raise
    shutil.rmtree(old, ignore_errors=True)


def export_parquet(
    source: str | os.PathLike,
    dest: str | os.PathLike,
    *,
    filter: str | None = None,
    batch_size: int = 16,
) -> Path:
    """Copy a Lance dataset (optionally filtered) to one Parquet file, streaming and atomic."""
    import pyarrow.parquet as pq

    from dexcanvas_core.io.reader import open_dataset

    ds = open_dataset(source)
    dest = Path(dest).expanduser()
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = dest.with_name(f".{dest.name}.tmp-{uuidlib.uuid4().hex[:8]}")
    schema = ds.schema
    try:
        with pq.ParquetWriter(str(tmp), schema) as w:
            for batch in ds.iter_batches(filter=filter, batch_size=batch_size):
                w.write_batch(batch.select(schema.names))
        os.replace(tmp, dest)
    finally:
        if tmp.exists():
            tmp.unlink()
    return dest
