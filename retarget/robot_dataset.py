"""The Lance dataset of robot trajectories that ``retarget batch`` writes, and its reader.

One row per demonstration × hand × method. The schema (:data:`ROBOT_SCHEMA`) is versioned like
the human layout's: its version is stored under the schema-metadata key
:data:`ROBOT_SCHEMA_VERSION_KEY` (``docs/design.md``, "Robot trajectory datasets", lists the
columns, units and shapes). Per-frame arrays are nested Arrow lists of ``float64`` in row-major
order: ``(T,)``, ``(T, n)`` or ``(T, n, 3)``; failed rows hold nulls there.

Rows are keyed by :data:`KEY_COLUMNS` (source uuid, hand, method). They are added with one
Lance ``merge_insert`` per chunk (:func:`upsert_rows`): one atomic commit that inserts new keys
and replaces rows of keys already present (a failed row retried), so an interrupted writer
leaves whole chunks and never two rows of one key.
"""

from __future__ import annotations

import json
import os
import shutil
import uuid as uuidlib
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa

from retarget.errors import RetargetError

os.environ.setdefault("LANCE_LOG", "error")

ROBOT_SCHEMA_VERSION_KEY = b"dexcanvas_robot_schema"
"""Schema-metadata key naming the version of a robot trajectory dataset's layout."""
ROBOT_SCHEMA_VERSION = "1.0"
ROBOT_SUPPORTED_MAJOR = 1

KEY_COLUMNS = ("uuid", "hand", "method")
"""A row's identity: one demonstration, one hand, one method (``method`` is canonical JSON)."""

_F64 = pa.float64()


def _nested(depth: int) -> pa.DataType:
    t = _F64
    for _ in range(depth):
        t = pa.list_(t)
    return t


TENSOR_COLUMNS = {
    # name: number of list levels (1: (T,), 2: (T, n), 3: (T, n, 3))
    "timestamp": 1,
    "q": 2,
    "q_command": 2,
    "q_sim": 2,
    "ctrl_refined": 2,
    "object_pos_sim": 2,
    "object_rot_sim": 2,
    "object_pos_err": 1,
    "object_rot_err": 1,
    "tip_pos_world": 3,
    "finger_force_world": 3,
    "keypoint_err": 1,
}
"""Per-frame array columns and their depth; see ``docs/design.md`` for units and shapes."""

ROBOT_SCHEMA = pa.schema(
    [
        ("uuid", pa.string()),
        ("source_row", pa.int64()),
        ("dataset", pa.string()),
        ("pair", pa.string()),
        ("hand", pa.string()),
        ("method", pa.string()),
        ("status", pa.string()),
        ("reason", pa.string()),
        ("model_source", pa.string()),
        ("model_hash", pa.string()),
        ("joint_names", pa.list_(pa.string())),
        ("tip_sites", pa.list_(pa.string())),
        ("force_parts", pa.list_(pa.string())),
        ("fps", _F64),
        ("frames", pa.int64()),
        *((name, _nested(depth)) for name, depth in TENSOR_COLUMNS.items()),
        ("success", pa.bool_()),
        ("success_refined", pa.bool_()),
        ("metrics", pa.string()),
        ("config", pa.string()),
        ("elapsed_s", _F64),
    ],
    metadata={ROBOT_SCHEMA_VERSION_KEY: ROBOT_SCHEMA_VERSION.encode()},
)
"""Arrow schema of a robot trajectory dataset (version :data:`ROBOT_SCHEMA_VERSION`)."""

JSON_COLUMNS = ("method", "metrics", "config")
"""String columns holding JSON (parsed by :func:`read_robot_rows`)."""


def method_key(forces: bool, refine: bool, overrides: dict, max_frames: int | None) -> str:
    """The ``method`` column: canonical JSON (sorted keys) of what was run.

    >>> method_key(True, False, {"w_contacts": 100.0}, None)
    '{"forces": true, "max_frames": null, "overrides": {"w_contacts": 100.0}, "refine": false}'
    """
    method = {"forces": forces, "refine": refine, "overrides": overrides, "max_frames": max_frames}
    return json.dumps(method, sort_keys=True)


def _tensor(a) -> pa.Array:
    """One row's array as a length-1 nested list array (``None``: a null)."""
    if a is None:
        return None
    a = np.ascontiguousarray(a, dtype=np.float64)
    arr = pa.array(a.ravel(), type=_F64)
    for size in reversed(a.shape[1:]):
        offsets = (
            np.arange(0, len(arr) + 1, size, dtype=np.int32) if size else np.zeros(1, np.int32)
        )
        arr = pa.ListArray.from_arrays(pa.array(offsets), arr)
    return pa.ListArray.from_arrays(pa.array([0, len(arr)], type=pa.int32()), arr)


def rows_to_table(rows: Sequence[dict]) -> pa.Table:
    """Rows (dicts with the schema's column names; arrays as NumPy) as an Arrow table of
    :data:`ROBOT_SCHEMA`; missing columns are null."""
    columns = []
    for field in ROBOT_SCHEMA:
        values = [r.get(field.name) for r in rows]
        if field.name in TENSOR_COLUMNS:
            parts = [_tensor(v) if v is not None else pa.nulls(1, field.type) for v in values]
            columns.append(pa.concat_arrays([p.cast(field.type) for p in parts]))
        else:
            columns.append(pa.array(values, type=field.type))
    return pa.Table.from_arrays(columns, schema=ROBOT_SCHEMA)


def _to_numpy(column: pa.Array, depth: int) -> np.ndarray | None:
    """A length-1 nested list array back to its ``float64`` array (``None`` for a null)."""
    if column.null_count:
        return None
    shape = []
    arr = column
    for _ in range(depth):
        lengths = arr.value_lengths().to_numpy(zero_copy_only=False)
        shape.append(int(lengths[0]) if len(lengths) else 0)
        arr = arr.flatten()
    return np.asarray(arr.to_numpy(zero_copy_only=False), dtype=np.float64).reshape(shape)


def check_robot_dataset(path) -> None:
    """Raise a ``RetargetError`` unless ``path`` is a robot trajectory dataset of a supported
    major version."""
    import lance  # heavy; only where a dataset is opened

    try:
        schema = lance.dataset(str(path)).schema
    except (OSError, ValueError) as e:
        raise RetargetError(f"{path}: not a Lance dataset ({e})") from e
    version = (schema.metadata or {}).get(ROBOT_SCHEMA_VERSION_KEY)
    if version is None:
        raise RetargetError(
            f"{path}: not a robot trajectory dataset (no {ROBOT_SCHEMA_VERSION_KEY.decode()!r} "
            "in its schema metadata); give another --out, or --overwrite to replace it"
        )
    major = int(version.decode().split(".")[0])
    if major != ROBOT_SUPPORTED_MAJOR:
        raise RetargetError(
            f"{path}: robot dataset layout {version.decode()}, this toolkit reads "
            f"{ROBOT_SUPPORTED_MAJOR}.x"
        )


def read_robot_rows(
    path,
    *,
    filter: str | None = None,
    columns: Sequence[str] | None = None,
    status: str | None = None,
) -> list[dict]:
    """The rows of robot trajectory dataset ``path`` as dicts: per-frame arrays as ``float64``
    NumPy arrays (shapes in ``docs/design.md``; ``None`` in failed rows), the JSON columns
    (:data:`JSON_COLUMNS`) parsed, the rest as Python values.

    Args:
        filter: a Lance SQL filter, e.g. ``"hand = 'allegro'"``.
        columns: only these columns (default all).
        status: only rows of this status (``"ok"`` or ``"failed"``).

    >>> import tempfile
    >>> path = Path(tempfile.mkdtemp()) / "R.lance"
    >>> create_empty(path)
    >>> row = {"uuid": "u1", "hand": "panda", "method": method_key(False, False, {}, None),
    ...        "status": "ok", "q": np.zeros((3, 8)), "joint_names": [f"j{i}" for i in range(8)]}
    >>> upsert_rows(path, [row])
    1
    >>> [(r["hand"], r["q"].shape, r["method"]["forces"]) for r in read_robot_rows(path)]
    [('panda', (3, 8), False)]
    """
    import lance  # heavy; only where a dataset is opened

    check_robot_dataset(path)
    if status is not None:
        cond = f"status = '{status}'"
        filter = cond if filter is None else f"({filter}) AND {cond}"
    table = lance.dataset(str(path)).to_table(columns=list(columns) if columns else None,
                                              filter=filter)  # fmt: skip
    out = []
    for i in range(table.num_rows):
        row = {}
        for name in table.column_names:
            col = table.column(name)
            if name in TENSOR_COLUMNS:
                row[name] = _to_numpy(col.slice(i, 1).combine_chunks(), TENSOR_COLUMNS[name])
            else:
                value = col[i].as_py()
                row[name] = json.loads(value) if name in JSON_COLUMNS and value else value
        out.append(row)
    return out


def read_keys(path) -> dict[tuple[str, str, str], str]:
    """``{(uuid, hand, method): status}`` of the rows in ``path`` (no arrays are read)."""
    import lance  # heavy; only where a dataset is opened

    t = lance.dataset(str(path)).to_table(columns=[*KEY_COLUMNS, "status"])
    cols = [t.column(c).to_pylist() for c in (*KEY_COLUMNS, "status")]
    return {(u, h, m): s for u, h, m, s in zip(*cols, strict=True)}


def create_empty(path: Path) -> None:
    """Create an empty robot trajectory dataset at ``path``, replacing what is there: written
    beside it and renamed into place, so a crash leaves the old one or the new one."""
    import lance  # heavy; only where a dataset is written

    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{uuidlib.uuid4().hex[:8]}")
    try:
        lance.write_dataset(ROBOT_SCHEMA.empty_table(), str(tmp), mode="create")
        if path.exists():
            old = path.with_name(f".{path.name}.old-{uuidlib.uuid4().hex[:8]}")
            os.replace(path, old)
            os.replace(tmp, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def upsert_rows(path, rows: Iterable[dict]) -> int:
    """Add ``rows`` to the dataset at ``path`` in one atomic commit: new keys inserted, keys
    present replaced (:data:`KEY_COLUMNS`). Returns the number of rows written."""
    import lance  # heavy; only where a dataset is written

    rows = list(rows)
    if not rows:
        return 0
    table = rows_to_table(rows)
    ds = lance.dataset(str(path))
    (
        ds.merge_insert(list(KEY_COLUMNS))
        .when_matched_update_all()
        .when_not_matched_insert_all()
        .execute(table)
    )
    return len(rows)
