"""The command line: ``run_benchmark`` (the run, its tables, JSON and plot) and ``main``."""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import sys
import time
from pathlib import Path

from rich.console import Console

import benchmarks.force_preservation as package  # the command's description
from benchmarks._common import (
    atomic_write_json,
    command_line,
    config_overrides,
    git_commit,
    is_five_finger,
    load_demonstrations,
    machine_info,
    parse_override,
    resolve_out,
    versions,
)
from benchmarks.force_preservation.aggregate import (
    aggregate_variants,
    by_contact_error,
    correlation_by_reach,
    heavy_vs_light,
    heavy_vs_light_by_wrench,
    human_heavy_vs_light,
    replay_ceiling,
    target_checks,
)
from benchmarks.force_preservation.config import (
    ALL_HANDS,
    FIVE_FINGER,
    LABELS,
    NAME,
    NOT_IMPLEMENTED,
    RUN_VARIANTS,
    TRACKERS,
    VARIANTS,
    VERSION_DISTS,
    BenchConfig,
    object_plan,
)
from benchmarks.force_preservation.jobs import run_jobs
from benchmarks.force_preservation.plots import plot_success
from benchmarks.force_preservation.tables import (
    contact_error_table,
    heavy_table,
    human_table,
    reach_table,
    targets_table,
    variants_table,
    wrench_table,
)
from dexcanvas_core.sim.pipeline import SimConfig
from dexcanvas_core.sim.signal import CAPTURE_SMOOTH_S
from dexcanvas_core.taxonomy import GROUPS
from retarget.config import RetargetConfig
from retarget.hands import available_hands, get_hand
from retarget.human_forces import HUMAN_REPLAY_SEED
from retarget.refine import RefineConfig


def run_benchmark(cfg: BenchConfig, console=None) -> dict:
    """Run every hand × pair × object × variant, print the tables, write the JSON and the plot;
    return the JSON document."""
    console = console or Console(width=None if sys.stdout.isatty() else 160)
    cfg = resolve_out(cfg.validate(), NAME)
    t_start = time.perf_counter()
    load0 = os.getloadavg()
    hands = [get_hand(h) for h in (cfg.hands or available_hands())]
    five = [h.name for h in hands if is_five_finger(h)]
    demos, source, demo_failures = load_demonstrations(cfg, console)
    if not demos:
        raise SystemExit("no demonstrations to run")
    plans = [object_plan(p, cfg.heavy) for p, _ in demos]
    groups = {g: sum(1 for p, _ in demos if p.manipulation_type.group == g) for g in GROUPS}
    n_heavy = sum(1 for p in plans for o in p if o["heavy_version_of"])
    console.print(
        f"{len(demos)} pairs from {source} ({', '.join(f'{g} {n}' for g, n in groups.items())})"
        f" + {n_heavy} heavy version(s); hands: {', '.join(h.name for h in hands)}; human "
        f"tracker {cfg.human_tracker}; {cfg.workers} worker(s)"
        + (f"; variants {' '.join(cfg.variants)}" if cfg.variants != RUN_VARIANTS else "")
        + (f"; RetargetConfig {cfg.overrides}" if cfg.overrides else "")
        + (f"; RefineConfig {cfg.refine_overrides}" if cfg.refine_overrides else "")
        + (f"; human cache {cfg.human_cache}" if cfg.human_cache is not None else "")
        + (f"; human replay at MPC seed {HUMAN_REPLAY_SEED}" if cfg.replays() else "")
    )

    human, rows, skipped = run_jobs(cfg, demos, plans, hands, console)
    hand_order = {h.name: k for k, h in enumerate(hands)}
    rows.sort(
        key=lambda r: (
            hand_order[r["hand"]],
            r["index"],
            r["object_variant"] == "heavy",
            r["variant"],
        )
    )
    for r in rows:
        if "error" in r:
            console.print(
                f"[red]{r['hand']} · {r['pair']} · {r['object_id']} · "
                f"{LABELS[r['variant']]}: {r['error']}[/red]"
            )

    per_hand = {h.name: aggregate_variants([r for r in rows if r["hand"] == h.name]) for h in hands}
    scopes = {ALL_HANDS: rows}
    if five:
        scopes = {FIVE_FINGER: [r for r in rows if r["hand"] in five], **scopes}
    scope_aggs = {s: aggregate_variants(rs) for s, rs in scopes.items()}
    hv = {s: heavy_vs_light(rs) for s, rs in scopes.items()}
    by_contact = {s: by_contact_error(rs) for s, rs in scopes.items()}
    by_reach = {s: correlation_by_reach(rs, human) for s, rs in scopes.items()}
    by_wrench = {s: heavy_vs_light_by_wrench(rs) for s, rs in scopes.items()}
    target_scope = FIVE_FINGER if five else ALL_HANDS
    ceilings = per_hand_ceiling = None
    if cfg.replays():
        ceilings = {
            s: {v: replay_ceiling(rs, human, v) for v in ("d", "e")} for s, rs in scopes.items()
        }
        per_hand_ceiling = {
            h.name: replay_ceiling([r for r in rows if r["hand"] == h.name], human, "d")
            for h in hands
        }
    checks = target_checks(
        target_scope,
        scopes[target_scope],
        scope_aggs[target_scope],
        hv[target_scope],
        None if ceilings is None else ceilings[target_scope],
    )

    console.print(human_table(human))
    for h in hands:
        n_skip = sum(1 for s in skipped if s["hand"] == h.name)
        title = h.name + (" (five fingers)" if h.name in five else "")
        if n_skip:
            title += f" ({n_skip} pair(s) skipped: cannot perform)"
        hc = None if per_hand_ceiling is None else per_hand_ceiling[h.name]
        console.print(variants_table(title, per_hand[h.name], hc))
    for s, a in scope_aggs.items():
        if s == ALL_HANDS and len(hands) == 1:
            continue  # the same as the one hand's table
        names = ", ".join(five) if s == FIVE_FINGER else ", ".join(h.name for h in hands)
        console.print(
            variants_table(f"{s} ({names})", a, None if ceilings is None else ceilings[s]["d"])
        )
    human_hv = human_heavy_vs_light(human)
    console.print(heavy_table(hv, human_hv))
    if "d" in cfg.computed_variants():
        for s_, tab in by_wrench.items():
            if s_ == ALL_HANDS and len(hands) == 1:
                continue
            console.print(wrench_table(s_, tab))
    for s_, tab in by_contact.items():
        if s_ == ALL_HANDS and len(hands) == 1:
            continue
        console.print(contact_error_table(s_, tab))
        if "d" in cfg.computed_variants():
            console.print(reach_table(s_, by_reach[s_]))
    console.print(targets_table(target_scope, checks))

    plot_ceilings = None
    if ceilings is not None:
        plot_ceilings = {**per_hand_ceiling, **{s: c["d"] for s, c in ceilings.items()}}
    plot = plot_success(
        per_hand,
        {s: a for s, a in scope_aggs.items() if len(hands) > 1},
        cfg.plot_path(),
        plot_ceilings,
    )
    doc = {
        "benchmark": "force_preservation",
        "command": command_line("benchmarks.force_preservation"),
        "config": {
            **dataclasses.asdict(cfg),
            "out": str(cfg.out),
            "plot": str(plot),
            "human_cache": None if cfg.human_cache is None else str(cfg.human_cache),
        },
        "human_sim_config": SimConfig(tracker=cfg.human_tracker).as_dict(),
        "variants": {
            v: {"label": LABELS[v], "implemented": v not in NOT_IMPLEMENTED} for v in VARIANTS
        },
        "demonstrations": {
            "source": source,
            "pairs": [str(p) for p, _ in demos],
            "frames": {str(p): t.num_frames for p, t in demos},
            "objects": {str(p): plans[i] for i, (p, _) in enumerate(demos)},
            "generation_failures": demo_failures,
        },
        "human_simulations": human,
        "human_simulations_failed": [
            {
                "pair": s["pair"],
                "object_id": s["object_id"],
                "failed_at_frame": s.get("failed_at_frame"),
                "error": s.get("error"),
            }
            for s in human
            if not s["success"]
        ],
        "hands": [h.name for h in hands],
        "five_finger_hands": five,
        "skipped": skipped,
        "commit": git_commit(),
        "machine": machine_info(load0, threads_per_worker=1),
        "versions": versions(VERSION_DISTS),
        "definitions": {
            "success": "Resimulator strict rule (no frame with object error > 5 cm)",
            "success_loose": "mean object error < 10 cm and < 0.5 rad",
            "force_correlation_mean": "retarget.metrics.force_metrics: mean over corresponding "
            "fingers the human loaded (> 0.05 N on more than 2 frames) of the correlation of "
            "human and re-simulated robot contact-force magnitude profiles (frames where either "
            "exceeds 0.05 N); 0 for a robot finger that never presses",
            "force_profile_correlation_mean": "the same correlation over every frame of the "
            "demonstration (the force profile, contact on/off timing included)",
            "*_load_bearing": "the same means over the fingers whose mean human force is at "
            "least retarget.force_scores.LOAD_BEARING_SHARE of the mapped fingers' summed "
            "mean force",
            "force_profile_correlation_mean_reached": "the whole-clip mean over the fingers "
            "whose contact_reach_m (the median distance from the robot finger to the human's "
            "contact point in (d)'s plan, over the frames the human finger loads) is at most "
            "retarget.force_scores.REACH_M; correlation_by_reach pools single fingers by reach",
            "force_profile_correlation_mean_smoothed": "the whole-clip mean with both force "
            "profiles moving-averaged over the demonstration's bandwidth first "
            "(retarget.force_scores.profile_band_frames: the force pipeline's "
            f"{1e3 * CAPTURE_SMOOTH_S:.0f}"
            " ms capture smoothing; "
            "the robots' contact chatter above it is not part of the human's profile)",
            "object_force_error_mean_n": "mean over frames where the human touches of |sum of "
            "robot contact forces - sum of human contact forces| on the object (force part of "
            "the wrench; no torque: the re-simulation reports no contact points)",
            "object_force_error_pct_weight": "object_force_error_mean_n / (m g) of the run's "
            "object",
            "*_successful": "over runs whose re-simulation met the strict rule",
            "success_rate_with_human_forces": "over runs whose (pair, object) the force "
            "pipeline reproduced",
            "penetration_max_m": "deepest kinematic hand-object penetration of q (max over "
            "frames; aggregates: max over runs)",
            "sim_penetration_max_m": "deepest hand-object penetration in the re-simulation",
            "ms_per_frame": "ours: RobotTrajectory.ms_per_frame (QP solve + squeeze or force "
            "QP); dex-retargeting: its per-frame call; frame-weighted in aggregates",
            "five_finger_hands": "hands with five distinct robot fingers",
            "heavy_vs_light_by_wrench": "light / heavy strict success of (d) and (e), split "
            "by (d)'s wrench_feasible_fraction >= WRENCH_FEASIBLE (feasible) or below (short): "
            "whether the force QP could produce the human's object wrench at the retargeted "
            "contacts within the servos' torque limits",
            "human_replay": "the force pipeline run again on the same (pair, object) with "
            f"MPC seed {HUMAN_REPLAY_SEED} (the first: 0); replay.force_* score its per-finger "
            "forces against the first simulation's as force_metrics scores a robot's "
            "(retarget.metrics.human_replay_metrics)",
            "human_replay_ceiling": "replay_ceiling: over a variant's successful runs with a "
            "scored replay, the replay's correlations on the fingers each run scores (and the "
            "run's load shares), next to the variant's own on the same runs",
        },
        "targets": checks,
        "aggregates": {
            "per_scope": scope_aggs,
            "per_hand": per_hand,
            "heavy_vs_light": hv,
            "heavy_vs_light_by_wrench": by_wrench,
            "human_heavy_vs_light": human_hv,
            "by_contact_error": by_contact,
            "correlation_by_reach": by_reach,
            "human_replay_ceiling": None
            if ceilings is None
            else {"per_scope": ceilings, "per_hand": per_hand_ceiling},
        },
        "runs": rows,
        "wall_time_s": time.perf_counter() - t_start,
    }
    atomic_write_json(cfg.out, doc)
    console.print(f"wrote {cfg.out} and {plot} ({doc['wall_time_s']:.0f} s)")
    return doc


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.force_preservation",
        description=package.__doc__.split("\n\n")[0],
    )
    ap.add_argument(
        "--hands",
        nargs="+",
        default=None,
        choices=available_hands(),
        help="hands to run (default: all)",
    )
    ap.add_argument("--n-pairs", type=int, default=20, help="pairs over the four groups")
    ap.add_argument("--max-frames", type=int, default=None, help="crop each demonstration")
    ap.add_argument(
        "--human-tracker",
        choices=TRACKERS,
        default="mpc",
        help="force pipeline tracker (open_loop: fast smoke runs)",
    )
    ap.add_argument(
        "--heavy",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also run heavy variants of the pairs' objects",
    )
    ap.add_argument("--workers", type=int, default=2, help="processes, one thread each")
    ap.add_argument(
        "--out",
        type=Path,
        default=None,
        help="JSON output (default: benchmarks/results/force_preservation/<date>-<commit>.json)",
    )
    ap.add_argument(
        "--plot", type=Path, default=None, help="PNG output (default: the JSON path with .png)"
    )
    ap.add_argument("--operator", default="operator1")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--dex-wrist",
        choices=("free", "fixed"),
        default="free",
        help="dex-retargeting's wrist: optimised (free) or the human wrist pose",
    )
    ap.add_argument(
        "--variants",
        nargs="+",
        choices=RUN_VARIANTS,
        default=list(RUN_VARIANTS),
        help="variants to run (default: all; e also runs d)",
    )
    ap.add_argument(
        "--set",
        dest="overrides",
        action="append",
        type=parse_override,
        default=[],
        metavar="NAME=VALUE",
        help="change a RetargetConfig field of our variants (repeatable), e.g. --set "
        "w_contacts=100",
    )
    ap.add_argument(
        "--refine-set",
        dest="refine_overrides",
        action="append",
        type=parse_override,
        default=[],
        metavar="NAME=VALUE",
        help="change a RefineConfig field of variant (e)'s refinement (repeatable), e.g. "
        "--refine-set retries=2",
    )
    ap.add_argument(
        "--calibrate-iterations",
        type=int,
        default=BenchConfig.calibrate_iterations,
        metavar="N",
        help="variant (d)'s force calibration: re-simulations correcting the commands until "
        f"the fingers press like the human's (default {BenchConfig.calibrate_iterations}; 0: "
        "the planned commands)",
    )
    ap.add_argument(
        "--human-cache",
        type=Path,
        default=None,
        metavar="DIR",
        help="reuse human simulations stored here (written on first use): ablations of the "
        "retargeting skip the force pipeline",
    )
    ap.add_argument(
        "--human-replay",
        action=argparse.BooleanOptionalAction,
        default=True,
        help=f"simulate each human demonstration again at MPC seed {HUMAN_REPLAY_SEED} and score "
        "its forces against the first's: the force correlation's ceiling (mpc tracker only)",
    )
    a = ap.parse_args(argv)

    overrides = config_overrides(a.overrides, RetargetConfig)
    refine_overrides = config_overrides(a.refine_overrides, RefineConfig, "--refine-set")
    logging.basicConfig(level=logging.ERROR)
    cfg = BenchConfig(
        hands=tuple(dict.fromkeys(a.hands)) if a.hands else None,
        n_pairs=a.n_pairs,
        max_frames=a.max_frames,
        human_tracker=a.human_tracker,
        heavy=a.heavy,
        workers=a.workers,
        out=a.out,
        plot=a.plot,
        operator=a.operator,
        seed=a.seed,
        dex_wrist=a.dex_wrist,
        variants=tuple(dict.fromkeys(a.variants)),
        overrides=overrides,
        refine_overrides=refine_overrides,
        calibrate_iterations=a.calibrate_iterations,
        human_cache=a.human_cache,
        human_replay=a.human_replay,
    )
    run_benchmark(cfg)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
