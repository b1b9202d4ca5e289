"""Resolving loader filters (manipulation types, objects, operators) to dataset row positions.

Users name manipulation types and objects the way the taxonomy does (``"palmar_pinch"``,
``"Palmar-Pinch"``, gesture code ``1``), while rows store them however the release spelled them
(``"001-Palmar-Pinch"``, ``"01"``, ``"palmar_pinch"``). The resolution therefore works in three
steps:

1. every filter value is looked up in the taxonomy catalogue (no I/O); a value the catalogue does
   not know is still accepted when a row stores exactly that string (custom objects, release
   codes the catalogue leaves open), otherwise :class:`UnknownNameError` is raised with the
   catalogue's suggestions. Operators have no catalogue: the dataset's own operators are the
   valid values.
2. the stored spellings that map to the requested entries are gathered from the dataset's
   metadata columns (``index``, ``trajectory_metadata``: no frame data is read);
3. a Lance SQL filter over those spellings (:func:`dexcanvas_core.io.build_filter`) is pushed down
   to Lance, and the matching row ids are mapped to 0-based row positions in dataset order.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from dexcanvas_core.builtin import builtin_demonstration_path
from dexcanvas_core.capture.importer import use_dataset_objects
from dexcanvas_core.checks import check_int, check_path
from dexcanvas_core.errors import DatasetError, DexCanvasError, UnknownNameError, ValidationError
from dexcanvas_core.io import LanceTrajectories, build_filter, open_dataset
from dexcanvas_core.taxonomy import Pair, manipulation_type, object_spec

FilterValues = str | int | Iterable[str | int] | None
"""One name or code, several, or ``None`` (no filter)."""


@dataclass(frozen=True)
class Selection:
    """The rows a loader serves."""

    positions: np.ndarray
    """(N,) int64: 0-based row positions in dataset order (for ``LanceTrajectories.take``)."""
    uuids: tuple[str, ...]
    """``index.uuid`` of each selected row, aligned with ``positions``."""
    filter: str | None
    """The Lance SQL filter that was pushed down (``None``: every row)."""


def as_list(values: FilterValues, what: str) -> list[str | int] | None:
    """Normalise a filter argument: ``None`` or an empty sequence → ``None`` (no filter)."""
    if values is None:
        return None
    if isinstance(values, str | int) and not isinstance(values, bool):
        return [values]
    try:
        out = list(values)  # type: ignore[arg-type]
    except TypeError:
        raise ValidationError(
            f"{what} must be a name, a code or a list of them, got {type(values).__name__}",
            field=what,
        ) from None
    return out or None


def _manipulation_lookup() -> Callable[[Any], str]:
    """``value → canonical type name`` through the taxonomy."""
    return lambda v: manipulation_type(v).name


def _object_lookup() -> Callable[[Any], str]:
    """``value → canonical object id`` through the taxonomy."""
    return lambda v: object_spec(v).id


def manipulation_spellings(name: str) -> list[str]:
    """Every spelling of one manipulation type that a release may store (name, aliases, code)."""
    mt = manipulation_type(name)
    out = [mt.name, *mt.aliases]
    if mt.gesture_code is not None:
        c = mt.gesture_code
        out += [str(c), f"{c:02d}", f"{c:03d}"]
    return out


@dataclass
class _Facet:
    """One filterable metadata column: requested values, their resolution, stored values."""

    kind: str  # "manipulation type", "object", "operator"
    column: str  # for messages
    requested: list[str | int] | None
    lookup: Callable[[Any], str] | None  # catalogue: value → canonical key (raises if unknown)
    keys: set[str]  # canonical keys requested (catalogue hits)
    literals: set[str]  # requested values the catalogue does not know (checked against rows)
    pending_error: dict[str, Exception]  # literal value → the catalogue's error

    @classmethod
    def resolve_names(
        cls, kind: str, column: str, requested: list[str | int] | None, lookup
    ) -> _Facet:
        """Step 1 without I/O: look every requested value up in the catalogue."""
        keys: set[str] = set()
        literals: set[str] = set()
        errors: dict[str, Exception] = {}
        for v in requested or []:
            if lookup is None:
                literals.add(str(v))
                continue
            try:
                keys.add(lookup(v))
            except UnknownNameError as e:  # maybe stored as is: decided against the rows
                literals.add(str(v))
                errors[str(v)] = e
        return cls(kind, column, requested, lookup, keys, literals, errors)

    def key_of(self, stored: str, cache: dict[str, str | None]) -> str | None:
        if self.lookup is None:
            return None
        if stored not in cache:
            try:
                cache[stored] = self.lookup(stored)
            except DexCanvasError:  # a stored value the catalogue does not know
                cache[stored] = None
        return cache[stored]

    def stored_values(self, stored: Iterable[str]) -> list[str] | None:
        """Step 2: the stored spellings to push down (``None``: no filter on this column).

        Raises:
            UnknownNameError: a requested value neither the catalogue nor any row knows.
        """
        if not self.requested:
            return None
        present = Counter(stored)
        for v in sorted(self.literals):
            if v not in present:
                if v in self.pending_error:
                    raise self.pending_error[v]
                raise UnknownNameError(self.kind, v, present)
        cache: dict[str, str | None] = {}
        out = {s for s in present if s in self.literals or self.key_of(s, cache) in self.keys}
        if self.kind == "manipulation type":
            # Canonical spellings too, so that the pushed-down list is never empty.
            for k in self.keys:
                out.update(manipulation_spellings(k))
        else:
            out.update(self.keys)
        out.update(self.literals)
        return sorted(out)


def _summary(values: Sequence[str], to_name: Callable[[str], str | None] | None) -> str:
    counts: Counter[str] = Counter()
    for v in values:
        name = None
        if to_name is not None:
            try:
                name = to_name(v)
            except DexCanvasError:  # reported as stored
                name = None
        counts[name or v] += 1
    return ", ".join(f"{k} ({n})" for k, n in sorted(counts.items())) or "nothing"


def select_rows(
    ds: LanceTrajectories,
    *,
    manipulation_types: FilterValues = None,
    objects: FilterValues = None,
    operators: FilterValues = None,
) -> Selection:
    """Resolve the filters to row positions (see the module docstring).

    Raises:
        UnknownNameError: a filter value that is neither in the catalogue nor in the dataset.
        DatasetError: no row matches; the message lists what the dataset contains.
    """
    facets = [
        _Facet.resolve_names(
            "manipulation type",
            "trajectory_metadata.gesture",
            as_list(manipulation_types, "manipulation_types"),
            _manipulation_lookup(),
        ),
        _Facet.resolve_names(
            "object", "index.scene", as_list(objects, "objects"), _object_lookup()
        ),
        _Facet.resolve_names("operator", "index.operator", as_list(operators, "operators"), None),
    ]
    meta = ds.scan_metadata()  # index + trajectory_metadata only: no frames
    index = meta.column("index").combine_chunks()
    md = meta.column("trajectory_metadata").combine_chunks()

    def child(struct, name: str) -> list:
        i = struct.type.get_field_index(name)
        if i < 0:
            raise DatasetError(f"missing metadata field {name!r}", dataset=ds.path)
        return [("" if v is None else str(v)) for v in struct.flatten()[i].to_pylist()]

    stored = {
        "manipulation type": child(md, "gesture"),
        "object": child(index, "scene"),
        "operator": child(index, "operator"),
    }
    uuids_all = child(index, "uuid")
    row_ids_all = meta.column("_rowid").to_numpy()

    values = {f.kind: f.stored_values(stored[f.kind]) for f in facets}
    filt = build_filter(
        manipulation_types=values["manipulation type"],
        objects=values["object"],
        operators=values["operator"],
    )
    if filt is None:
        positions = np.arange(len(row_ids_all), dtype=np.int64)
    else:
        matched = ds.row_ids(filt)  # pushed down to Lance
        where = {int(r): p for p, r in enumerate(row_ids_all)}
        positions = np.array(sorted(where[int(r)] for r in matched), dtype=np.int64)
    if positions.size == 0 and not uuids_all:
        raise DatasetError("the dataset holds no trajectory", dataset=ds.path)
    if positions.size == 0:
        asked = "; ".join(
            f"{f.kind}s={[str(v) for v in f.requested]}" for f in facets if f.requested
        )
        lookup_type = facets[0].lookup
        raise DatasetError(
            f"no trajectory matches {asked}. The dataset holds {len(uuids_all)} trajectories; "
            f"objects: {_summary(stored['object'], None)}; manipulation types: "
            f"{_summary(stored['manipulation type'], lookup_type)}; operators: "
            f"{_summary(stored['operator'], None)}",
            dataset=ds.path,
        )
    return Selection(
        positions=positions,
        uuids=tuple(uuids_all[p] for p in positions),
        filter=filt,
    )


def load_demonstration(pair, index: int = 0, dataset=None):
    """The ``index``-th demonstration (0-based) of ``pair`` (``"cube2/tripod"`` or a ``Pair``)
    in ``dataset`` (a DexCanvas-layout Lance path; ``None``: the built-in demonstration of
    ``pair``, built alone on first use when the whole built-in set is not built,
    ``builtin.builtin_demonstration_path``).

    >>> from dexcanvas_core import load_demonstration
    >>> traj = load_demonstration("cube2/tripod")
    >>> traj.scene, traj.gesture, traj.fps
    ('cube2', 'tripod', 120.0)
    """
    index = check_int("index", index, min=0)
    dataset = check_path("dataset", dataset, optional=True)
    if dataset is None:
        pair = pair if isinstance(pair, Pair) else Pair.parse(pair)
        dataset = builtin_demonstration_path(pair)
    else:
        use_dataset_objects(dataset)
        pair = pair if isinstance(pair, Pair) else Pair.parse(pair)
    ds = open_dataset(dataset)
    sel = select_rows(
        ds, objects=[pair.object.id], manipulation_types=[pair.manipulation_type.name]
    )
    n = len(sel.positions)
    if not 0 <= index < n:
        raise DatasetError(
            f"--index {index} out of range: the dataset has {n} demonstration(s) of {pair}",
            dataset=str(ds.path),
        )
    return ds.take([int(sel.positions[index])])[0]


@dataclass(frozen=True)
class RowSubject:
    """What one dataset row shows: its object and, when the taxonomy knows it, its
    manipulation type (imported captures may carry ``unknown`` or another label).

    ``str()`` gives ``"<object id>/<type name or stored label>"``, like a :class:`Pair`."""

    object: Any
    """The row's :class:`~dexcanvas_core.taxonomy.ObjectSpec` (``index.scene``)."""
    manipulation_type: Any
    """Its :class:`~dexcanvas_core.taxonomy.ManipulationType`, or ``None`` for an unknown label."""
    label: str = "unknown"
    """The stored ``gesture`` when the taxonomy does not know it."""

    def __str__(self) -> str:
        t = self.manipulation_type.name if self.manipulation_type is not None else self.label
        return f"{self.object.id}/{t or 'unknown'}"


def subject_of(traj) -> RowSubject:
    """The :class:`RowSubject` of a trajectory (its ``scene`` and ``gesture``).

    Raises:
        UnknownNameError: the row's object is not in the catalogue nor in the objects given by
            a manifest (the message says how to give it).
    """
    obj = object_spec(traj.scene or traj.object.name)
    try:
        mtype = manipulation_type(traj.gesture) if traj.gesture else None
    except (UnknownNameError, ValidationError):
        mtype = None
    return RowSubject(obj, mtype, str(traj.gesture or "unknown"))


def load_row(dataset, index: int = 0):
    """Row ``index`` (0-based, dataset order) of ``dataset``, with the objects of an imported
    dataset put in use (``dexcanvas_core.capture.use_dataset_objects``).

    Raises:
        DatasetError: no such row (the message gives the row count).
    """
    use_dataset_objects(dataset)
    ds = open_dataset(dataset)
    n = len(ds)
    if isinstance(index, bool) or not isinstance(index, int | np.integer) or not 0 <= index < n:
        raise DatasetError(
            f"--index {index!r} out of range: the dataset has {n} row(s) (0..{n - 1})",
            dataset=str(ds.path),
        )
    return ds.take([int(index)])[0]
