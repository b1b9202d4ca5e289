"""The work per pair: its demonstration (and mocap fit), its simulations, and the pool that runs
them."""

from __future__ import annotations

import time
from concurrent.futures import FIRST_COMPLETED, wait
from pathlib import Path

import numpy as np

from benchmarks._common import (
    error_record,
    generate_one,
    operator_for,
    progress_bar,
    worker_pool,
)
from benchmarks.force_pipeline.config import MOCAP_DROPOUT, MOCAP_NOISE_MM, BenchConfig
from dexcanvas_core.mocap import fit_markers, render_markers
from dexcanvas_core.rotations import rotation_angle_between_aa
from dexcanvas_core.sim.pipeline import simulate
from dexcanvas_core.sim.plots import plot_finger_forces


# ------------------------------------------------------------------------------------ workers
def _prepare(args) -> dict:
    """Worker: generate the demonstration of pair ``i`` and, if asked, its mocap fit.

    Returns ``{"record": dict, "clean": Trajectory | None, "mocap": Trajectory | None}``.
    """

    i, pair, seed, mocap = args
    rec: dict = {
        "index": i,
        "pair": str(pair),
        "manipulation_type": pair.manipulation_type.name,
        "object": pair.object.id,
        "operator": operator_for(i),
    }
    out: dict = {"record": rec, "clean": None, "mocap": None}
    t0 = time.perf_counter()
    try:
        demo, used = generate_one(pair, i, seed)
    except Exception as e:
        rec.update(error_record(e))
        return out
    traj = demo.trajectory
    rec.update(
        seed=used,
        uuid=traj.uuid,
        frames=traj.num_frames,
        duration_s=traj.num_frames / traj.fps,
        plausible=bool(demo.report.passed),
        generation_s=time.perf_counter() - t0,
    )
    out["clean"] = traj
    if not mocap:
        return out
    try:
        stream = render_markers(traj, noise_mm=MOCAP_NOISE_MM, dropout=MOCAP_DROPOUT, seed=seed + i)
        t0 = time.perf_counter()
        fit = fit_markers(
            stream,
            object_id=traj.object.name,
            uuid=traj.uuid,
            operator=traj.operator,
            gesture=traj.gesture,
        )
        ft = fit.trajectory
        kp = np.linalg.norm(ft.hand.joint_pos - traj.hand.joint_pos, axis=-1)
        rec["mocap_fit"] = {
            "fit_s": time.perf_counter() - t0,
            "keypoint_err_mean_mm": float(1e3 * kp.mean()),
            "object_pos_err_mean_mm": float(
                1e3 * np.linalg.norm(ft.object.pos - traj.object.pos, axis=-1).mean()
            ),
            "object_rot_err_mean_deg": float(
                np.degrees(rotation_angle_between_aa(ft.object.rot_aa, traj.object.rot_aa)).mean()
            ),
            "frames_long_gap": int(fit.flags.long_gap.sum()),
            "frames_interpolated": int(fit.flags.interpolated.sum()),
        }
        out["mocap"] = ft
    except Exception as e:
        rec["mocap_fit"] = error_record(e)
    return out


def hold_force_share(finger_mean: dict | None) -> dict | None:
    """Each part's share of the summed mean hold-force magnitudes, or ``None`` (no hold or no
    force)."""
    if not finger_mean:
        return None
    total = sum(finger_mean.values())
    if total <= 1e-9:
        return None
    return {k: v / total for k, v in finger_mean.items()}


def _simulate(args) -> dict:
    """Worker: one simulated run; its metrics (or the error), and its plot if asked."""

    i, pair, condition, sim_cfg, traj, plot_path = args
    row = {
        "index": i,
        "pair": str(pair),
        "condition": condition,
        "manipulation_type": pair.manipulation_type.name,
        "tracker": sim_cfg.tracker,
        "object_scale": sim_cfg.object_scale,
        "object_id": sim_cfg.object_id,
    }
    w0 = time.perf_counter()
    try:
        res = simulate(traj, sim_cfg)
        row.update({k: v for k, v in res.metrics.items() if k != "config"})
        row["hold_force_share"] = hold_force_share(res.metrics["hold_finger_force_mean_n"])
        if plot_path is not None:
            title = f"{pair} · {condition}" + (
                f" (size ×{sim_cfg.object_scale:g})" if sim_cfg.object_scale != 1.0 else ""
            )
            row["plot"] = str(plot_finger_forces(res, plot_path, title=title))
    except Exception as e:  # recorded in the JSON and counted as a failure
        row.update(error_record(e))
        row["success"] = row["success_loose"] = False
    row["wall_s"] = time.perf_counter() - w0
    return row


# --------------------------------------------------------------------------------------- main
def _sim_jobs(i: int, pair, prepared: dict, plan: list, cfg: BenchConfig, plot_dir: Path):
    """``(jobs, rows)``: the simulation jobs of pair ``i`` once its demonstration is ready, and
    error rows for the runs that have no trajectory (generation or mocap fit failed)."""
    rec = prepared["record"]
    jobs, rows = [], []
    for cond, sim_cfg in plan:
        traj = prepared["mocap"] if cond.startswith("mocap") else prepared["clean"]
        if traj is None:
            why = rec.get("error") or rec["mocap_fit"]["error"]
            rows.append({"index": i, "pair": str(pair), "condition": cond,
                         "manipulation_type": pair.manipulation_type.name,
                         "error": f"no demonstration: {why}", "success": False,
                         "success_loose": False})  # fmt: skip
            continue
        plot = None
        if i < cfg.plots:
            name = f"{i:02d}_{pair.object.id}_{pair.manipulation_type.name}_{cond}.png"
            plot = plot_dir / name
        jobs.append((i, pair, cond, sim_cfg, traj, plot))
    return jobs, rows


def run_jobs(cfg: BenchConfig, pairs: list, plans: list, plot_dir: Path, console):
    """Generate (and mocap-fit) every pair's demonstration, then simulate its runs as soon as
    it is ready, over ``cfg.workers`` spawned one-thread processes; ``(demos, rows)``."""
    mocap = any(c.startswith("mocap") for c in cfg.conditions)
    total = len(pairs) + sum(len(p) for p in plans)
    demos: dict[int, dict] = {}
    rows: list[dict] = []
    with worker_pool(cfg.workers) as pool, progress_bar(console) as prog:
        task = prog.add_task("generating + fitting", total=total)
        pending = {pool.submit(_prepare, (i, p, cfg.seed, mocap)): (i, None)
                   for i, p in enumerate(pairs)}  # fmt: skip
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                i, condition = pending.pop(fut)
                prog.advance(task)
                if condition is not None:  # a simulation
                    rows.append(fut.result())
                    prog.update(task, description=f"simulating · {pairs[i]} · {condition}")
                    continue
                prepared = fut.result()
                demos[i] = prepared["record"]
                jobs, failed = _sim_jobs(i, pairs[i], prepared, plans[i], cfg, plot_dir)
                rows += failed
                prog.advance(task, len(failed))
                for job in jobs:
                    pending[pool.submit(_simulate, job)] = (i, job[2])
    return demos, rows
