"""Retargeting speed and quality per robot hand: our QP against dex-retargeting, same inputs.

For every hand × demonstration pair the same human trajectory is retargeted twice onto the same
robot model (the hand's compiled ``MjModel``):

* **ours** — ``Retargeter`` (Pinocchio backend, default ``RetargetConfig``: keypoints, wrist
  pose, fingertip vectors, contact targets, non-penetration, joint/velocity/coupling limits);
* **dex-retargeting** — its position retargeting (PyPI ``dex-retargeting``, free 6-DoF wrist
  unless ``--dex-wrist fixed``, its default optimizer settings) on a URDF exported from the
  same ``MjModel``, fed the same scaled keypoint targets (``retarget.baselines.
  dex_retargeting``).

Measured per run:

* **ms/frame** — wall time of the per-frame solves only, divided by the frame count. Ours: the
  time inside ``Retargeter._warm_start`` and ``_solve_frame`` (starting point, QP build + solve
  iterations), not the per-frame metrics ``retarget()`` also records nor the grip (those are in
  ``ms_per_frame_total`` in the JSON). dex-retargeting: the time inside its
  ``SeqRetargeting.retarget`` calls. With ``--timing-repeats N`` each pair's solves are timed
  N times, the two methods alternating (ours, dex-retargeting, ours, …; the outputs are the
  first run's, every repeat computes the same): ms/frame is the median of the N, and the
  minimum is reported beside it. On this shared 2-core machine the same run of the same code
  measured 0.72 and 1.30 ms/frame a minute apart (Shadow, 20 pairs), so one run's
  number is a sample, not the cost.
* **kp err** — mean over frames of the mean distance between the robot keypoint sites and their
  scaled human targets (``Retargeter.human_targets``), both methods through
  ``retarget.baselines.measure_trajectory`` (the definitions ``RobotTrajectory`` uses).
* **penetration** — deepest hand–object penetration of the kinematic solution [mm]
  (``CollisionLimit.distances`` on the retargeting scene, object at its human pose).
* **self pen** — deepest penetration between collision geoms of different hand parts (finger vs
  finger or palm; ``HandModel.self_collision_pairs``) of the kinematic solution [mm].
* **contact err** — mean over human fingertip contacts of the distance from the robot finger's
  surface point nearest the object to the human contact point (``RobotTrajectory.contact_err``).
* **strict / loose success** — ``Resimulator`` (robot actuators track the joint trajectory,
  object free on a table): strict = no frame with object position error > 5 cm (DexCanvas);
  loose = mean error < 10 cm and < 0.5 rad. Ours is re-simulated on ``q_command`` (the solution
  plus the grip squeeze) and, for a like-for-like comparison, on ``q`` (no squeeze);
  dex-retargeting on its ``q``. Kinematic metrics of both "ours" rows are those of ``q``.

Pairs: ``--n-pairs`` feasible pairs of the built-in demonstrations
(``dexcanvas_core.demos``), spread evenly over the four groups (power, intermediate,
precision, in-hand) by a deterministic round robin over manipulation types and objects; a
hand skips pairs it cannot perform (``retarget.pipeline.check_pair``; counted). Prints a table per
hand and an overall table with the targets, and writes JSON (per-run rows and aggregates;
default ``benchmarks/results/retarget_speed_quality/<date>-<commit>.json``)::

    python -m benchmarks.retarget_speed_quality                 # 20 pairs, every hand
    python -m benchmarks.retarget_speed_quality --quick         # smoke run: 2 pairs, 1 hand
    python -m benchmarks.retarget_speed_quality --hands allegro shadow --max-frames 240
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import traceback
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from benchmarks._common import (
    atomic_write_json,
    command_line,
    config_overrides,
    git_commit,
    load_demonstrations,
    machine_info,
    mm,
    parse_override,
    pct,
    progress_bar,
    resim,
    resolve_out,
    versions,
)
from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.taxonomy import GROUPS
from retarget.baselines import (
    DexRetargetingBaseline,
    DexRetargetingConfig,
    KinematicMetrics,
    measure_trajectory,
)
from retarget.config import RetargetConfig
from retarget.hands import available_hands, get_hand
from retarget.pipeline import check_pair
from retarget.retargeter import Retargeter
from retarget.validate import Resimulator

NAME = "retarget_speed_quality"
"""The benchmark's name: its results folder ``benchmarks/results/<NAME>/``."""
OURS, OURS_Q, DEX = "ours", "ours (no squeeze)", "dex-retargeting"
METHODS = (OURS, OURS_Q, DEX)
VERSION_DISTS = ("dexcanvas-retarget", "dex-retargeting", "mujoco", "pin", "numpy", "nlopt",
                 "torch", "qpsolvers", "daqp")  # fmt: skip

# The targets (reported against, not enforced).
TARGET_MS = 0.5
TARGET_PEN_MM = 2.0
TARGET_SUCCESS_RATIO = 1.5


@dataclass(frozen=True)
class BenchConfig:
    """One benchmark run."""

    hands: tuple[str, ...] | None = None
    """Hands to run; ``None``: every registered hand."""
    n_pairs: int = 20
    """Demonstration pairs, spread over the four groups."""
    max_frames: int | None = None
    """Crop each demonstration to this many frames (around the start of the object motion)."""
    out: Path | None = None
    """JSON output; ``None``: ``benchmarks/results/retarget_speed_quality/<date>-<commit>.json``
    (``benchmarks._common.result_path``)."""
    operator: str = "operator1"
    seed: int = 0
    dex_wrist: str = "free"
    """dex-retargeting's wrist: ``free`` (optimised) or ``fixed`` (the human wrist pose)."""
    overrides: dict = field(default_factory=dict)
    """``RetargetConfig`` fields of ours changed from their defaults (``--set KEY=VALUE``)."""
    timing_repeats: int = 1
    """Times each pair's solves are timed, the two methods alternating (module docstring)."""

    def validate(self) -> BenchConfig:
        if self.n_pairs < 1:
            raise SystemExit("--n-pairs must be >= 1")
        if self.timing_repeats < 1:
            raise SystemExit(f"--timing-repeats must be >= 1, got {self.timing_repeats}")
        if self.max_frames is not None and self.max_frames < 2:
            raise SystemExit("--max-frames must be >= 2")
        if self.dex_wrist not in ("free", "fixed"):
            raise SystemExit("--dex-wrist must be free or fixed")
        return self


# ------------------------------------------------------------------------------------- runs
def _timed_solves(rt):
    """Wrap ``rt._warm_start`` (the frame's starting point) and ``rt._solve_frame`` (its QP
    iterations) to accumulate the time spent in them; returns the accumulator.

    ``Retargeter.retarget`` times its whole loop, which also records per-frame metrics and the
    grip squeeze; the per-frame solve is what compares with dex-retargeting's per-frame call.
    """
    acc = {"s": 0.0}

    def wrap(name):
        f = getattr(rt, name)

        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            out = f(*args, **kwargs)
            acc["s"] += time.perf_counter() - t0
            return out

        setattr(rt, name, timed)

    wrap("_warm_start")
    wrap("_solve_frame")
    return acc


def _timing(seconds: list[float], frames: int) -> dict:
    """A method's solve times over the repeats [s]: the median is the row's time, the minimum
    and every repeat kept beside it."""
    med = float(np.median(seconds))
    return {
        "ms_per_frame": 1e3 * med / frames,
        "ms_per_frame_min": 1e3 * min(seconds) / frames,
        "solve_time_s": med,
        "solve_time_s_min": float(min(seconds)),
        "solve_time_s_runs": [float(x) for x in seconds],
    }


def run_one(
    hand, pair, traj, baseline, overrides: dict | None = None, timing_repeats: int = 1
) -> list[dict]:
    """Both methods on one hand × pair: three rows (ours on q_command and q, dex-retargeting);
    the solves timed ``timing_repeats`` times, alternating (``_timing``)."""

    geom = object_geometry(pair.object.id)
    base = {
        "hand": hand.name,
        "pair": str(pair),
        "group": pair.manipulation_type.group,
        "frames": traj.num_frames,
        "uuid": traj.uuid,
    }
    rt = Retargeter(
        hand, geom, RetargetConfig.from_overrides({"backend": "pinocchio", **(overrides or {})})
    )
    solve = _timed_solves(rt)
    robot = rt.retarget(traj)
    ours_km = KinematicMetrics.of(robot).summary()
    tg = rt.human_targets(traj)
    if rt.kp_sites != baseline.keypoint_sites:
        raise RuntimeError(f"{hand.name}: baseline keypoint sites differ from the retargeter's")
    dex = baseline.retarget_targets(tg["keypoints"], tg["wrist_p"], tg["wrist_R"])
    ours_s, dex_s = [solve["s"]], [dex.solve_time_s]
    for _ in range(timing_repeats - 1):
        s0 = solve["s"]
        rt.retarget(traj)
        ours_s.append(solve["s"] - s0)
        again = baseline.retarget_targets(tg["keypoints"], tg["wrist_p"], tg["wrist_R"])
        dex_s.append(again.solve_time_s)
    dex_km = measure_trajectory(rt, traj, dex.q, tg).summary()
    sim = Resimulator(hand, geom)
    ours_t, dex_t = _timing(ours_s, traj.num_frames), _timing(dex_s, traj.num_frames)
    rows = [
        {**base, "method": OURS, **ours_t,
         "ms_per_frame_total": robot.ms_per_frame, **ours_km, **resim(sim, robot.q_command, traj)},
        {**base, "method": OURS_Q, **ours_t,
         "ms_per_frame_total": robot.ms_per_frame, **ours_km, **resim(sim, robot.q, traj)},
        {**base, "method": DEX, **dex_t,
         "ms_per_frame_total": dex.ms_per_frame, "solver_failures": dex.solver_failures,
         **dex_km, **resim(sim, dex.q, traj)},
    ]  # fmt: skip
    return rows


# ------------------------------------------------------------------------------- aggregates
def aggregate(rows: list[dict]) -> dict:
    """Per method: frame-weighted speed and keypoint error, worst and mean penetration, mean
    contact error, success rates (errors count as failures)."""
    out = {}
    for method in METHODS:
        rs = [r for r in rows if r["method"] == method]
        ok = [r for r in rs if "error" not in r]
        if not rs:
            continue
        frames = np.array([r["frames"] for r in ok], float)
        contact_w = np.array(
            [r["contact_frames"] for r in ok if r["contact_err_mean_m"] is not None]
        )
        contact_v = np.array(
            [r["contact_err_mean_m"] for r in ok if r["contact_err_mean_m"] is not None]
        )
        pens = np.array([r["penetration_max_m"] for r in ok])
        out[method] = {
            "runs": len(rs),
            "errors": len(rs) - len(ok),
            "frames": int(frames.sum()),
            "ms_per_frame": 1e3 * sum(r["solve_time_s"] for r in ok) / frames.sum() if ok else None,
            "ms_per_frame_min": (
                1e3 * sum(r["solve_time_s_min"] for r in ok) / frames.sum()
                if ok else None
            ),
            "ms_per_frame_total": (
                float(np.sum([r["ms_per_frame_total"] * r["frames"] for r in ok]) / frames.sum())
                if ok else None
            ),
            "keypoint_err_mean_m": (
                float(np.sum([r["keypoint_err_mean_m"] * r["frames"] for r in ok]) / frames.sum())
                if ok else None
            ),
            "penetration_max_m": float(pens.max()) if ok else None,
            "penetration_mean_of_max_m": float(pens.mean()) if ok else None,
            "self_penetration_max_m": max(
                (r["self_penetration_max_m"] for r in ok
                 if r.get("self_penetration_max_m") is not None),
                default=None,
            ),
            "contact_err_mean_m": (
                float(np.sum(contact_v * contact_w) / contact_w.sum()) if contact_w.sum() else None
            ),
            "success_rate": float(np.mean([bool(r.get("success")) for r in rs])),
            "success_loose_rate": float(np.mean([bool(r.get("success_loose")) for r in rs])),
            "sim_penetration_max_m": max(
                (r["sim_penetration_max_m"] for r in ok if "sim_penetration_max_m" in r),
                default=None,
            ),
            "table_penetration_max_m": max(
                (r["table_penetration_max_m"] for r in ok
                 if r.get("table_penetration_max_m") is not None),
                default=None,
            ),
            "runs_below_table_2cm": sum(
                1 for r in ok if (r.get("table_penetration_max_m") or 0.0) > 0.02
            ),
        }  # fmt: skip
    return out


def target_checks(overall: dict) -> list[dict]:
    """The issue's targets against the overall aggregates."""
    ours, dex = overall.get(OURS), overall.get(DEX)
    if not (ours and dex):
        return []

    def ratio(a, b):
        return None if b == 0 else a / b

    checks = [
        {"target": f"ms/frame ≤ {TARGET_MS} (contact + penetration terms on)",
         "value": ours["ms_per_frame"], "met": ours["ms_per_frame"] <= TARGET_MS,
         # The absolute target depends on the machine (dex-retargeting took 0.84–1.96 ms per
         # frame where it was set): the same run's ratio is reported beside it.
         "dex_ms_per_frame": dex["ms_per_frame"],
         "ratio": ratio(ours["ms_per_frame"], dex["ms_per_frame"] or 0)},
        {"target": "keypoint error ≤ dex-retargeting's",
         "value": [ours["keypoint_err_mean_m"], dex["keypoint_err_mean_m"]],
         "met": ours["keypoint_err_mean_m"] <= dex["keypoint_err_mean_m"]},
        {"target": f"penetration ≤ {TARGET_PEN_MM} mm max",
         "value": ours["penetration_max_m"],
         "met": 1e3 * ours["penetration_max_m"] <= TARGET_PEN_MM},
    ]  # fmt: skip
    for key, label in (("success_rate", "strict"), ("success_loose_rate", "loose")):
        r = ratio(ours[key], dex[key])
        checks.append(
            {
                "target": f"re-sim {label} success ≥ {TARGET_SUCCESS_RATIO}× dex-retargeting's",
                "value": [ours[key], dex[key]],
                "ratio": r,
                "met": (ours[key] >= TARGET_SUCCESS_RATIO * dex[key]) and ours[key] > 0,
            }
        )
    return checks


# ----------------------------------------------------------------------------------- output
def _ms(a: dict) -> str:
    """ms/frame (the median over the timing repeats), and their minimum where it differs."""
    if a["ms_per_frame"] is None:
        return "–"
    s = f"{a['ms_per_frame']:.3f}"
    lo = a.get("ms_per_frame_min")
    return s if lo is None or lo == a["ms_per_frame"] else f"{s} (min {lo:.3f})"


def metrics_table(title: str, agg: dict):

    t = Table(
        title=title,
        caption=f"{OURS}: re-simulated on q_command (grip squeeze); {OURS_Q}: on q. "
        "Kinematic columns of both: q. pen: hand–object; self pen: finger–finger/palm; table "
        "pen: hand below the re-simulation's table (diagnostic).",
    )
    for col in ("method", "runs", "ms/frame", "kp err mm", "pen max mm", "self pen mm",
                "contact err mm", "strict %", "loose %", "table pen mm"):  # fmt: skip
        t.add_column(col, justify="left" if col == "method" else "right")
    for method in METHODS:
        a = agg.get(method)
        if a is None:
            continue
        t.add_row(
            method,
            f"{a['runs']}" + (f" ({a['errors']} err)" if a["errors"] else ""),
            _ms(a),
            mm(a["keypoint_err_mean_m"], ".2f"),
            mm(a["penetration_max_m"], ".2f"),
            mm(a.get("self_penetration_max_m"), ".2f"),
            mm(a["contact_err_mean_m"], ".2f"),
            pct(a["success_rate"], unit=""),
            pct(a["success_loose_rate"], unit=""),
            mm(a["table_penetration_max_m"], ".2f"),
        )
    return t


def targets_table(checks: list[dict]):
    t = Table(title="targets (issue)")
    t.add_column("target")
    t.add_column("measured", justify="right")
    t.add_column("met", justify="center")
    for c in checks:
        v = c["value"]
        if "ms/frame" in c["target"]:
            s = f"{v:.3f} ms"
            if c.get("ratio") is not None:
                s += f" ({c['ratio']:.2f}× dex-retargeting's {c['dex_ms_per_frame']:.3f})"
        elif "keypoint" in c["target"]:
            s = f"{1e3 * v[0]:.2f} vs {1e3 * v[1]:.2f} mm"
        elif "penetration" in c["target"]:
            s = f"{1e3 * v:.2f} mm"
        else:
            s = f"{100 * v[0]:.0f}% vs {100 * v[1]:.0f}%" + (
                f" ({c['ratio']:.2f}×)" if c.get("ratio") is not None else ""
            )
        t.add_row(c["target"], s, "[green]yes[/green]" if c["met"] else "[red]no[/red]")
    return t


# ------------------------------------------------------------------------------------- main
def run_benchmark(cfg: BenchConfig, console=None) -> dict:
    """Run every hand × pair, print the tables, write the JSON; return the JSON document."""

    # Tables are wider than the 80 columns rich assumes off a terminal.
    console = console or Console(width=None if sys.stdout.isatty() else 120)
    cfg = resolve_out(cfg.validate(), NAME)
    t_start = time.perf_counter()
    load0 = os.getloadavg()
    hands = [get_hand(h) for h in (cfg.hands or available_hands())]
    demos, source, demo_failures = load_demonstrations(cfg, console)
    if not demos:
        raise SystemExit("no demonstrations to run")
    groups = {g: sum(1 for p, _ in demos if p.manipulation_type.group == g) for g in GROUPS}
    console.print(
        f"{len(demos)} pairs from {source} ({', '.join(f'{g} {n}' for g, n in groups.items())}); "
        f"hands: {', '.join(h.name for h in hands)}"
    )
    rows: list[dict] = []
    skipped: list[dict] = []
    jobs = []
    for hand in hands:
        for pair, traj in demos:
            try:
                check_pair(hand, pair.manipulation_type)
            except Exception as e:
                skipped.append({"hand": hand.name, "pair": str(pair), "reason": str(e)})
                continue
            jobs.append((hand, pair, traj))
    baselines: dict[str, object] = {}
    with progress_bar(console) as prog:
        task = prog.add_task("retargeting + re-simulating", total=len(jobs))
        for hand, pair, traj in jobs:
            prog.update(task, description=f"{hand.name} · {pair}")
            try:
                if hand.name not in baselines:
                    baselines[hand.name] = DexRetargetingBaseline(
                        hand, DexRetargetingConfig(wrist=cfg.dex_wrist)
                    )
                rows.extend(
                    run_one(
                        hand, pair, traj, baselines[hand.name], cfg.overrides, cfg.timing_repeats
                    )
                )
            except Exception as e:  # recorded in the JSON and counted in the tables
                err = f"{type(e).__name__}: {e}"
                console.print(f"[red]{hand.name} · {pair}: {err}[/red]")
                tb = traceback.format_exc(limit=3)
                for method in METHODS:
                    rows.append({"hand": hand.name, "pair": str(pair), "method": method,
                                 "group": pair.manipulation_type.group, "frames": traj.num_frames,
                                 "error": err, "traceback": tb})  # fmt: skip
            prog.advance(task)

    per_hand = {h.name: aggregate([r for r in rows if r["hand"] == h.name]) for h in hands}
    per_group = {g: aggregate([r for r in rows if r["group"] == g]) for g in GROUPS}
    overall = aggregate(rows)
    checks = target_checks(overall)
    for h in hands:
        if per_hand[h.name]:
            n_skip = sum(1 for s in skipped if s["hand"] == h.name)
            title = f"{h.name}" + (f" ({n_skip} pair(s) skipped: cannot perform)" if n_skip else "")
            console.print(metrics_table(title, per_hand[h.name]))
    console.print(metrics_table(f"overall: {len(hands)} hand(s) × {len(demos)} pair(s)", overall))
    if checks:
        console.print(targets_table(checks))
    doc = {
        "benchmark": "retarget_speed_quality",
        "command": command_line("benchmarks.retarget_speed_quality"),
        "config": {**asdict(cfg), "out": str(cfg.out)},
        "demonstrations": {
            "source": source,
            "pairs": [str(p) for p, _ in demos],
            "frames": {str(p): t.num_frames for p, t in demos},
            "generation_failures": demo_failures,
        },
        "hands": [h.name for h in hands],
        "skipped": skipped,
        "commit": git_commit(),
        "machine": machine_info(load0),
        "versions": versions(VERSION_DISTS),
        "definitions": {
            "ms_per_frame": "per-frame solve time only (ours: Retargeter._warm_start + "
            "_solve_frame; dex-retargeting: SeqRetargeting.retarget), total / frames; the "
            "median over config.timing_repeats runs per pair, the methods alternating",
            "ms_per_frame_min": "the same with each pair's fastest repeat",
            "ms_per_frame_total": "ours: the whole Retargeter.retarget loop (incl. in-loop "
            "metrics and grip squeeze) / frames",
            "keypoint_err_mean_m": "mean over frames of the mean robot-site to scaled-target "
            "distance (frame-weighted in aggregates)",
            "penetration_max_m": "deepest kinematic hand-object penetration (max over frames; "
            "aggregates: max over runs)",
            "contact_err_mean_m": "mean over active fingertip contacts (contact-frame-weighted "
            "in aggregates)",
            "success": "Resimulator strict rule (no frame > 5 cm)",
            "success_loose": "Resimulator loose rule (mean < 10 cm and < 0.5 rad)",
            "sim_penetration_max_m": "deepest hand-object penetration seen in the re-simulation",
            "table_penetration_max_m": "deepest kinematic penetration of the hand into the "
            "re-simulation's table plane along the re-simulated joint trajectory (diagnostic)",
        },
        "targets": checks,
        "aggregates": {"overall": overall, "per_hand": per_hand, "per_group": per_group},
        "runs": rows,
        "wall_time_s": time.perf_counter() - t_start,
    }
    atomic_write_json(cfg.out, doc)
    console.print(f"wrote {cfg.out} ({doc['wall_time_s']:.0f} s)")
    return doc


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.retarget_speed_quality",
        description=__doc__.split("\n\n")[0],
    )
    ap.add_argument("--hands", nargs="+", default=None, help="hands to run (default: all)")
    ap.add_argument("--n-pairs", type=int, default=20, help="pairs over the four groups")
    ap.add_argument("--max-frames", type=int, default=None, help="crop each demonstration")
    ap.add_argument(
        "--out",
        type=Path,
        default=None,
        help="JSON output (default: "
        "benchmarks/results/retarget_speed_quality/<date>-<commit>.json)",
    )
    ap.add_argument("--quick", action="store_true", help="smoke run: 2 pairs, 1 hand")
    ap.add_argument("--operator", default="operator1")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--dex-wrist",
        choices=("free", "fixed"),
        default="free",
        help="dex-retargeting's wrist: optimised (free) or the human wrist pose",
    )
    ap.add_argument(
        "--set",
        action="append",
        type=parse_override,
        default=[],
        metavar="NAME=VALUE",
        help="change a RetargetConfig field of ours (repeatable), e.g. --set w_posture=0",
    )
    ap.add_argument(
        "--timing-repeats",
        type=int,
        default=1,
        metavar="N",
        help="time each pair's solves N times, the methods alternating; ms/frame is the median "
        "(the minimum beside it)",
    )
    a = ap.parse_args(argv)

    overrides = config_overrides(a.set, RetargetConfig)
    hands = tuple(a.hands) if a.hands else None
    n_pairs = a.n_pairs
    if a.quick:
        hands = hands[:1] if hands else ("allegro",)
        n_pairs = min(n_pairs, 2)
    cfg = BenchConfig(hands=hands, n_pairs=n_pairs, max_frames=a.max_frames, out=a.out,
                      operator=a.operator, seed=a.seed, dex_wrist=a.dex_wrist,
                      overrides=overrides, timing_repeats=a.timing_repeats)  # fmt: skip
    run_benchmark(cfg)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
