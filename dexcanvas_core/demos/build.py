"""Building demonstration datasets: many pairs × operators × seeds → a checked Lance dataset.

``build_demos`` generates the demonstrations one by one, streams those that pass every
plausibility check into a DexCanvas-layout Lance dataset (``io.write_dataset``) and returns a
:class:`BuildReport` with every demonstration's checks and the pairs that failed, with the
reason. ``run_build(BuildConfig(...))`` is what ``dexcanvas demos build`` calls; it also writes
the report as JSON next to the dataset (``<out>.report.json``).

The built-in set that ``DexCanvasDataset()`` uses is chosen in :mod:`.builtin_set`.
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

from dexcanvas_core.demos.demo import Demo, DemoError, generate_demo
from dexcanvas_core.demos.feasibility import feasibility, feasible_pairs
from dexcanvas_core.demos.operators import OPERATORS
from dexcanvas_core.errors import DatasetError, ValidationError
from dexcanvas_core.io import write_dataset
from dexcanvas_core.safe_io import atomic_write_text, check_output
from dexcanvas_core.taxonomy import Pair

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class BuildConfig:
    """What ``dexcanvas demos build`` builds."""

    out: Path
    """Destination Lance dataset (a directory, conventionally ``*.lance``)."""
    pairs: tuple[str, ...] | None = None
    """Pairs ``object/manipulation_type``; ``None`` = every feasible pair of the catalogue."""
    reps: int = 1
    """Demonstrations per pair (seeds ``seed … seed + reps - 1``, operators cycling), ≥ 1."""
    seed: int = 0
    """First seed (object pose, posture variation, timing), ≥ 0."""
    overwrite: bool = False
    """Replace an existing dataset at ``out``."""
    workers: int = 1
    """Processes generating demonstrations, ≥ 1 (the output does not depend on it)."""

    def validate(self) -> BuildConfig:
        """Check the fields and parse the pairs (unknown names list close matches)."""
        if not isinstance(self.reps, int) or self.reps < 1:
            raise ValidationError(f"reps must be an integer ≥ 1, got {self.reps!r}", field="reps")
        if not isinstance(self.workers, int) or self.workers < 1:
            raise ValidationError(
                f"workers must be an integer ≥ 1, got {self.workers!r}", field="workers"
            )
        if not isinstance(self.seed, int) or self.seed < 0:
            raise ValidationError(f"seed must be an integer ≥ 0, got {self.seed!r}", field="seed")
        if self.pairs is not None:
            if not self.pairs:
                raise ValidationError("pairs is empty; give at least one or None for all")
            for p in self.pairs:
                Pair.parse(p)  # raises UnknownNameError / ValidationError with suggestions
        check_output(self.out, overwrite=self.overwrite, kind="dir")
        return self


@dataclass
class DemoRecord:
    """One generated demonstration in a build report."""

    pair: str
    operator: str
    seed: int
    uuid: str
    passed: bool
    frames: int
    seconds: float
    summary: str
    checks: dict = field(default_factory=dict)
    grasp: dict = field(default_factory=dict)
    notes: dict = field(default_factory=dict)


@dataclass
class BuildReport:
    """What a build produced: per-demonstration checks, failures and skipped pairs."""

    out: Path
    demos: list[DemoRecord] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    """Pair → why its demonstrations were left out (failed checks or generation errors)."""
    skipped: dict[str, str] = field(default_factory=dict)
    """Requested pairs that are not feasible → the feasibility table's reason."""
    written: int = 0
    seconds: float = 0.0

    @property
    def passed(self) -> int:
        return sum(d.passed for d in self.demos)

    @property
    def all_passed(self) -> bool:
        return bool(self.demos) and all(d.passed for d in self.demos)

    def to_dict(self) -> dict:
        return {
            "out": str(self.out),
            "written": self.written,
            "generated": len(self.demos),
            "passed": self.passed,
            "seconds": round(self.seconds, 2),
            "failed_pairs": dict(self.failed),
            "skipped_pairs": dict(self.skipped),
            "demos": [asdict(d) for d in self.demos],
        }

    def write_json(self, path: str | os.PathLike | None = None) -> Path:
        """Write the report as JSON (default: ``<out>.report.json`` next to the dataset)."""
        dest = Path(path) if path is not None else report_path(self.out)
        # atomic: readers see the old report or the new one
        return atomic_write_text(dest, json.dumps(self.to_dict(), indent=2, default=_json_default))

    def lines(self) -> list[str]:
        """A short human-readable summary (the CLI prints it)."""
        out = [
            f"{self.written} demonstrations written to {self.out} "
            f"({self.passed}/{len(self.demos)} passed the checks, {self.seconds:.1f} s)"
        ]
        out += [f"failed {p}: {why}" for p, why in self.failed.items()]
        out += [f"skipped {p}: {why}" for p, why in self.skipped.items()]
        return out


def report_path(out: str | os.PathLike) -> Path:
    """Where a build's JSON report goes: next to the dataset, ``<out>.report.json``."""
    out = Path(out).expanduser()
    return out.with_name(out.name + ".report.json")


def _json_default(v):
    if hasattr(v, "tolist"):
        return v.tolist()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return str(v)


def _record(demo: Demo) -> DemoRecord:
    checks = {
        n: {"passed": c.passed, "value": c.value, "limit": c.limit, "unit": c.unit}
        for n, c in demo.report.checks.items()
    }
    g = demo.grasp
    return DemoRecord(
        pair=str(demo.pair),
        operator=demo.operator,
        seed=demo.seed,
        uuid=demo.trajectory.uuid,
        passed=demo.passed,
        frames=demo.trajectory.num_frames,
        seconds=round(demo.seconds, 3),
        summary=demo.report.summary(),
        checks=checks,
        grasp={
            "ok": g.ok,
            "reason": g.reason,
            "contact_mm": [round(float(x) * 1e3, 3) for x in g.distance_m],
            "closure": round(g.closure, 3),
            "seconds": round(g.seconds, 3),
        },
        notes=dict(demo.notes),
    )


def _plan(pairs: Sequence[Pair], reps: int, seed: int) -> list[tuple[Pair, str, int]]:
    """``(pair, operator, seed)`` per demonstration: operators cycle over the pairs (in
    order) and reps, seeds count up from ``seed`` per rep."""
    ops = list(OPERATORS)
    return [
        (p, ops[(i + r) % len(ops)], seed + r) for i, p in enumerate(pairs) for r in range(reps)
    ]


CHECK_RETRIES = 2
"""Further seeds (``seed + CHECK_SEED_STRIDE · k``) tried for a demonstration that fails its
plausibility checks (a grasp or script that ends a millimetre too deep on one seed), per
operator (see ``_generate_one``)."""
CHECK_SEED_STRIDE = 1_000_003


def _operators_by_size(planned: str) -> list[str]:
    """The planned operator, then the others by how close their hand size is (smaller first on
    ties)."""
    scale = OPERATORS[planned].scale
    return sorted(OPERATORS, key=lambda o: (o != planned, abs(OPERATORS[o].scale - scale),
                                            OPERATORS[o].scale))  # fmt: skip


def _generate_one(item: tuple[Pair, str, int]) -> tuple[Demo | None, str]:
    """The planned demonstration, or the first of its retry seeds that passes the checks; when
    none does, the same with the other operators' hands, nearest size first (a 10 mm rod lying
    on the table is pinched above its equator by the largest hand's 10 mm pads, which misses
    the contact check by a fraction of a millimetre). The planned one, failing, when none
    passes; a demonstration's ``operator`` is the hand that made it."""
    p, op, s = item
    first = None
    for hand in _operators_by_size(op):
        for k in range(CHECK_RETRIES + 1):
            try:
                demo = generate_demo(p, hand, s + CHECK_SEED_STRIDE * k)
            except DemoError as e:
                return (first, "") if first is not None else (None, str(e))
            if demo.passed:
                if hand != op:
                    log.info("%s: %s's demonstration fails the checks; made by %s", p, op, hand)
                return demo, ""
            first = first or demo
    return first, ""


def _run_plan(plan: list[tuple[Pair, str, int]], workers: int) -> Iterator:
    """``(demo or None, error)`` per planned item, in plan order."""
    if workers <= 1 or len(plan) < 2:
        yield from map(_generate_one, plan)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    ctx = multiprocessing.get_context("spawn")  # Lance and torch are not fork-safe
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        yield from pool.map(_generate_one, plan, chunksize=1)


def build_demos(
    out: str | os.PathLike,
    pairs: Sequence[str | Pair] | None = None,
    reps: int = 1,
    seed: int = 0,
    overwrite: bool = False,
    progress: bool = False,
    workers: int = 1,
) -> BuildReport:
    """Generate demonstrations and write those that pass the checks as a Lance dataset (a
    demonstration that fails them is generated again with up to ``CHECK_RETRIES`` other seeds,
    then with the other operators' hands; the seed and operator used are in the report).

    Args:
        out: destination dataset directory.
        pairs: pairs to build (``"cube2/tripod"`` or :class:`Pair`); ``None`` = every
            feasible pair. Infeasible ones are skipped with the table's reason.
        reps: demonstrations per pair (seeds ``seed + r``; operators cycle over pairs and reps).
        seed: first seed.
        overwrite: replace an existing dataset.
        progress: show a progress bar (rich).
        workers: processes generating demonstrations (the output does not depend on it).

    Returns:
        The :class:`BuildReport` (not yet written to disk; see ``run_build``).

    Raises:
        DemoError: every requested pair is infeasible, or no demonstration passed the checks
            (nothing to write).
        DatasetError: ``out`` exists and ``overwrite`` is false.
        ValidationError: ``reps`` < 1 or ``seed`` < 0.
    """
    t0 = time.perf_counter()
    out = Path(out).expanduser()
    if isinstance(reps, bool) or not isinstance(reps, int) or reps < 1:
        raise ValidationError(f"reps must be an integer ≥ 1, got {reps!r}", field="reps")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValidationError(f"seed must be an integer ≥ 0, got {seed!r}", field="seed")
    check_output(out, overwrite=overwrite, kind="dir")
    report = BuildReport(out=out)
    selected: list[Pair] = []
    for item in pairs if pairs is not None else feasible_pairs():
        p = item if isinstance(item, Pair) else Pair.parse(item)
        f = feasibility(p)
        if not f.feasible:
            report.skipped[str(p)] = f.reason
            log.warning("skipping %s: %s", p, f.reason)
        elif p not in selected:
            selected.append(p)
    plan = _plan(selected, reps, seed)
    if not plan:
        raise DemoError(
            "nothing to build: every requested pair is infeasible ("
            + "; ".join(f"{k}: {v}" for k, v in report.skipped.items())
            + ")"
        )
    write_plan(out, plan, report, overwrite=overwrite, progress=progress, workers=workers)
    report.seconds = time.perf_counter() - t0
    return report


def write_plan(
    out: Path,
    plan: Sequence[tuple[Pair, str, int]],
    report: BuildReport,
    *,
    overwrite: bool = False,
    progress: bool = False,
    workers: int = 1,
) -> None:
    """Generate the planned ``(pair, operator, seed)`` demonstrations (``workers``
    processes, spawned) and write those that pass the checks to the Lance dataset ``out``
    (atomically: ``io.write_dataset``), in plan order whatever ``workers`` is; fills
    ``report``. ``progress``: a rich progress bar on stderr naming the demonstration being
    built and the destination.

    Raises:
        DemoError: no demonstration passed the checks (nothing written).
    """

    def generate(on_done) -> Iterator:
        for k, ((p, op, s), (demo, error)) in enumerate(
            zip(plan, _run_plan(list(plan), workers), strict=True)
        ):
            on_done(k)
            if demo is None:
                report.failed[str(p)] = error
                log.warning("%s (%s, seed %d) failed: %s", p, op, s, error)
                continue
            report.demos.append(_record(demo))
            if demo.passed:
                report.written += 1
                yield demo.trajectory
            else:
                why = demo.report.summary()
                report.failed.setdefault(str(p), f"{op}, seed {s}: {why}")
                log.warning(
                    "%s (%s, seed %d and %d retries, every operator) failed its checks: %s",
                    p, op, s, CHECK_RETRIES, why,
                )  # fmt: skip

    mode = "overwrite" if overwrite else "create"
    try:
        if progress:
            with _progress_bar() as bar:
                n = len(plan)

                def describe(k: int) -> str:
                    what = f"{plan[k][0]} ({plan[k][1]})" if k < n else "writing"
                    return f"building {what} → {out}"

                task = bar.add_task(describe(0), total=n)

                def done(k: int) -> None:
                    bar.update(task, completed=k + 1, description=describe(k + 1))

                write_dataset(generate(done), out, mode=mode)
                bar.update(task, description=f"built {n} demonstration(s) → {out}")
        else:
            write_dataset(generate(lambda k: None), out, mode=mode)
    except DatasetError as e:
        if report.written == 0 and (report.demos or report.failed):
            raise DemoError(
                "no demonstration passed the checks; nothing written ("
                + "; ".join(f"{k}: {v}" for k, v in report.failed.items())
                + ")"
            ) from e
        raise


def _progress_bar():
    """A rich progress bar on stderr: spinner, description, bar, count, elapsed time."""
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        SpinnerColumn,
        TextColumn,
        TimeElapsedColumn,
    )

    return Progress(
        SpinnerColumn(),
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=Console(stderr=True),
        transient=False,
    )


def run_build(cfg: BuildConfig, progress: bool = True) -> BuildReport:
    """Validate ``cfg``, build the dataset and write its JSON report next to it."""
    cfg.validate()
    report = build_demos(
        cfg.out,
        pairs=cfg.pairs,
        reps=cfg.reps,
        seed=cfg.seed,
        overwrite=cfg.overwrite,
        progress=progress,
        workers=cfg.workers,
    )
    report.write_json()
    return report
