"""Mocap fit accuracy and speed: generated demonstrations → markers → MANO fit → errors.

For ``--n-demos`` demonstrations from the built-in generator (``dexcanvas_core.demos``; pairs
taken round-robin over the 21 manipulation types, operators cycled, so every type appears once
``--n-demos`` ≥ 21), the script renders the mocap marker stream (``mocap.render_markers``) at each
``--noise`` level [mm, per axis] with ``--dropout`` single-frame dropouts and the renderer's
default occlusion gaps and label swaps (``--gap-rate``, ``--swap-rate``), fits it
(``mocap.fit_markers``, default options) and compares with the demonstration:

* 21-keypoint error [mm] (``mano_joint_pos``): mean and 95th percentile over every keypoint of
  every frame, and over the frames not flagged ``long_gap``;
* object position [mm] and rotation [deg] error: mean and 95th percentile;
* fit throughput [frames/s]: frames fitted / elapsed wall time of the fitting alone (streams are
  rendered before, errors scored after), with ``--workers`` processes (default: one per CPU
  core) fitting demonstrations in parallel, one torch thread each. Also reported: the rate of a
  single process (frames / its summed ``fit_markers`` wall time) and per CPU-second (what the
  fit costs when the machine is shared with other work);
* label swaps found (share of truly swapped frames flagged ``swapped``) and flagged frames.

Prints a table and writes JSON (default ``benchmarks/results/mocap_fit/<date>-<commit>.json``)::

    python -m benchmarks.mocap_fit --n-demos 50 --noise 0 1 2 --dropout 0.1
"""

from __future__ import annotations

import argparse
import logging
import multiprocessing
import os
import platform
import sys
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import torch
from rich.console import Console
from rich.table import Table

from benchmarks._common import atomic_write_json, command_line, generate, git_commit, result_path
from dexcanvas_core.mocap import fit_markers, render_markers
from dexcanvas_core.rotations import rotation_angle_between_aa

NAME = "mocap_fit"
"""The benchmark's name: its results folder ``benchmarks/results/<NAME>/``."""


def _noop(_: int) -> None:
    return None


def _init_worker() -> None:
    logging.basicConfig(level=logging.ERROR)
    torch.set_num_threads(1)
    import dexcanvas_core.mocap  # noqa: F401  (import cost outside the timed region)


def _fit_job(stream) -> dict:
    c0, w0 = time.process_time(), time.perf_counter()
    fit = fit_markers(stream)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    t = fit.trajectory
    return {
        "joint_pos": t.hand.joint_pos,
        "obj_pos": t.object.pos,
        "obj_rot": t.object.rot_aa,
        "long_gap": fit.flags.long_gap,
        "interpolated": fit.flags.interpolated,
        "swapped": fit.flags.swapped,
        "wall": wall,
        "cpu": cpu,
    }


def score(
    trajs: list,
    noise: float,
    dropout: float,
    gap_rate: float,
    swap_rate: float,
    pool: ProcessPoolExecutor | None,
) -> dict:

    streams = [
        render_markers(
            tr, noise_mm=noise, dropout=dropout, gap_rate=gap_rate, swap_rate=swap_rate, seed=i
        )
        for i, tr in enumerate(trajs)
    ]
    t0 = time.perf_counter()
    if pool is None:
        fits = [_fit_job(s) for s in streams]
    else:
        fits = list(pool.map(_fit_job, streams))
    elapsed = time.perf_counter() - t0
    kp, kp_ok, pos, ang = [], [], [], []
    swaps_true = swaps_found = flagged_long = flagged_interp = 0
    for tr, stream, fit in zip(trajs, streams, fits, strict=True):
        e = np.linalg.norm(fit["joint_pos"] - tr.hand.joint_pos, axis=-1) * 1000
        kp.append(e.reshape(-1))
        kp_ok.append(e[~fit["long_gap"]].reshape(-1))
        pos.append(np.linalg.norm(fit["obj_pos"] - tr.object.pos, axis=-1) * 1000)
        ang.append(np.rad2deg(rotation_angle_between_aa(fit["obj_rot"], tr.object.rot_aa)))
        truth = stream.truth.swapped.any(1)
        swaps_true += int(truth.sum())
        swaps_found += int((fit["swapped"] & truth).sum())
        flagged_long += int(fit["long_gap"].sum())
        flagged_interp += int(fit["interpolated"].sum())
    kp_a, kp_ok_a = np.concatenate(kp), np.concatenate(kp_ok)
    pos_a, ang_a = np.concatenate(pos), np.concatenate(ang)
    frames = sum(t.num_frames for t in trajs)
    wall = sum(f["wall"] for f in fits)
    cpu = sum(f["cpu"] for f in fits)

    def stats(a: np.ndarray) -> dict:
        return {"mean": float(a.mean()), "p95": float(np.percentile(a, 95))}

    return {
        "noise_mm": noise,
        "dropout": dropout,
        "demos": len(trajs),
        "frames": frames,
        "keypoint_error_mm": stats(kp_a),
        "keypoint_error_mm_unflagged": stats(kp_ok_a),
        "object_position_error_mm": stats(pos_a),
        "object_rotation_error_deg": stats(ang_a),
        "elapsed_seconds": elapsed,
        "frames_per_second": frames / elapsed,
        "fit_seconds_per_process": wall,
        "frames_per_second_per_process": frames / wall,
        "fit_cpu_seconds": cpu,
        "frames_per_cpu_second": frames / cpu,
        "swapped_frames_true": swaps_true,
        "swapped_frames_found": swaps_found,
        "frames_long_gap": flagged_long,
        "frames_interpolated": flagged_interp,
    }


def print_table(results: list[dict], title: str) -> None:
    table = Table(title=title)
    cols = (
        "noise [mm]",
        "kp mean [mm]",
        "kp p95 [mm]",
        "kp mean, unflagged",
        "obj pos mean/p95 [mm]",
        "obj rot mean/p95 [°]",
        "frames/s",
        "frames/s, 1 process",
        "frames/CPU-s",
        "swaps found",
    )
    for c in cols:
        table.add_column(c, justify="right")
    for r in results:
        k, ku = r["keypoint_error_mm"], r["keypoint_error_mm_unflagged"]
        p, a = r["object_position_error_mm"], r["object_rotation_error_deg"]
        found = (
            f"{r['swapped_frames_found']}/{r['swapped_frames_true']}"
            if r["swapped_frames_true"]
            else "–"
        )
        table.add_row(
            f"{r['noise_mm']:g}",
            f"{k['mean']:.3f}",
            f"{k['p95']:.3f}",
            f"{ku['mean']:.3f}",
            f"{p['mean']:.3f} / {p['p95']:.3f}",
            f"{a['mean']:.3f} / {a['p95']:.3f}",
            f"{r['frames_per_second']:,.0f}",
            f"{r['frames_per_second_per_process']:,.0f}",
            f"{r['frames_per_cpu_second']:,.0f}",
            found,
        )
    Console(width=160).print(table)


def main(argv: list[str] | None = None) -> dict:
    defaults = render_markers.__kwdefaults__
    p = argparse.ArgumentParser(
        prog="python -m benchmarks.mocap_fit", description=__doc__.split("\n\n")[0]
    )
    p.add_argument("--n-demos", type=int, default=50, help="demonstrations (≥ 21: all types)")
    p.add_argument("--noise", type=float, nargs="+", default=[0.0, 1.0, 2.0], help="σ [mm]")
    p.add_argument("--dropout", type=float, default=0.1, help="marker sample dropout rate")
    p.add_argument("--gap-rate", type=float, default=defaults["gap_rate"])
    p.add_argument("--swap-rate", type=float, default=defaults["swap_rate"])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--workers",
        type=int,
        default=os.cpu_count() or 1,
        help="fitting processes (one thread each); 1 fits in this process",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="JSON results (default: benchmarks/results/mocap_fit/<date>-<commit>.json)",
    )
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    torch.set_num_threads(1)

    t0 = time.perf_counter()
    trajs = generate(args.n_demos, args.seed)
    t_gen = time.perf_counter() - t0
    types = Counter(t.gesture for t in trajs)
    pool = None
    if args.workers > 1:
        ctx = multiprocessing.get_context("spawn")
        pool = ProcessPoolExecutor(args.workers, mp_context=ctx, initializer=_init_worker)
        list(pool.map(_noop, range(args.workers)))  # start the workers before timing
    try:
        results = [
            score(trajs, noise, args.dropout, args.gap_rate, args.swap_rate, pool)
            for noise in args.noise
        ]
    finally:
        if pool is not None:
            pool.shutdown()
    frames = sum(t.num_frames for t in trajs)
    title = (
        f"Mocap → MANO fit: {len(trajs)} demonstrations, {len(types)} manipulation types, "
        f"{frames:,} frames; dropout {args.dropout:g}, gaps {args.gap_rate:g}/marker/frame, "
        f"swaps {args.swap_rate:g}/frame"
    )
    print_table(results, title)
    report = {
        "benchmark": "mocap_fit",
        "command": command_line("benchmarks.mocap_fit", argv),
        "demos": len(trajs),
        "manipulation_types": dict(sorted(types.items())),
        "operators": dict(sorted(Counter(t.operator for t in trajs).items())),
        "frames_per_noise_level": frames,
        "render": {
            "dropout": args.dropout,
            "gap_rate": args.gap_rate,
            "gap_frames": list(defaults["gap_frames"]),
            "swap_rate": args.swap_rate,
        },
        "generation_seconds": t_gen,
        "torch": torch.__version__,
        "threads_per_fit": 1,
        "workers": args.workers,
        "cpu_count": os.cpu_count(),
        "machine": platform.machine(),
        "python": sys.version.split()[0],
        "results": results,
    }
    args.out = args.out or result_path(NAME, git_commit())
    atomic_write_json(args.out, report)
    print(f"wrote {args.out}")
    return report


if __name__ == "__main__":
    main()
