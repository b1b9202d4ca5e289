"""Scale benchmark: what one core does per stage, how 1 → 2 workers scale on a process pool and
on a private local Ray, and what that projects to for the real release on N cores.

1. **Per-stage throughput** — demonstration-seconds per CPU-second (``time.process_time`` in
   this process) of each stage of ``retarget.pipeline.retarget_demonstration``, on the
   built-in demonstrations (``--pairs`` of :data:`PAIRS`, each clipped to ``--seconds`` from
   frame ``--start``) × ``--hands``: human forces (``human_forces``, once per demonstration),
   retarget (``Retargeter.retarget``) and re-simulate (``Resimulator.run``) without and with
   force matching, force calibration (``calibrate_forces``, ``--iterations``; per iterate
   too), and the physics refinement (``retarget.refine.refine``) of the first
   ``--refine-runs`` runs whose re-simulation lost the object (a run that kept it when none
   did, marked so). Constructors (``Retargeter``, ``Resimulator``) are timed apart (setup).
2. **Scaling** — the jobs "retarget + re-simulate one demonstration × hand without forces"
   (``retarget_demonstration``) on a spawn ``ProcessPoolExecutor`` with each of ``--workers``
   and, with ``--ray``, as Ray tasks on a private local Ray (``address="local"``, bound to
   127.0.0.1, no dashboard) with as many CPUs: wall time after the workers are started and
   warm, speedup against one worker; Ray's overhead per task (a no-op task's round trip, and
   (Ray wall − pool wall) / tasks) and as a share of the mean task time.
3. **Projection** (:func:`project`) — the real release (70 h at 120 Hz × 7 hands) on N cores
   without and with ``--forces``, from the per-stage CPU costs, the 2-worker efficiency and
   Ray's overhead; the assumptions are written into the result (``projection.assumptions``).
   Also what 4 calibration iterates instead of 10 would buy: the calibration's chosen iterate
   restricted to the first 4 (iterate ``k`` does not depend on how many follow, so this is the
   4-iterate run's result exactly) — success and force error against the 10-iterate choice.

The machine is shared, so every timing is a sample: the load average (``os.getloadavg()``)
is recorded beside each. Writes JSON (``benchmarks/results/scale/<date>-<commit>.json``) and
``docs/benchmarks/scale.md``::

    python -m benchmarks.scale --quick                 # a few minutes
    python -m benchmarks.scale --hands shadow allegro panda --pairs 3 --seconds 0 --ray
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from rich.console import Console

from benchmarks._common import (
    ROOT,
    atomic_write_json,
    command_line,
    display_path,
    error_record,
    git_commit,
    init_worker,
    machine_info,
    one_thread_env,
    result_path,
    versions,
)
from benchmarks.scale_report import (
    PAGE,
    calibration_cut,
    project,
    render_page,
    scaling_summary,
    tables,
    throughput,
)
from dexcanvas_core import load_demonstration
from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.safe_io import atomic_write_text
from dexcanvas_core.table import table_of
from retarget.config import RetargetConfig
from retarget.errors import RetargetError
from retarget.force_calibration import ForceCalibrationConfig, calibrate_forces
from retarget.hands import get_hand
from retarget.pipeline import human_forces, refine_config, retarget_demonstration
from retarget.refine import refine
from retarget.retargeter import Retargeter
from retarget.validate import FORCE_CONTACT_TIMECONST, Resimulator, ValidateConfig

NAME = "scale"
PAIRS = ("cube2/tripod", "cube2/lateral_pinch", "cuboid3/palmar_pinch")
"""The built-in demonstrations measured, in order (``--pairs`` takes the first N)."""


def load() -> list[float]:
    """The 1, 5 and 15 minute load averages now."""
    return [round(x, 2) for x in os.getloadavg()]


def clip(pair: str, start: int, seconds: float):
    """The built-in demonstration of ``pair`` from frame ``start``, ``seconds`` long (0: to the
    end)."""
    traj = load_demonstration(pair)
    stop = (
        traj.num_frames if seconds <= 0 else min(traj.num_frames, start + round(seconds * traj.fps))
    )
    return traj.slice(min(start, stop - 2), stop)


def _cpu(fn, *args, **kw):
    """``(fn(...), CPU seconds)``."""
    t0 = time.process_time()
    out = fn(*args, **kw)
    return out, time.process_time() - t0


# ------------------------------------------------------------------------ per-stage throughput
def stage_runs(cfg: argparse.Namespace, console: Console) -> list[dict]:
    """One row per pair × hand: each stage's CPU seconds, the clip length and the outcomes."""
    rows, cands = [], []
    for pair in cfg.pair_list:
        traj = clip(pair, cfg.start, cfg.seconds)
        obj = pair.split("/")[0]
        geometry, table = object_geometry(obj), table_of(traj)
        hf = {"load": load()}
        try:
            (ftraj, _), hf["cpu_s"] = _cpu(human_forces, traj, obj)
        except RetargetError as e:
            ftraj, hf["error"] = None, str(e)
        for name in cfg.hands:
            console.print(f"  {pair} × {name} ({traj.duration:.1f} s)")
            hand = get_hand(name)
            row = {
                "pair": pair,
                "hand": name,
                "demo_s": traj.duration,
                "frames": traj.num_frames,
                "load": load(),
                "cpu_s": {},
                "setup_cpu_s": {},
            }
            if name == cfg.hands[0]:
                row["cpu_s"]["human_forces"] = hf.get("cpu_s")
                row["human_forces_error"] = hf.get("error")
            rt, row["setup_cpu_s"]["retargeter"] = _cpu(Retargeter, hand, geometry, table=table)
            robot, row["cpu_s"]["retarget"] = _cpu(rt.retarget, traj)
            resim, row["setup_cpu_s"]["resimulator"] = _cpu(
                Resimulator, hand, geometry, ValidateConfig(), table=table
            )
            sim, row["cpu_s"]["resim"] = _cpu(resim.run, robot.q_command, traj)
            row["success"] = bool(sim.success)
            cands.append((row, hand, geometry, rt, robot, traj, False, not sim.success))
            if ftraj is not None:
                fcfg = RetargetConfig.from_overrides({"force_matching": True})
                rtf = Retargeter(hand, geometry, fcfg, table=table)
                robotf, row["cpu_s"]["retarget_f"] = _cpu(rtf.retarget, ftraj)
                vcfg = ValidateConfig(contact_timeconst=FORCE_CONTACT_TIMECONST)
                resimf = Resimulator(hand, geometry, vcfg, table=table)
                simf, row["cpu_s"]["resim_f"] = _cpu(resimf.run, robotf.q_command, ftraj)
                cal, row["cpu_s"]["calibrate"] = _cpu(
                    calibrate_forces,
                    rtf,
                    resimf,
                    robotf,
                    ftraj,
                    simf,
                    ForceCalibrationConfig(iterations=cfg.iterations),
                )
                row["success_f_planned"] = bool(simf.success)
                row["calibration"] = {
                    "iterations": cfg.iterations,
                    "iterates": [
                        it.__dict__ | {"match_error": _finite(it.match_error)}
                        for it in cal.iterates
                    ],
                }
                cands.append((row, hand, geometry, rtf, robotf, ftraj, True, not simf.success))
            rows.append(row)
    lost = [c for c in cands if c[-1]] or cands[:1]  # none lost: time a run that kept it
    for row, hand, geometry, rt, robot, traj, forces, failed in lost[: cfg.refine_runs]:
        console.print(f"  refining {row['pair']} × {row['hand']} (forces: {forces})")
        res, row["cpu_s"]["refine"] = _cpu(
            refine, hand, geometry, traj, robot, rt.tip_sites, refine_config(forces)
        )
        row["refine"] = {"replay_failed": failed, "forces": forces, "success": bool(res.success)}
    return rows


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


# ---------------------------------------------------------------------------------- scaling
def job(pair: str, hand: str, start: int, seconds: float) -> dict:
    """One scaling job: retarget + re-simulate ``pair`` (clipped) onto ``hand`` without forces;
    its CPU and wall seconds in the worker and the outcome."""
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        res = retarget_demonstration(clip(pair, start, seconds), pair, hand)
        ok = {"success": bool(res.success)}
    except Exception as e:  # a failed job is a row, the run goes on
        ok = error_record(e)
    return {
        "pair": pair,
        "hand": hand,
        "cpu_s": time.process_time() - c0,
        "wall_s": time.perf_counter() - t0,
        **ok,
    }


def noop() -> int:
    """A task that does nothing (Ray's round trip)."""
    return os.getpid()


def warm(hands: list[str], pair: str, start: int) -> int:
    """Warm a worker outside the timed batch: one thread, and a 5-frame job per hand (imports,
    models, the demonstration's cache)."""
    init_worker()
    for h in hands:
        retarget_demonstration(clip(pair, start, 5 / 120), pair, h)
    return os.getpid()


def pool_batch(jobs: list[tuple], workers: int, cfg) -> dict:
    """The jobs on a spawn pool of ``workers`` (warm first): wall time and the jobs' rows."""
    ctx = multiprocessing.get_context("spawn")
    t0 = time.perf_counter()
    with one_thread_env(), ProcessPoolExecutor(workers, mp_context=ctx) as pool:
        list(pool.map(warm, *([x] * workers for x in (cfg.hands, jobs[0][0], cfg.start))))
        started = time.perf_counter() - t0
        ld, t1 = load(), time.perf_counter()
        futs = [pool.submit(job, *j) for j in jobs]
        out = [f.result() for f in futs]
        wall = time.perf_counter() - t1
    return {
        "engine": "pool",
        "workers": workers,
        "start_s": started,
        "wall_s": wall,
        "load": ld,
        "load_end": load(),
        "jobs": out,
    }


def ray_batch(jobs: list[tuple], workers: int, cfg) -> dict:
    """The jobs as Ray tasks on a private local Ray of ``workers`` CPUs bound to 127.0.0.1: wall
    time, the jobs' rows, and a no-op task's mean round trip."""
    import ray  # the distributed extra: only this part needs it

    saved = os.environ.get("PYTHONPATH")
    path = os.pathsep.join(p for p in (str(ROOT), saved) if p)  # the workers import this checkout
    t0 = time.perf_counter()
    with one_thread_env(), tempfile.TemporaryDirectory(prefix="rs", dir="/tmp") as tmp:
        os.environ["PYTHONPATH"] = path  # Ray's processes inherit the driver's environment
        try:
            ray.init(
                address="local",
                num_cpus=workers,
                include_dashboard=False,
                _node_ip_address="127.0.0.1",
                _temp_dir=tmp,
                log_to_driver=False,
                logging_level="ERROR",
            )
        finally:
            if saved is None:
                os.environ.pop("PYTHONPATH")
            else:
                os.environ["PYTHONPATH"] = saved
        try:
            rjob, rnoop, rwarm = (ray.remote(num_cpus=1)(f) for f in (job, noop, warm))
            ray.get([rwarm.remote(cfg.hands, jobs[0][0], cfg.start) for _ in range(workers)])
            started = time.perf_counter() - t0
            t1 = time.perf_counter()
            for _ in range(cfg.noops):
                ray.get(rnoop.remote())
            roundtrip = (time.perf_counter() - t1) / cfg.noops
            ld, t1 = load(), time.perf_counter()
            out = ray.get([rjob.remote(*j) for j in jobs])
            wall = time.perf_counter() - t1
        finally:
            ray.shutdown()
    return {
        "engine": "ray",
        "workers": workers,
        "start_s": started,
        "wall_s": wall,
        "noop_roundtrip_s": roundtrip,
        "load": ld,
        "load_end": load(),
        "jobs": out,
    }


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.scale",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    ap.add_argument("--hands", nargs="+", default=["shadow", "allegro", "panda"])
    ap.add_argument("--pairs", type=int, default=3, help=f"how many of {', '.join(PAIRS)}")
    ap.add_argument("--seconds", type=float, default=0.0, help="clip length [s]; 0: whole")
    ap.add_argument("--start", type=int, default=230, help="clip's first frame (the grasp)")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--ray", action="store_true", help="also on a private local Ray")
    ap.add_argument("--repeat-jobs", type=int, default=1, help="scaling jobs: pairs×hands×this")
    ap.add_argument("--iterations", type=int, default=10, help="calibration iterates")
    ap.add_argument("--fewer-iterates", type=int, default=4, help="the cheaper calibration")
    ap.add_argument("--refine-runs", type=int, default=1, help="refinements timed")
    ap.add_argument("--noops", type=int, default=50, help="no-op Ray tasks timed")
    ap.add_argument(
        "--quick",
        action="store_true",
        help="3 hands, 3 pairs, 2 s clips, 2× the jobs, with --ray: a few minutes",
    )
    ap.add_argument("--out", type=Path, default=None, help="JSON (default: the result path)")
    ap.add_argument("--page", type=Path, default=PAGE)
    cfg = ap.parse_args(argv)
    if cfg.quick:
        cfg.hands, cfg.pairs, cfg.seconds, cfg.repeat_jobs, cfg.ray = (
            ["shadow", "allegro", "panda"],
            3,
            2.0,
            2,
            True,
        )
    if not 1 <= cfg.pairs <= len(PAIRS):
        ap.error(f"--pairs must be 1..{len(PAIRS)}, got {cfg.pairs}")
    cfg.pair_list = list(PAIRS[: cfg.pairs])
    return cfg


def main(argv: list[str] | None = None) -> int:
    cfg = parse_args(argv)
    console, t0, load0 = Console(), time.perf_counter(), list(os.getloadavg())
    console.print("[bold]per-stage throughput[/bold]")
    rows = stage_runs(cfg, console)
    jobs = [(p, h, cfg.start, cfg.seconds) for p in cfg.pair_list for h in cfg.hands]
    jobs *= cfg.repeat_jobs
    batches = []
    for eng in ("pool", "ray") if cfg.ray else ("pool",):
        for w in cfg.workers:
            console.print(f"[bold]scaling[/bold]: {eng}, {w} worker(s), {len(jobs)} jobs")
            batches.append((pool_batch if eng == "pool" else ray_batch)(jobs, w, cfg))
    tp, sc = throughput(rows), scaling_summary(batches)
    commit = git_commit()
    doc = {
        "name": NAME,
        "commit": commit,
        "command": command_line("benchmarks.scale", argv),
        "machine": machine_info(load0),
        "versions": versions(["ray", "mujoco", "numpy"]),
        "config": {k: v for k, v in vars(cfg).items() if k not in ("out", "page", "pair_list")}
        | {"pairs": cfg.pair_list},
        "runs": rows,
        "throughput": tp,
        "batches": batches,
        "scaling": sc,
        "calibration_cut": calibration_cut(rows, cfg.fewer_iterates),
        "projection": project(tp, sc, fewer_iterates=cfg.fewer_iterates),
        "wall_time_s": time.perf_counter() - t0,
    }
    for t in tables(doc):
        console.print(t)
    out = cfg.out or result_path(NAME, commit)
    atomic_write_json(out, doc)
    atomic_write_text(cfg.page, render_page(json.loads(out.read_text()), out))
    console.print(f"wrote {display_path(out)}, {display_path(cfg.page)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
