"""The built-in set: the generated demonstrations ``DexCanvasDataset()`` uses without a path.

A documented subset of the feasible pairs (``builtin_pairs``): every manipulation type with up
to three objects, chosen so that every light object of the catalogue appears (heavy duplicates
share their light base's geometry and are left out), operators cycling through the five hand
sizes, seed 0 (``builtin_plan``). ``build_builtin`` builds the whole set, or single pairs as the
whole set holds them (the cold start of ``retarget run``); pairs that fail the checks are left
out of the dataset and listed in the report.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Sequence
from pathlib import Path

from dexcanvas_core.demos.build import BuildReport, _plan, write_plan
from dexcanvas_core.demos.feasibility import feasible_pairs
from dexcanvas_core.errors import DatasetError
from dexcanvas_core.taxonomy import MANIPULATION_TYPES, Pair

log = logging.getLogger(__name__)

BUILTIN_PER_TYPE = 3

FEATURED_PAIRS: tuple[str, ...] = ("cube2/tripod", "sphere1/sphere_4_finger")
"""Pairs the built-in set always contains: the README's main job (``retarget run --hand shadow
--pair cube2/tripod``) and the demonstrations the documentation uses."""
"""Objects per manipulation type in the built-in set."""


def builtin_pairs(per_type: int = BUILTIN_PER_TYPE) -> list[Pair]:
    """The built-in set's pairs (deterministic): every light object once, on the type where
    it is feasible that has the fewest pairs so far; then every type filled up to
    ``per_type`` objects, objects used least first (catalogue order breaks ties)."""
    light = [p for p in feasible_pairs() if not p.object.heavy]
    by_type: dict[str, list[Pair]] = {t: [] for t in MANIPULATION_TYPES}
    for p in light:
        by_type[p.manipulation_type.name].append(p)
    chosen: dict[str, list[Pair]] = {t: [] for t in MANIPULATION_TYPES}
    uses: dict[str, int] = {}
    types = list(MANIPULATION_TYPES)
    for name in FEATURED_PAIRS:
        p = Pair.parse(name)
        if p in light:
            chosen[p.manipulation_type.name].append(p)
            uses[p.object.id] = uses.get(p.object.id, 0) + 1
    for oid in dict.fromkeys(p.object.id for p in light):
        options = [p for p in light if p.object.id == oid]
        options = [p for p in options if len(chosen[p.manipulation_type.name]) < per_type]
        if not options:
            continue
        p = min(options, key=lambda p: (len(chosen[p.manipulation_type.name]),
                                        types.index(p.manipulation_type.name)))  # fmt: skip
        chosen[p.manipulation_type.name].append(p)
        uses[oid] = uses.get(oid, 0) + 1
    for t in types:
        cands = [p for p in by_type[t] if p not in chosen[t]]
        while len(chosen[t]) < per_type and cands:
            p = min(cands, key=lambda p: (uses.get(p.object.id, 0), cands.index(p)))
            cands.remove(p)
            chosen[t].append(p)
            uses[p.object.id] = uses.get(p.object.id, 0) + 1
    return [p for t in types for p in sorted(chosen[t], key=light.index)]


def builtin_plan(pairs: Sequence[str | Pair] | None = None) -> list[tuple[Pair, str, int]]:
    """The built-in set's ``(pair, operator, seed)`` items (``builtin_pairs``, seed 0, one
    demonstration each, operators cycling over the whole set), or those of ``pairs`` only —
    with the operator and seed the whole set gives them, so a pair built alone is the row the
    whole set holds for it.

    Raises:
        DatasetError: a pair that is not in the built-in set (the message lists those that are).
    """
    plan = _plan(builtin_pairs(), 1, 0)
    if pairs is None:
        return plan
    wanted = [p if isinstance(p, Pair) else Pair.parse(p) for p in pairs]
    known = {item[0] for item in plan}
    missing = [str(p) for p in wanted if p not in known]
    if missing:
        raise DatasetError(
            f"no built-in demonstration of {', '.join(missing)}; the built-in set holds "
            f"{', '.join(sorted(str(p) for p in known))}. Give a dataset that has it (--dataset "
            "PATH) or build one (dexcanvas demos build --pairs ...)",
            dataset="built-in",
        )
    return [item for item in plan if item[0] in wanted]


def build_builtin(
    out: str | os.PathLike,
    progress: bool = False,
    workers: int = 1,
    pairs: Sequence[str | Pair] | None = None,
) -> BuildReport:
    """Build the built-in set (``builtin_plan``: ``builtin_pairs``, seed 0, one demonstration
    each) at ``out``, replacing what is there, and write its report next to it (``workers``
    processes; the content does not depend on it). ``pairs``: only these built-in pairs, each
    the row the whole set holds for it (same operator and seed).

    Raises:
        DatasetError: a pair of ``pairs`` that is not in the built-in set.
        DemoError: no demonstration passed the checks.
    """
    t0 = time.perf_counter()
    out = Path(out).expanduser()
    plan = builtin_plan(pairs)
    report = BuildReport(out=out)
    write_plan(out, plan, report, overwrite=True, progress=progress, workers=workers)
    report.seconds = time.perf_counter() - t0
    report.write_json()
    if report.failed:
        log.warning(
            "built-in set: %d pairs left out: %s",
            len(report.failed),
            "; ".join(f"{k}: {v}" for k, v in report.failed.items()),
        )
    return report
