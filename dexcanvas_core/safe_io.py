"""Safe outputs: whole-or-nothing files, one writer per output, checks before any work.

* :func:`atomic_path` — a unique temporary file beside the target (``.<name>.<random>.tmp``,
  mode 0o644), synced and renamed over the target when the block ends, removed on any error;
  :func:`atomic_write_bytes` and :func:`atomic_write_text` write through it. A reader sees
  the old file or the new one, never a part; a process killed mid-write leaves at most the
  hidden temporary file.
* :func:`output_lock` — an exclusive, non-blocking ``flock`` that one process holds while it
  writes an output; a second process asking for it gets :class:`OutputBusyError` naming the
  holder. The kernel drops the lock when its holder dies (also on ``kill -9``).
* :func:`check_output` — before any work: an existing output without ``--overwrite``, a
  directory that cannot be written, a file where a directory is wanted (or the reverse),
  too little free space; each a one-line :class:`OutputError`.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import shutil
import sys
import tempfile
import threading
import uuid as uuidlib
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Literal

from dexcanvas_core.errors import DexCanvasError

MIN_FREE_BYTES = 50 * 1024**2
"""Free space [bytes] an output's file system must have before a command starts (50 MiB)."""

FILE_MODE = 0o644
"""Mode of files written through :func:`atomic_path` (readable by all, writable by the owner)."""
DIR_MODE = 0o755
"""Mode of directories written through :func:`atomic_dir` (the same, listable by all)."""

LOCK_NAME = ".dexcanvas-output.lock"
"""Name of the lock file inside an output directory (:func:`output_lock`, ``where='inside'``)."""


class OutputError(DexCanvasError):
    """An output that cannot or must not be written (exists, read-only, wrong kind, disk full)."""


class OutputExistsError(OutputError, FileExistsError):
    """An output that exists, written without ``overwrite``."""

    def __str__(self) -> str:  # FileExistsError would format (errno, strerror)
        return str(self.args[0])


class OutputBusyError(OutputError):
    """An output that another live process is writing (it holds :func:`output_lock`)."""


# ---------------------------------------------------------------------------- atomic files


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, suffix: str = ".tmp") -> Iterator[Path]:
    """Yield a unique temporary path in ``path``'s directory; when the block ends, sync it and
    rename it over ``path``; on any exception remove it and leave ``path`` as it was.

    For writers that need a file name (``np.savez``, Parquet, matplotlib: pass the format
    explicitly, the name ends in ``suffix``). The parent directory is created.

    >>> import tempfile
    >>> target = Path(tempfile.mkdtemp()) / "a.txt"
    >>> with atomic_path(target) as tmp:
    ...     _ = tmp.write_text("whole")
    >>> target.read_text(), sorted(p.name for p in target.parent.iterdir())
    ('whole', ['a.txt'])
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix)
    os.close(fd)
    tmp = Path(name)
    try:
        os.chmod(tmp, FILE_MODE)
        yield tmp
        _fsync(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_dir(path.parent)


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` whole or not at all (:func:`atomic_path`); return the path."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return path


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` whole or not at all (:func:`atomic_path`)."""
    return atomic_write_bytes(path, text.encode("utf-8"))


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a new empty temporary directory beside directory ``path``; when the block ends,
    put it in ``path``'s place (an existing ``path`` is swapped out, then removed:
    :func:`replace_dir`); on any exception remove it and leave ``path`` as it was.

    For outputs that are a whole directory of files (an export, a Lance dataset).

    >>> import tempfile
    >>> target = Path(tempfile.mkdtemp()) / "out"
    >>> with atomic_dir(target) as tmp:
    ...     _ = (tmp / "a.txt").write_text("whole")
    >>> sorted(p.name for p in target.iterdir()), sorted(p.name for p in target.parent.iterdir())
    (['a.txt'], ['out'])
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp"))
    try:
        os.chmod(tmp, DIR_MODE)
        yield tmp
        replace_dir(tmp, path)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    _fsync_dir(path.parent)


def replace_dir(src: Path, dest: Path) -> None:
    """Move directory ``src`` to ``dest``; an existing ``dest`` is swapped out first, then
    removed (when the second rename fails, it is put back)."""
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


def _fsync(path: Path) -> None:
    if not path.is_file():  # a writer that made a directory (nothing to sync as one file)
        return
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(d: Path) -> None:
    """Make the rename durable; file systems that cannot sync a directory are skipped."""
    try:
        fd = os.open(d, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


# ---------------------------------------------------------------------------- the lock

_held: dict[Path, int] = {}
"""Lock files this process holds → nesting depth (a second ``flock`` on a new descriptor
would conflict with our own; nested :func:`output_lock` calls share the first)."""
_held_guard = threading.Lock()


def lock_path(path: str | os.PathLike, where: Literal["beside", "inside"] = "beside") -> Path:
    """The lock file of output ``path``: ``.<name>.lock`` beside it (a file, or a directory
    replaced whole such as a Lance dataset), or :data:`LOCK_NAME` inside it (a directory whose
    files are written one by one, such as a run directory)."""
    path = Path(path).absolute()
    return path / LOCK_NAME if where == "inside" else path.parent / f".{path.name}.lock"


@contextlib.contextmanager
def output_lock(
    path: str | os.PathLike, *, where: Literal["beside", "inside"] = "beside"
) -> Iterator[Path]:
    """Hold the exclusive lock of output ``path`` (:func:`lock_path`) while the block runs.

    Non-blocking: when another live process holds it, raise :class:`OutputBusyError` naming
    that process. Re-entrant within a process. The lock file holds the holder's pid and
    command line and is removed on release (a killed holder leaves it, unlocked and harmless).

    >>> import tempfile
    >>> out = Path(tempfile.mkdtemp()) / "data.parquet"
    >>> with output_lock(out) as lock:
    ...     lock.name
    '.data.parquet.lock'
    >>> lock.exists()
    False
    """
    lock = lock_path(path, where)
    with _held_guard:
        if lock in _held:
            _held[lock] += 1
            fd = None
        else:
            fd = _acquire(lock, Path(path))
            _held[lock] = 1
    try:
        yield lock
    finally:
        with _held_guard:
            _held[lock] -= 1
            if _held[lock] == 0:
                del _held[lock]
                if fd is not None:
                    _release(lock, fd)


def _acquire(lock: Path, output: Path) -> int:
    lock.parent.mkdir(parents=True, exist_ok=True)
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, FILE_MODE)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as e:
            holder = _holder(fd)
            os.close(fd)
            if e.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise
            raise OutputBusyError(
                f"{output} is being written by another process ({holder}); wait for it to "
                f"finish or choose another output (lock: {lock})"
            ) from None
        # The file we locked must still be the lock file: a holder that released between our
        # open and our flock has unlinked it, and a third process may have made a new one.
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(lock))
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    os.ftruncate(fd, 0)
    os.write(fd, f"pid {os.getpid()}: {' '.join(sys.argv)}\n".encode())
    return fd


def _release(lock: Path, fd: int) -> None:
    try:
        lock.unlink(missing_ok=True)  # unlink while locked: no one can lock this file after
    finally:
        os.close(fd)


def _holder(fd: int) -> str:
    try:
        text = os.pread(fd, 4096, 0).decode(errors="replace").strip()
    except OSError:
        text = ""
    return text.splitlines()[0] if text else "pid unknown"


# ---------------------------------------------------------------------------- preflight


def check_output(
    path: str | os.PathLike,
    *,
    overwrite: bool,
    kind: Literal["file", "dir"] = "file",
    what: str = "--out",
    contents: Iterable[str] | None = None,
    min_free_bytes: int = MIN_FREE_BYTES,
) -> Path:
    """Check, before any work, that output ``path`` may be written; return it as a ``Path``.

    Args:
        path: the output: a file (``kind='file'``) or a directory (``kind='dir'``).
        overwrite: an existing output may be replaced (``--overwrite``).
        kind: what ``path`` must be when it exists.
        what: the option that named it, for the messages.
        contents: for a directory: the names whose presence inside makes it an existing
            output (a run directory holds ``metrics.json``); ``None``: the directory itself.
        min_free_bytes: free space [bytes] the file system must have.

    Raises:
        OutputExistsError: the output exists and ``overwrite`` is false.
        OutputError: ``path`` or a parent is a file where a directory is wanted (or ``path``
            a directory where a file is), the directory cannot be written, or the disk has
            less than ``min_free_bytes`` free.
    """
    path = Path(path).expanduser()
    if path.exists():
        if kind == "dir" and not path.is_dir():
            raise OutputError(f"{what} {path} is a file; give a directory")
        if kind == "file" and path.is_dir():
            raise OutputError(f"{what} {path} is a directory; give a file name")
        names = [path] if contents is None else [path / n for n in contents]
        found = [p for p in names if p.exists()]
        if found and not overwrite:
            held = (
                f"{path} already exists"
                if contents is None
                else (f"{path} already holds {found[0].name}")
            )
            raise OutputExistsError(f"{what} {held}; pass --overwrite to replace it")
    # The nearest directory that exists must be writable (files go in it, or it takes the
    # missing directories); a file on the way makes the path impossible.
    base = path if (kind == "dir" and path.is_dir()) else path.parent
    while not base.exists():
        base = base.parent
    if not base.is_dir():
        raise OutputError(f"{what} {path}: {base} is a file, not a directory")
    need = [base]
    if kind == "dir" and contents is None and path.is_dir():
        need.append(path.parent)  # a directory replaced whole: its temporary is a sibling
    for d in need:
        if not os.access(d, os.W_OK | os.X_OK):
            raise OutputError(f"{what} {path}: cannot write in {d} (read-only or not yours)")
    free = shutil.disk_usage(base).free
    if free < min_free_bytes:
        raise OutputError(
            f"{what} {path}: only {free / 1024**2:.0f} MiB free on its disk (at least "
            f"{min_free_bytes / 1024**2:.0f} MiB needed); free space or choose another place"
        )
    return path
