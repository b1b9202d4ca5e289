"""Throughput of ``RLTrajectoryBuffer``: buffer steps per second at several environment counts.

One *step* is what an RL loop does per simulation step::

    obs = buf.get_observations()         # gather every env's current frame
    done = buf.advance_timesteps()       # t += 1, done at the last frame
    buf.reset_envs(done)                 # new seeded trajectories for the finished envs

Without ``--dataset`` the script writes a synthetic DexCanvas-layout dataset (``--trajectories``
rows of ``--min-frames``–``--max-frames`` frames at 120 Hz, no contacts) to a temporary
directory with the toolkit's writer, loads it once, then times ``--steps`` steps per env count
after ``--warmup`` untimed steps. Prints a table and writes JSON (default
``benchmarks/results/rl_buffer/<date>-<commit>.json``).

    python -m benchmarks.rl_buffer                      # 1024 and 8192 envs on the CPU
    python -m benchmarks.rl_buffer --envs 4096 --device cuda --steps 5000
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from benchmarks._common import atomic_write_json, git_commit, result_path
from dexcanvas_core.io import write_dataset
from dexcanvas_core.loaders import DexCanvasDataset, RLTrajectoryBuffer, trajectory_to_sample
from dexcanvas_core.trajectory import HandTrack, ObjectMove, ObjectTrack, Trajectory

NAME = "rl_buffer"
"""The benchmark's name: its results folder ``benchmarks/results/<NAME>/``."""


def synthetic_trajectory(rng: np.random.Generator, uuid: str, T: int, fps: int = 120) -> Trajectory:
    """A smooth random demonstration: sinusoidal wrist, finger and object motion."""
    t = np.arange(T) / fps

    def waves(n: int, amp: float) -> np.ndarray:
        f = rng.uniform(0.2, 1.5, n)
        ph = rng.uniform(0, 2 * np.pi, n)
        return (amp * np.sin(2 * np.pi * f * t[:, None] + ph)).astype(np.float32)

    hand = HandTrack(
        name="right",
        global_pos=waves(3, 0.05) + np.float32([0.0, 0.0, 0.15]),
        global_rot_aa=waves(3, 0.4),
        hand_pose=np.concatenate([waves(3, 0.4), waves(45, 0.3)], axis=1),
        joint_pos=waves(63, 0.08).reshape(T, 21, 3),
    )
    obj = ObjectTrack(
        "cube2", pos=waves(3, 0.03) + np.float32([0.0, 0.0, 0.03]), rot_aa=waves(3, 0.5)
    )
    return Trajectory(
        uuid=uuid,
        timestamp=t,
        fps=float(fps),
        hands=[hand],
        objects=[obj],
        gesture="tripod",
        operator="bench",
        scene="cube2",
        object_move=[ObjectMove("cube2", T // 5, 4 * T // 5)],
    )


def build_dataset(path: Path, n: int, min_frames: int, max_frames: int, seed: int) -> Path:
    rng = np.random.default_rng(seed)
    lengths = rng.integers(min_frames, max_frames + 1, n)
    trajs = (synthetic_trajectory(rng, f"bench{i:04d}", int(T)) for i, T in enumerate(lengths))
    return write_dataset(trajs, path, mode="overwrite")


@dataclass
class Result:
    num_envs: int
    steps: int
    seconds: float
    steps_per_s: float
    env_steps_per_s: float
    us_per_step: float
    resets: int
    """Environments reset during the timed steps (episodes finished)."""


def time_buffer(
    samples: list, num_envs: int, steps: int, warmup: int, device: str, seed: int
) -> Result:
    buf = RLTrajectoryBuffer(samples, num_envs=num_envs, device=device, seed=seed)
    sync = torch.cuda.synchronize if buf.device.type == "cuda" else (lambda: None)
    for _ in range(warmup):
        buf.get_observations()
        buf.reset_envs(buf.advance_timesteps())
    resets = torch.zeros((), dtype=torch.int64, device=buf.device)
    sync()
    t0 = time.perf_counter()
    for _ in range(steps):
        buf.get_observations()
        done = buf.advance_timesteps()
        resets += done.sum()
        buf.reset_envs(done)
    sync()
    dt = time.perf_counter() - t0
    return Result(
        num_envs=num_envs,
        steps=steps,
        seconds=dt,
        steps_per_s=steps / dt,
        env_steps_per_s=steps * num_envs / dt,
        us_per_step=dt / steps * 1e6,
        resets=int(resets),
    )


def print_table(results: list[Result], title: str) -> None:
    try:
        from rich.console import Console
        from rich.table import Table
    except ImportError:  # plain text
        print(title)
        print(f"{'envs':>8} {'steps/s':>12} {'env-steps/s':>14} {'µs/step':>10}")
        for r in results:
            print(
                f"{r.num_envs:>8} {r.steps_per_s:>12,.0f} {r.env_steps_per_s:>14,.0f} "
                f"{r.us_per_step:>10.1f}"
            )
        return
    table = Table(title=title)
    for col in ("envs", "steps/s", "env-steps/s", "µs/step", "episodes ended"):
        table.add_column(col, justify="right")
    for r in results:
        table.add_row(
            str(r.num_envs), f"{r.steps_per_s:,.0f}", f"{r.env_steps_per_s:,.0f}",
            f"{r.us_per_step:.1f}", f"{r.resets:,}",
        )  # fmt: skip
    Console().print(table)


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(
        prog="python -m benchmarks.rl_buffer", description=__doc__.split("\n\n")[0]
    )
    p.add_argument("--dataset", type=Path, help="DexCanvas Lance dataset (default: synthetic)")
    p.add_argument("--envs", type=int, nargs="+", default=[1024, 8192], help="env counts")
    p.add_argument("--steps", type=int, default=2000, help="timed steps per env count")
    p.add_argument("--warmup", type=int, default=50, help="untimed steps first")
    p.add_argument("--device", default="cpu")
    p.add_argument("--threads", type=int, default=None, help="torch intra-op threads")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--trajectories", type=int, default=64, help="synthetic: number of rows")
    p.add_argument("--min-frames", type=int, default=300, help="synthetic: shortest row")
    p.add_argument("--max-frames", type=int, default=1200, help="synthetic: longest row")
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="JSON results (default: benchmarks/results/rl_buffer/<date>-<commit>.json)",
    )
    args = p.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)

    with tempfile.TemporaryDirectory(prefix="rl_buffer_bench_") as tmp:
        t0 = time.perf_counter()
        path = args.dataset or build_dataset(
            Path(tmp) / "bench.lance",
            args.trajectories,
            args.min_frames,
            args.max_frames,
            args.seed,
        )
        t_build = time.perf_counter() - t0
        t0 = time.perf_counter()
        ds = DexCanvasDataset(path)
        samples = [trajectory_to_sample(t) for t in ds.iter_trajectories()]
        t_load = time.perf_counter() - t0
    lengths = [int(s["finger_pose"].shape[0]) for s in samples]

    results = [
        time_buffer(samples, e, args.steps, args.warmup, args.device, args.seed) for e in args.envs
    ]
    title = (
        f"RLTrajectoryBuffer on {args.device} ({torch.get_num_threads()} threads): "
        f"{len(samples)} trajectories, {sum(lengths):,} frames"
    )
    print_table(results, title)
    report = {
        "benchmark": "rl_buffer",
        "step": "get_observations + advance_timesteps + reset_envs(done)",
        "device": args.device,
        "torch": torch.__version__,
        "threads": torch.get_num_threads(),
        "cpu_count": os.cpu_count(),
        "machine": platform.machine(),
        "python": sys.version.split()[0],
        "dataset": str(args.dataset) if args.dataset else "synthetic",
        "trajectories": len(samples),
        "frames": sum(lengths),
        "frames_min_max": [min(lengths), max(lengths)],
        "fields": list(RLTrajectoryBuffer(samples, 1).fields),
        "dataset_build_s": round(t_build, 3) if not args.dataset else None,
        "dataset_load_s": round(t_load, 3),
        "results": [asdict(r) for r in results],
    }
    args.out = args.out or result_path(NAME, git_commit())
    atomic_write_json(args.out, report)
    print(f"wrote {args.out}")
    return report


if __name__ == "__main__":
    main()
