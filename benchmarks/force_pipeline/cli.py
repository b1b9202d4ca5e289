"""The command line: ``run_benchmark`` (the run, its tables, JSON and plots) and ``main``."""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import sys
import time
from pathlib import Path

from rich.console import Console

import benchmarks.force_pipeline as package  # the command's description
from benchmarks._common import (
    atomic_write_json,
    command_line,
    git_commit,
    machine_info,
    parse_override,
    pick_pairs,
    resolve_out,
    versions,
)
from benchmarks.force_pipeline.aggregate import (
    aggregate,
    force_signature,
    heavy_vs_light,
    target_checks,
)
from benchmarks.force_pipeline.config import (
    CONDITIONS,
    HEAVY,
    MOCAP_DROPOUT,
    MOCAP_NOISE_MM,
    NAME,
    PLOTS_DIR,
    SIZE_PERTURBATION,
    TRACKERS,
    VERSION_DISTS,
    BenchConfig,
    plan_runs,
    tracking_config,
)
from benchmarks.force_pipeline.jobs import run_jobs
from benchmarks.force_pipeline.tables import conditions_table, heavy_table, signature_table
from dexcanvas_core.sim.pipeline import SimConfig


def run_benchmark(cfg: BenchConfig, console=None) -> dict:
    """Run the suite in every condition, print the tables, write the JSON and plots; return
    the JSON document."""
    console = console or Console(width=None if sys.stdout.isatty() else 140)
    cfg = resolve_out(cfg.validate(), NAME)
    t_start = time.perf_counter()
    load0 = os.getloadavg()
    pairs = pick_pairs(cfg.n_pairs, cfg.seed)
    plans = [plan_runs(i, p, cfg) for i, p in enumerate(pairs)]
    n_sims = sum(len(p) for p in plans)
    plot_dir = Path(cfg.out).parent / PLOTS_DIR
    if cfg.plots:
        plot_dir.mkdir(parents=True, exist_ok=True)
    n_types = len({p.manipulation_type.name for p in pairs})
    console.print(
        f"{len(pairs)} pairs ({n_types} manipulation types), conditions: "
        f"{', '.join(cfg.conditions)}; {n_sims} simulations "
        f"({sum(1 for p in plans for c, _ in p if c == HEAVY)} heavy), tracker {cfg.tracker}, "
        f"{cfg.workers} worker(s)"
    )

    demos, rows = run_jobs(cfg, pairs, plans, plot_dir, console)
    order = {c: k for k, c in enumerate((*CONDITIONS, HEAVY))}
    rows.sort(key=lambda r: (r["index"], order[r["condition"]]))
    for r in rows:
        if "error" in r:
            console.print(f"[red]{r['pair']} · {r['condition']}: {r['error']}[/red]")
    aggs = {c: aggregate([r for r in rows if r["condition"] == c]) for c in cfg.conditions}
    checks = {c: target_checks(c, a) for c, a in aggs.items()}
    signatures = {
        c: force_signature([r for r in rows if r["condition"] == c and "error" not in r])
        for c in cfg.conditions
    }
    hv = heavy_vs_light(rows)

    console.print(
        conditions_table(
            f"force pipeline: {len(pairs)} pairs, {n_types} types, tracker {cfg.tracker}",
            aggs,
            checks,
        )
    )
    first = cfg.conditions[0]
    console.print(
        signature_table(f"force signature per manipulation type ({first})", signatures[first])
    )
    if hv["pairs"]:
        console.print(heavy_table(hv))

    plots = sorted(r["plot"] for r in rows if r.get("plot"))
    doc = {
        "benchmark": "force_pipeline",
        "command": command_line("benchmarks.force_pipeline"),
        "config": {**dataclasses.asdict(cfg), "out": str(cfg.out)},
        "sim_config": SimConfig(tracker=cfg.tracker, tracking=tracking_config(cfg)).as_dict(),
        "mocap": {
            "noise_mm": MOCAP_NOISE_MM,
            "dropout": MOCAP_DROPOUT,
            "render": "render_markers defaults otherwise (gaps, swaps)",
            "fit": "fit_markers default options",
        },
        "size_perturbation": SIZE_PERTURBATION,
        "demonstrations": [demos[i] for i in sorted(demos)],
        "commit": git_commit(),
        "machine": machine_info(load0, threads_per_worker=1),
        "versions": versions(VERSION_DISTS),
        "definitions": {
            "success_rate": "strict DexCanvas rule over runs (errors count as failures)",
            "object_pos_err_mean_m": "mean over runs of each run's mean object position error",
            "compute_s_per_demo_s_median": "median over runs of tracking process-CPU seconds "
            "per second of demonstration (one thread)",
            "newton_euler_*_median": "median over runs of each run's median residual / (m·g)",
            "hold_weight_dev_median": "median over runs with static-hold frames of "
            "|hold_weight_ratio - 1|",
            "hold_force_share": "per run: each part's share of the summed mean contact-force "
            "magnitudes over static-hold frames",
            "hold_force_n": "sum over parts of the mean contact-force magnitude in static hold",
        },
        "summary": {
            "per_condition": aggs,
            "targets": [c for cs in checks.values() for c in cs],
            "force_signature": signatures,
            "heavy_vs_light": hv,
        },
        "plots": plots,
        "runs": rows,
        "wall_time_s": time.perf_counter() - t_start,
    }
    atomic_write_json(cfg.out, doc)
    console.print(
        f"wrote {cfg.out}"
        + (f" and {len(plots)} plot(s) in {plot_dir}" if plots else "")
        + f" ({doc['wall_time_s']:.0f} s)"
    )
    return doc


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.force_pipeline",
        description=package.__doc__.split("\n\n")[0],
    )
    ap.add_argument("--n-pairs", type=int, default=32, help="pairs (≥ 21: every type)")
    ap.add_argument(
        "--conditions",
        nargs="+",
        choices=CONDITIONS,
        default=list(CONDITIONS),
        help="clean, mocap (markers → fit), mocap_size (fit, object size ±20 %%)",
    )
    ap.add_argument("--workers", type=int, default=2, help="processes, one thread each")
    ap.add_argument("--tracker", choices=TRACKERS, default="mpc")
    ap.add_argument(
        "--out",
        type=Path,
        default=None,
        help="JSON output (default: benchmarks/results/force_pipeline/<date>-<commit>.json)",
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--plots", type=int, default=4, help="plot every run of the first N pairs")
    ap.add_argument(
        "--heavy",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also run clean demonstrations with the heavy object variant",
    )
    ap.add_argument(
        "--set",
        dest="tracking",
        metavar="FIELD=VALUE",
        type=parse_override,
        action="append",
        default=[],
        help="override a TrackingConfig field in every run (repeatable), e.g. "
        "--set grip_force_min_n=2.0",
    )
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    cfg = BenchConfig(
        n_pairs=a.n_pairs,
        conditions=tuple(dict.fromkeys(a.conditions)),
        workers=a.workers,
        tracker=a.tracker,
        out=a.out,
        seed=a.seed,
        plots=a.plots,
        heavy=a.heavy,
        tracking=tuple(a.tracking),
    )
    run_benchmark(cfg)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
