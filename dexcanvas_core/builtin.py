"""The built-in demonstrations: the dataset ``DexCanvasDataset()`` uses when no path is given,
and the single demonstrations ``load_demonstration(pair)`` and the command lines use.

They are generated on first use, deterministically, and cached in the user cache directory
(``$DEXCANVAS_CACHE_DIR`` or the platform's cache dir, e.g. ``~/.cache/dexcanvas-retarget``).
The content comes from :mod:`dexcanvas_core.demos`: the built-in subset of feasible
(object, manipulation type) pairs (``demos.builtin_pairs``), one demonstration each, operators
cycling, seed 0, every demonstration passing the plausibility checks (``demos.builtin_plan``).

* :func:`default_dataset_path` — the whole set, one Lance dataset
  (``builtin-demos-v<version>.lance``), built in parallel over the CPU cores;
* :func:`builtin_demonstration_path` — one pair's demonstration only, the row the whole set
  holds for it (same operator and seed), built alone in a few seconds and cached per pair
  (``builtin-demos-v<version>-pairs/<object>.<type>.lance``); the whole set, when already
  built, serves it instead.

Every build writes into a temporary directory renamed into place (``io.write_dataset``) under a
per-destination lock, so concurrent first uses build once and readers never see a partial
dataset. The build report is written next to each dataset (``<dataset>.report.json``). No
network is needed.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import sys
from pathlib import Path

from dexcanvas_core.cache import cache_dir
from dexcanvas_core.checks import check_str_seq
from dexcanvas_core.demos import DEMOS_VERSION, DemoError, build_builtin, builtin_plan
from dexcanvas_core.errors import DatasetError
from dexcanvas_core.taxonomy import OBJECTS, Pair, custom_objects

log = logging.getLogger(__name__)


def builtin_dataset_name() -> str:
    """File name of the cached built-in dataset: changes with the generator's version and with
    the models given to catalogue objects (``--objects``, ``--objects-dir``), since the
    demonstrations are generated on the shapes in use."""
    given = [s for s in custom_objects().values() if s.id in OBJECTS]
    return f"builtin-demos-v{DEMOS_VERSION}{_shapes_suffix(given)}.lance"


def _shapes_suffix(specs) -> str:
    """``""`` for the built-in shapes, else ``-objects-<hash>`` of the given models (file
    contents, scale, mass, friction)."""
    if not specs:
        return ""
    h = hashlib.sha256()
    for spec in sorted(specs, key=lambda s: s.id):
        h.update(f"{spec.id}|{spec.mesh_scale!r}|{spec.mass_kg!r}|{spec.friction!r}|".encode())
        h.update(Path(spec.mesh).read_bytes())
    return f"-objects-{h.hexdigest()[:12]}"


@contextlib.contextmanager
def _build_lock(path: Path):
    """Serialise concurrent first builds (POSIX advisory lock; no-op elsewhere)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    lock = path.with_name(path.name + ".lock")
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield
        return
    with open(lock, "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _built(path: Path) -> bool:
    """Whether a Lance dataset is complete at ``path`` (it is renamed into place whole)."""
    return (path / "_versions").is_dir()


def default_dataset_path(progress: bool | None = None, workers: int | None = None) -> Path:
    """Path of the whole built-in set, building it on first use.

    Args:
        progress: show a progress bar on stderr naming what is built and where (default:
            when stderr is a terminal).
        workers: processes generating demonstrations (default ``os.cpu_count()``; the content
            does not depend on it).
    """
    path = cache_dir() / builtin_dataset_name()
    if _built(path):
        return path
    with _build_lock(path):
        if not _built(path):  # another process may have built it meanwhile
            workers = workers or os.cpu_count() or 1
            log.info("building the built-in dataset at %s (%d processes)", path, workers)
            build_builtin(path, progress=_show(progress), workers=workers)
    return path


def builtin_pair_path(pair) -> Path:
    """Where one pair's built-in demonstration is cached (``"cube2/tripod"`` or a ``Pair``).

    >>> from dexcanvas_core import builtin_pair_path
    >>> builtin_pair_path("cube2/tripod").name
    'cube2.tripod.lance'
    """
    p = pair if isinstance(pair, Pair) else Pair.parse(pair)
    folder = cache_dir() / f"builtin-demos-v{DEMOS_VERSION}-pairs"
    shape = _shapes_suffix([p.object] if p.object.mesh else [])
    return folder / f"{p.object.id}.{p.manipulation_type.name}{shape}.lance"


def builtin_demonstration_cached(pair) -> Path | None:
    """The dataset already holding ``pair``'s built-in demonstration (the whole set, else the
    pair's own), or None when using it would build it."""
    pair = pair if isinstance(pair, Pair) else Pair.parse(pair)  # a bad pair fails here
    whole = cache_dir() / builtin_dataset_name()
    if _built(whole):
        return whole
    own = builtin_pair_path(pair)
    return own if _built(own) else None


def builtin_demonstration_path(pair, progress: bool | None = None) -> Path:
    """A dataset holding the built-in demonstration of ``pair``: the whole set when it is
    built, else the pair's own (built now if needed: the row the whole set holds for it).

    Args:
        pair: ``"cube2/tripod"`` or a ``Pair``.
        progress: show a progress indication on stderr while building (default: when stderr
            is a terminal).

    Raises:
        DatasetError: the pair is not in the built-in set, or its demonstration fails the
            plausibility checks (the whole set leaves it out too); the message says which and
            how to proceed.

    >>> from dexcanvas_core import builtin_demonstration_path
    >>> builtin_demonstration_path("cube2/tripod").suffix
    '.lance'
    """
    cached = builtin_demonstration_cached(pair)
    if cached is not None:
        return cached
    builtin_plan([pair])  # raises DatasetError for a pair the built-in set does not hold
    path = builtin_pair_path(pair)
    with _build_lock(path):
        if not _built(path):  # another process may have built it meanwhile
            log.info("building the built-in demonstration of %s at %s", pair, path)
            try:
                build_builtin(path, progress=_show(progress), pairs=[pair])
            except DemoError as e:
                raise DatasetError(
                    f"the built-in demonstration of {pair} does not pass the plausibility "
                    f"checks, so the built-in set leaves it out ({e}); use another pair or "
                    "give a dataset that has it (--dataset PATH)",
                    dataset=str(path),
                ) from e
    return path


def _show(progress: bool | None) -> bool:
    return sys.stderr.isatty() if progress is None else bool(progress)


def rebuild_builtin(
    pairs=None, progress: bool | None = None, workers: int | None = None
) -> list[Path]:
    """Build the built-in demonstrations again, replacing what the cache holds (a corrupt or
    partial copy included); the paths built.

    Args:
        pairs: ``None``: the whole set (:func:`default_dataset_path`'s dataset); else only these
            pairs' own caches (:func:`builtin_pair_path`, ``"cube2/tripod"`` or ``Pair``).
        progress: show a progress bar on stderr (default: when stderr is a terminal).
        workers: processes generating the whole set (default ``os.cpu_count()``).

    Raises:
        ValidationError: ``pairs`` is a single string instead of a list.
        DatasetError: a pair that the built-in set does not hold.
    """
    if pairs is None:
        path = cache_dir() / builtin_dataset_name()
        with _build_lock(path):
            workers = workers or os.cpu_count() or 1
            log.info("rebuilding the built-in dataset at %s (%d processes)", path, workers)
            build_builtin(path, progress=_show(progress), workers=workers)
        return [path]
    if isinstance(pairs, str | bytes):
        check_str_seq("pairs", pairs)  # raises: one pair is written ["cube2/tripod"]
    pairs = tuple(pairs)
    builtin_plan(list(pairs))  # raises DatasetError for a pair the built-in set does not hold
    built = []
    for pair in pairs:
        path = builtin_pair_path(pair)
        with _build_lock(path):
            log.info("rebuilding the built-in demonstration of %s at %s", pair, path)
            build_builtin(path, progress=_show(progress), pairs=[pair])
        built.append(path)
    return built
