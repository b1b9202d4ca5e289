"""Loading the demonstration a run retargets: a pair of the built-in set (built on first use),
a pair of a DexCanvas Lance dataset, or one of its rows; a heavy object without a
demonstration of its own borrows its light twin's (same shape)."""

from __future__ import annotations

import logging

from rich.console import Console

from dexcanvas_core.builtin import (
    builtin_demonstration_cached,
    builtin_demonstration_path,
    builtin_pair_path,
)
from dexcanvas_core.capture import use_dataset_objects
from dexcanvas_core.demos import builtin_pairs
from dexcanvas_core.errors import DatasetError, DexCanvasError
from dexcanvas_core.loaders.selection import load_demonstration, load_row, subject_of
from dexcanvas_core.taxonomy import Pair
from retarget.errors import RetargetError

log = logging.getLogger(__name__)


def load_subject(pair: str | None = None, dataset=None, index: int = 0, progress: bool = False):
    """``(trajectory, subject, substituted)``: the demonstration named by ``pair``
    (``"OBJECT/TYPE"``) or, without a pair, the ``dataset`` row ``index``; what it shows (a
    ``Pair``, or for a row taken without ``pair`` a ``RowSubject``); and the pair whose
    demonstration stands in for it (``None``: its own).

    ``dataset``: a DexCanvas Lance dataset; ``None``: the built-in demonstrations (built on
    first use, with a progress bar when ``progress``). ``index``: which demonstration of the
    pair (0-based); without a pair, which row.

    Raises:
        RetargetError: neither ``pair`` nor ``dataset``, or no such demonstration.
    """
    if pair is None:
        if dataset is None:
            raise RetargetError(
                "say which demonstration: --pair OBJECT/TYPE (built-in data), or --dataset D "
                "--index I"
            )
        try:
            traj = load_row(dataset, index)  # puts the dataset's objects in use
            return traj, subject_of(traj), None
        except DexCanvasError as e:
            raise RetargetError(str(e)) from e
    subject = parse_pair(pair, dataset)
    traj, substituted = _load_demonstration(subject, dataset, index, progress)
    return traj, subject, substituted


def parse_pair(pair: str, dataset=None):
    """``pair`` (``"OBJECT/TYPE"``) as a ``Pair``, with ``dataset``'s imported objects in use
    first (``None``: the built-in catalogue); a one-line ``RetargetError`` when it names no
    known object or type."""
    try:
        if dataset is not None:
            use_dataset_objects(dataset)
        return Pair.parse(pair)
    except DexCanvasError as e:
        raise RetargetError(str(e)) from e


def _load_demonstration(pair, dataset, index: int, progress: bool):
    """The demonstration of ``pair``; for a heavy object without one of its own (the built-in
    data has light objects only), the light object's demonstration, to be simulated with the
    heavy object (same shape, its mass) — said on the terminal and in ``metrics.json``."""

    def load(p):
        if dataset is None:
            _ensure_builtin(p, progress)
        return load_demonstration(p, index, dataset)

    try:
        return load(pair), None
    except DatasetError as e:
        base = pair.object.base_id
        if not pair.object.heavy or base is None:
            raise RetargetError(str(e)) from e
        light = Pair.parse(f"{base}/{pair.manipulation_type.name}")
        try:
            traj = load(light)
        except DatasetError:
            raise RetargetError(str(e)) from e
        log.warning(
            "no %s demonstration: using %s's with the %s object", pair, light, pair.object.id
        )
        return traj, str(light)


def _ensure_builtin(pair, progress: bool) -> None:
    """Build the built-in demonstration of ``pair`` if it is not cached yet, saying so on the
    terminal first (``progress``; else in the log) with where it is cached, then showing the
    build's progress bar (``builtin.builtin_demonstration_path``).

    Raises:
        DatasetError: ``pair`` is not in the built-in set, or its demonstration fails the
            checks.
    """
    if builtin_demonstration_cached(pair) is not None:
        return
    if pair not in builtin_pairs():
        builtin_demonstration_path(pair)  # raises the DatasetError that says so
    line = (
        f"building the built-in demonstration {pair} (first use; cached in "
        f"{builtin_pair_path(pair)})"
    )
    if progress:
        Console(stderr=True, highlight=False).print(line, markup=False)
    else:
        log.info("%s", line)
    builtin_demonstration_path(pair, progress=progress)
