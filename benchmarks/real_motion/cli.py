"""The command line: ``run_benchmark`` (the cases, the jobs, the tables, JSON and page) and
``main``."""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import asdict
from pathlib import Path

from rich.console import Console
from rich.markup import escape

import benchmarks.real_motion as package  # the command's description
from benchmarks._common import (
    atomic_write_json,
    command_line,
    git_commit,
    machine_info,
    resolve_out,
    versions,
)
from benchmarks.real_motion.aggregate import summarize
from benchmarks.real_motion.cases import (
    build_real_cases,
    build_stress_cases,
    filter_cases,
    find_real_captures,
)
from benchmarks.real_motion.config import (
    ALL_MODES,
    DEFAULT_DENSITY,
    DEFAULT_WORK,
    MANO,
    MODES,
    NAME,
    PAGE,
    STRESS_PAIRS,
    BenchConfig,
    resolve_hands,
)
from benchmarks.real_motion.jobs import JobStore, Scheduler, plan_jobs
from benchmarks.real_motion.tables import page_markdown, print_tables
from dexcanvas_core.safe_io import atomic_write_text


def run_benchmark(cfg: BenchConfig, console=None) -> dict:
    """Build the cases, run the jobs not finished yet, print the tables, write the JSON and
    the page; return the JSON document."""
    console = console or Console(width=None if sys.stdout.isatty() else 140)
    cfg = resolve_out(cfg.validate(), NAME)
    t0 = time.perf_counter()
    load0 = os.getloadavg()
    work = Path(cfg.work)
    work.mkdir(parents=True, exist_ok=True)
    hands, five = resolve_hands(cfg.hands) if any(m in cfg.modes for m in MODES) else ([], [])
    found, notes = find_real_captures(cfg.captures, cfg.models, cfg.per_object)
    for n in notes:
        console.print(f"[yellow]note:[/yellow] {escape(n)}")
    cases, more = build_stress_cases(work, cfg.pairs, cfg.originals, console)
    real, more2 = build_real_cases(found, work, cfg.models, cfg.density, console)
    notes += more + more2
    for n in more + more2:
        console.print(f"[yellow]note:[/yellow] {escape(n)}")
    cases = filter_cases(real + cases, cfg.cases, cfg.limit)
    if not cases:
        raise SystemExit("no cases to run (check --cases / --captures)")
    console.print(
        f"{len(cases)} case(s); hands: {', '.join(hands) or '-'}; modes: {', '.join(cfg.modes)}"
    )
    mano_jobs, hand_jobs = plan_jobs(cases, hands, cfg.modes, work)
    sched = Scheduler(JobStore(work), cfg.retry_errors)
    sched.run(mano_jobs, hand_jobs, cfg.workers, console)
    keys = [s["key"] for s in mano_jobs if MANO in cfg.modes] + [s["key"] for s in hand_jobs]
    records = [sched.records[k] for k in keys if k in sched.records]
    doc = {
        "benchmark": "real_motion",
        "command": command_line("benchmarks.real_motion"),
        "config": {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(cfg).items()},
        "hands": hands,
        "five_finger_hands": five,
        "cases": [c.as_dict() for c in cases],
        "notes": notes,
        "records": records,
        "summary": summarize(records, hands, five),
        "commit": git_commit(),
        "machine": machine_info(load0, workers=cfg.workers),
        "versions": versions(("dexcanvas-retarget", "mujoco", "pin", "numpy", "lance")),
        "definitions": {
            "strict_success": "no frame of the contact window (object_move start..end) with "
            "object error > 5 cm; forces_refine: the refinement's result where the open loop "
            "failed there (kept through the window's end)",
            "success": "DexCanvas rule over the whole clip (open loop; MANO: the pipeline's)",
            "object_err_max_window_m": "max object error in the window (refined: the "
            "refinement's max over the frames it tracked)",
            "wrist_pos_err_mean_m": "mean over the clip of the re-simulated wrist's distance "
            "from its command (MANO: the simulated wrist from its target)",
            "penetration_max_m": "deepest kinematic hand-object penetration",
            "failure": "MANO: reason at the failure's onset (wrist lag ≥ 2 cm in the 0.1 s "
            "before / fewer than 2 hand parts pressing / slip) and phase",
        },
        "wall_time_s": time.perf_counter() - t0,
    }
    print_tables(doc, console)
    atomic_write_json(cfg.out, doc, indent=1)
    console.print(f"wrote {cfg.out} ({doc['wall_time_s']:.0f} s)")
    if cfg.page is not None:
        atomic_write_text(Path(cfg.page), page_markdown(doc, cfg.out))
        console.print(f"wrote {cfg.page}")
    return doc


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.real_motion",
        description=package.__doc__.split("\n\n")[0],
    )
    ap.add_argument(
        "--captures",
        type=Path,
        default=None,
        help="directory with mano-npz/, dexycb/, taco/ (never downloaded)",
    )
    ap.add_argument("--models", type=Path, default=None, help="YCB object models (dexycb)")
    ap.add_argument("--per-object", type=int, default=1, help="DexYCB sequences per item")
    ap.add_argument(
        "--density",
        type=float,
        default=DEFAULT_DENSITY,
        help="kg/m³ for captured objects without a known mass",
    )
    ap.add_argument(
        "--hands", nargs="+", default=None, help="hands (default: every five-finger hand)"
    )
    ap.add_argument("--modes", nargs="+", default=list(ALL_MODES), choices=ALL_MODES)
    ap.add_argument(
        "--cases",
        nargs="+",
        default=[],
        metavar="SUBSTRING",
        help="only the cases whose name contains one of these",
    )
    ap.add_argument("--limit", type=int, default=None, help="only the first N cases")
    ap.add_argument(
        "--pairs",
        nargs="+",
        default=list(STRESS_PAIRS),
        help="built-in demonstrations the stress cases are made of",
    )
    ap.add_argument(
        "--originals", action="store_true", help="also run the unmodified demonstrations"
    )
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument(
        "--work",
        type=Path,
        default=DEFAULT_WORK,
        help="job records, runs and imported datasets (resumable)",
    )
    ap.add_argument("--retry-errors", action="store_true", help="rerun jobs that raised")
    ap.add_argument(
        "--out",
        type=Path,
        default=None,
        help="JSON output (default: benchmarks/results/real_motion/<date>-<commit>.json)",
    )
    ap.add_argument("--page", type=Path, default=PAGE, help="markdown page output")
    ap.add_argument("--no-page", action="store_true", help="do not write the page")
    a = ap.parse_args(argv)
    cfg = BenchConfig(
        captures=a.captures,
        models=a.models,
        per_object=a.per_object,
        density=a.density,
        hands=tuple(a.hands) if a.hands else None,
        modes=tuple(a.modes),
        cases=tuple(a.cases),
        limit=a.limit,
        pairs=tuple(a.pairs),
        originals=a.originals,
        workers=a.workers,
        work=a.work,
        out=a.out,
        page=None if a.no_page else a.page,
        retry_errors=a.retry_errors,
    )
    run_benchmark(cfg)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
