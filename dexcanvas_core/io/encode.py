"""Encoding trajectories as Arrow record batches in the DexCanvas layout (``schema_for``,
``trajectories_to_batch``): every field of the target schema is filled from the trajectory
attribute it maps to, or from ``Trajectory.extras`` for fields this toolkit does not interpret.
"""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa

from dexcanvas_core.errors import DatasetError
from dexcanvas_core.io.schema import default_schema
from dexcanvas_core.trajectory import CONTACT_PAIR_FIELDS, Trajectory


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
        per_row.append(_struct_of_children(children, st))
    return _list_of(per_row, typ)


def _struct_of_children(children: dict[str, list[pa.Array]], st: pa.StructType) -> pa.Array:
    """One row's struct array from its children's per-element arrays (empty ones typed)."""
    arrays = {
        k: pa.concat_arrays(v) if v else pa.array([], type=st.field(k).type)
        for k, v in children.items()
    }
    return _struct(arrays, st)


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
        per_row.append(_struct_of_children(children, st))
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
