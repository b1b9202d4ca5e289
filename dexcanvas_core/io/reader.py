"""Reading DexCanvas-layout Lance datasets into :class:`~dexcanvas_core.trajectory.Trajectory`.

``open_dataset(path)`` checks that the path holds a readable Lance dataset in the expected layout
and returns a :class:`LanceTrajectories`: row count, summary (``info``), random access, and a
streaming iterator with filters pushed down to Lance (manipulation type, object, operator), so
memory stays flat on datasets larger than RAM. Rows are decoded by :mod:`.decode`.
"""

from __future__ import annotations

import logging
import os
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from dexcanvas_core.cache import cache_dir
from dexcanvas_core.checks import check_path, check_str, check_str_seq
from dexcanvas_core.errors import DatasetError, DexCanvasError
from dexcanvas_core.io.decode import _child, row_to_trajectory
from dexcanvas_core.io.schema import (
    REQUIRED_COLUMNS,
    SCHEMA_VERSION_KEY,
    SUPPORTED_MAJOR,
)
from dexcanvas_core.taxonomy import manipulation_type
from dexcanvas_core.trajectory import (
    Trajectory,
)

log = logging.getLogger(__name__)

os.environ.setdefault("LANCE_LOG", "error")


def _lance():
    import lance

    return lance


def corrupt_hint(path: str | os.PathLike) -> str:
    """How to repair a corrupt or partial dataset at ``path``: a cached built-in one is rebuilt
    by ``dexcanvas cache rebuild``; any other is rebuilt by whatever made it, or copied again."""
    p = Path(path).expanduser().resolve()
    if p.is_relative_to(cache_dir().expanduser().resolve()):
        return (
            "it is a cached built-in dataset: run `dexcanvas cache rebuild` (the whole set) or "
            "`dexcanvas cache rebuild --pairs OBJECT/TYPE` (one pair's cache)"
        )
    return "rebuild it with the command that made it, or copy it again"


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
    names and numeric codes pass every spelling of the same type. Each filter is a list of
    values (``None`` or empty: no filter); a single ``str`` is refused, not read letter by
    letter.

    Raises:
        ValidationError: a filter that is not a list of strings (``manipulation_types``: or
            int codes), or an ``extra`` that is not a string.

    >>> build_filter(objects=["cube2"])
    "index.scene IN ('cube2')"
    """
    manipulation_types = check_str_seq("manipulation_types", manipulation_types, codes=True)
    objects = check_str_seq("objects", objects)
    operators = check_str_seq("operators", operators)
    extra = check_str("extra", extra, optional=True, empty=True)
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
                f"cannot read: {e}. The dataset is corrupt or partially written; "
                + corrupt_hint(self.path),
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

    >>> from dexcanvas_core import builtin_demonstration_path, open_dataset
    >>> ds = open_dataset(builtin_demonstration_path("cube2/tripod"))
    >>> len(ds) >= 1, ds.get(0).fps
    (True, 120.0)
    """
    p = check_path("path", path).expanduser()
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
            f"cannot open: {e}. The dataset is corrupt or partially written; " + corrupt_hint(p),
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
