"""Writing trajectories as DexCanvas-layout Lance datasets (and Parquet for other tools).

The writer is schema-driven: every field of the target schema is filled from the trajectory
attribute it maps to, or from ``Trajectory.extras`` for fields this toolkit does not interpret.
Passing the source dataset's schema therefore writes rows back exactly as they were read (the
encoding is :mod:`.encode`).

Writes are atomic: a new dataset is written next to the destination and renamed into place, so a
crash leaves either the old dataset or none, never a partial one. Appends use Lance's own
atomic commits. One process writes a destination at a time (its
:func:`~dexcanvas_core.safe_io.output_lock`; a second gets ``OutputBusyError``).
"""

from __future__ import annotations

import logging
import os
import shutil
import uuid as uuidlib
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Literal

import pyarrow as pa

from dexcanvas_core.errors import DatasetError
from dexcanvas_core.io.encode import schema_for, trajectories_to_batch
from dexcanvas_core.io.reader import open_dataset
from dexcanvas_core.io.schema import SCHEMA_VERSION, SCHEMA_VERSION_KEY
from dexcanvas_core.safe_io import atomic_path, check_output, output_lock, replace_dir
from dexcanvas_core.trajectory import Trajectory

log = logging.getLogger(__name__)

os.environ.setdefault("LANCE_LOG", "error")


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
    dest = Path(path).expanduser()
    if mode not in ("create", "overwrite", "append"):
        raise DatasetError(f"unknown write mode {mode!r}; use create, overwrite or append")
    dest.parent.mkdir(parents=True, exist_ok=True)
    with output_lock(dest):  # one writer per dataset (OutputBusyError for a second one)
        return _write_dataset(trajectories, dest, mode, schema, batch_rows, validate)


def _write_dataset(trajectories, dest: Path, mode, schema, batch_rows, validate) -> Path:
    import lance

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
    tmp = dest.with_name(f".{dest.name}.tmp-{uuidlib.uuid4().hex[:8]}")
    try:
        _lance_write(lance, pa.RecordBatchReader.from_batches(schema, batches), tmp, "create", enc)
        replace_dir(tmp, dest)
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


def export_parquet(
    source: str | os.PathLike,
    dest: str | os.PathLike,
    *,
    filter: str | None = None,
    batch_size: int = 16,
    overwrite: bool = False,
) -> Path:
    """Copy a Lance dataset (optionally filtered) to one Parquet file, streaming and atomic
    (:func:`dexcanvas_core.safe_io.atomic_path`, under the file's :func:`output_lock`).

    Raises:
        dexcanvas_core.safe_io.OutputError: ``dest`` exists and ``overwrite`` is false, is a
            directory, or cannot be written (checked before reading anything).
    """
    import pyarrow.parquet as pq

    dest = check_output(dest, overwrite=overwrite, kind="file", what="--parquet")
    ds = open_dataset(source)
    schema = ds.schema
    with output_lock(dest), atomic_path(dest) as tmp:
        with pq.ParquetWriter(str(tmp), schema) as w:
            for batch in ds.iter_batches(filter=filter, batch_size=batch_size):
                w.write_batch(batch.select(schema.names))
    return dest
