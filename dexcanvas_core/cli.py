"""``dexcanvas``: the command line of the human side (datasets, examples, exports).

A thin layer: each sub-command parses into a frozen config and calls a library function.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from dataclasses import dataclass
from pathlib import Path

from dexcanvas_core import __version__
from dexcanvas_core.capture.cli import add_import_parser, run_import_command
from dexcanvas_core.demos import BuildConfig, run_build
from dexcanvas_core.errors import DatasetError, DexCanvasError
from dexcanvas_core.example import build_example_dataset
from dexcanvas_core.exits import EXIT_FAILED, EXIT_OK, run_command
from dexcanvas_core.io import export_parquet, open_dataset
from dexcanvas_core.io.decode import row_to_trajectory
from dexcanvas_core.loaders.selection import select_rows
from dexcanvas_core.objects.options import add_object_options, use_object_options
from dexcanvas_core.plausibility import add_allow_implausible, allowing_implausible, check_fps
from dexcanvas_core.safe_io import check_output


def _human_bytes(n: int) -> str:
    size = float(n)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if size < 1024 or unit == "TiB":
            return f"{size:.1f} {unit}" if unit != "B" else f"{int(size)} B"
        size /= 1024
    return f"{n} B"


@dataclass(frozen=True)
class InfoConfig:
    path: Path
    as_json: bool = False


def run_info(cfg: InfoConfig) -> dict:
    """Summarise a dataset; print a table (or JSON) and return the summary."""
    from rich.console import Console
    from rich.table import Table

    info = open_dataset(cfg.path).info()
    d = info.to_dict()
    if cfg.as_json:
        print(json.dumps(d, indent=2, sort_keys=True))
        return d
    con = Console()
    t = Table(title=f"DexCanvas dataset {info.path}", show_header=False)
    t.add_row("rows (trajectories)", str(info.rows))
    t.add_row("frames", f"{info.frames:,}")
    t.add_row("duration", f"{info.duration_s:.1f} s ({info.duration_s / 3600:.3f} h)")
    t.add_row("fps", ", ".join(f"{k} Hz × {v}" for k, v in sorted(info.fps.items())))
    t.add_row("objects", str(len(info.objects)))
    t.add_row("manipulation types", str(len(info.gestures)))
    t.add_row("operators", ", ".join(f"{k} ({v})" for k, v in sorted(info.operators.items())))
    t.add_row("contacts", "yes" if info.has_contacts else "no")
    t.add_row("size on disk", _human_bytes(info.size_bytes))
    t.add_row("schema version", info.schema_version or "public (unversioned)")
    con.print(t)
    pairs = Table(title="pairs (object/manipulation_type)")
    pairs.add_column("pair")
    pairs.add_column("rows", justify="right")
    for k, v in sorted(info.pairs.items()):
        pairs.add_row(k, str(v))
    con.print(pairs)
    return d


@dataclass(frozen=True)
class ValidateConfig:
    path: Path


def run_validate(cfg: ValidateConfig) -> int:
    """Read every row with full validation; print the first problem of each bad row.

    Returns the number of bad rows.
    """
    from rich.console import Console
    from rich.progress import track

    con = Console()
    ds = open_dataset(cfg.path)
    n = len(ds)
    bad = 0
    position = 0
    batches = ds.iter_batches(batch_size=8)
    for batch in track(batches, description="validating", total=(n + 7) // 8, console=con):
        for i in range(batch.num_rows):
            try:
                row_to_trajectory(batch, i, dataset=ds.path, row=position, validate=True)
            except DexCanvasError as e:
                bad += 1
                con.print(f"[red]✗[/red] {e}")
            position += 1
    con.print(f"{n - bad} of {n} rows valid")
    return bad


@dataclass(frozen=True)
class ExportConfig:
    path: Path
    out: Path
    objects: tuple[str, ...] = ()
    manipulation_types: tuple[str, ...] = ()
    operators: tuple[str, ...] = ()
    overwrite: bool = False
    """Replace an existing Parquet file; without it one is refused before any work."""


def run_export(cfg: ExportConfig) -> Path:
    """Export a dataset (optionally filtered) to a Parquet file."""
    if Path(cfg.out).expanduser().is_dir():
        raise DatasetError(
            f"--parquet {cfg.out} is a directory; give the path of a file, e.g. "
            f"{Path(cfg.out) / 'export.parquet'}"
        )
    check_output(cfg.out, overwrite=cfg.overwrite, kind="file", what="--parquet")
    ds = open_dataset(cfg.path)
    sel = select_rows(
        ds,
        manipulation_types=list(cfg.manipulation_types) or None,
        objects=list(cfg.objects) or None,
        operators=list(cfg.operators) or None,
    )
    for _ in ds.iter_trajectories(filter=sel.filter):  # full validation, plausibility included
        pass
    out = export_parquet(cfg.path, cfg.out, filter=sel.filter, overwrite=cfg.overwrite)
    print(f"wrote {out}")
    return out


@dataclass(frozen=True)
class ExampleConfig:
    out: Path
    seed: int = 0
    overwrite: bool = False


def run_example(cfg: ExampleConfig) -> Path:
    """Write the built-in example dataset (synthetic, public layout) to ``cfg.out``."""
    out = build_example_dataset(cfg.out, seed=cfg.seed, overwrite=cfg.overwrite, progress=True)
    print(f"wrote {out}")
    return out


def run_demos_build_command(args: argparse.Namespace) -> int:
    """``dexcanvas demos build``: generate demonstrations; returns the number that failed."""
    cfg = BuildConfig(
        out=args.out,
        pairs=tuple(args.pairs) if args.pairs else None,
        reps=args.reps,
        seed=args.seed,
        overwrite=args.overwrite,
        workers=args.workers,
    )
    report = run_build(cfg, progress=True)
    for line in report.lines():
        print(line)
    return len(report.failed)


def run_fit_command(args: argparse.Namespace) -> dict:
    """``dexcanvas fit``: markers → MANO + object poses dataset with per-frame quality flags."""
    from rich.console import Console

    from dexcanvas_core.mocap import (  # lazy: mocap (scipy.signal/stats) ~1.2 s on --help
        FitConfig,
        run_fit,
    )

    if args.fps is not None:
        check_fps(args.fps)
    cfg = FitConfig(
        markers=args.markers,
        out=args.out,
        format=args.format,
        mapping=args.mapping,
        object_id=args.object,
        fps=args.fps,
        units=args.units,
        up=args.up,
        side=args.side,
        overwrite=args.overwrite,
        calibration_file=args.calibration,
        save_calibration=args.save_calibration,
    )
    with Console().status(f"fitting {args.markers}"):
        report = run_fit(cfg)
    d = report.to_dict()
    print(json.dumps(d, indent=2, sort_keys=True, default=str))
    return d


def _sim_config(args: argparse.Namespace):
    from dexcanvas_core.sim.mpc import MPCConfig  # lazy: mujoco ~0.5 s on --help
    from dexcanvas_core.sim.pipeline import SimConfig  # lazy: mujoco ~0.5 s on --help

    return SimConfig(
        tracker=args.tracker,
        mpc=MPCConfig(samples=args.samples, seed=args.seed),
        object_id=getattr(args, "object", None),
    ).validate()


def run_simulate_command(args: argparse.Namespace) -> dict:
    """``dexcanvas simulate``: track one demonstration in physics, write contacts and forces."""
    from dexcanvas_core.sim.run import SimulateConfig, run_simulate  # lazy: mujoco ~0.5 s on --help

    return run_simulate(
        SimulateConfig(
            pair=args.pair,
            out=args.out,
            dataset=args.dataset,
            index=args.index,
            sim=_sim_config(args),
            overwrite=args.overwrite,
            plot=not args.no_plot,
        )
    )


def run_synthesize_command(args: argparse.Namespace) -> dict:
    """``dexcanvas synthesize``: perturbed re-tracking, keeping the successful rollouts."""
    import numpy as np

    from dexcanvas_core.sim.run import (  # lazy: mujoco ~0.5 s on --help
        SynthesizeConfig,
        run_synthesize,
    )
    from dexcanvas_core.sim.synthesis import PerturbationRanges  # lazy: mujoco ~0.5 s on --help

    ranges = PerturbationRanges(
        size=args.size,
        mass=args.mass,
        friction=args.friction,
        hand=args.hand_scale,
        shift_m=args.shift,
        yaw_rad=float(np.deg2rad(args.yaw_deg)),
        object_offset_m=args.object_offset,
        object_offset_yaw_rad=float(np.deg2rad(args.object_offset_yaw_deg)),
    )
    return run_synthesize(
        SynthesizeConfig(
            dataset=args.dataset,
            out=args.out,
            expand=args.expand,
            seed=args.seed,
            workers=args.workers,
            sim=_sim_config(args),
            limit=args.limit,
            overwrite=args.overwrite,
            ranges=ranges,
        )
    )


def _add_tracker_args(s: argparse.ArgumentParser) -> None:
    s.add_argument("--tracker", choices=["mpc", "open_loop"], default="mpc",
                   help="sampling MPC (default) or the reference replayed open loop")  # fmt: skip
    s.add_argument("--samples", type=int, default=16, help="MPC samples per replan")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--overwrite", action="store_true", help="replace an existing output")


def build_parser() -> argparse.ArgumentParser:
    import numpy as np

    p = argparse.ArgumentParser(
        prog="dexcanvas",
        description="DexCanvas human demonstrations: inspect, validate, export, build examples.",
    )
    p.add_argument("--version", action="version", version=f"dexcanvas-retarget {__version__}")
    p.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    s = sub.add_parser(
        "info", help="summarise a Lance dataset (rows, pairs, operators, frames, fps, size)"
    )
    s.add_argument("path", type=Path, help="dataset directory (*.lance)")
    s.add_argument("--json", action="store_true", help="print JSON instead of tables")

    s = sub.add_parser(
        "validate", help="check every row of a dataset (shapes, NaNs, rotations, fps)"
    )
    s.add_argument("path", type=Path)
    add_allow_implausible(s)

    s = sub.add_parser("export", help="export a dataset (optionally filtered) to Parquet")
    s.add_argument("path", type=Path)
    s.add_argument("--parquet", type=Path, required=True, dest="out", help="output .parquet file")
    s.add_argument("--objects", nargs="*", default=[], help="object ids, e.g. cube2 sphere1")
    s.add_argument("--types", nargs="*", default=[], help="manipulation types (names or codes)")
    s.add_argument("--operators", nargs="*", default=[])
    s.add_argument("--overwrite", action="store_true", help="replace an existing --parquet file")
    add_allow_implausible(s)

    s = sub.add_parser("demos", help="generated human demonstrations")
    demos_sub = s.add_subparsers(dest="demos_command", required=True, metavar="SUBCOMMAND")
    b = demos_sub.add_parser("build", help="generate demonstrations into a Lance dataset")
    b.add_argument("--out", type=Path, required=True, help="output dataset directory (*.lance)")
    b.add_argument(
        "--pairs", nargs="*", default=None, help="OBJECT/TYPE pairs (default: every feasible pair)"
    )
    b.add_argument("--reps", type=int, default=1, help="demonstrations per pair")
    b.add_argument("--seed", type=int, default=0)
    b.add_argument("--workers", type=int, default=1, help="generator processes")
    b.add_argument("--overwrite", action="store_true")
    add_object_options(b)

    s = sub.add_parser("fit", help="fit MANO hand + object poses to mocap markers (C3D or CSV)")
    s.add_argument("markers", type=Path, help="marker file (.c3d or .csv)")
    s.add_argument("--out", type=Path, required=True, help="output dataset directory (*.lance)")
    s.add_argument("--format", choices=["auto", "c3d", "csv"], default="auto")
    s.add_argument("--mapping", type=Path, default=None, help="marker-name mapping (JSON or CSV)")
    s.add_argument("--object", default=None, help="catalogue object id carrying obj1..obj4")
    s.add_argument("--fps", type=float, default=None, help="frame rate [Hz] (default: the file's)")
    s.add_argument("--units", default=None, help="length unit of the file: mm, cm or m")
    s.add_argument("--up", choices=["y", "z"], default="y", help="vertical axis of the mocap frame")
    s.add_argument("--side", choices=["right", "left"], default=None)
    s.add_argument("--calibration", type=Path, default=None, help="saved subject calibration")
    s.add_argument("--save-calibration", type=Path, default=None)
    s.add_argument("--overwrite", action="store_true")
    add_allow_implausible(s)

    s = sub.add_parser(
        "simulate",
        help="track a demonstration with the simulated MANO hand; write contacts and forces",
    )
    s.add_argument("--pair", default=None,
                   help="OBJECT/TYPE, e.g. cube2/tripod (optional with --dataset)")  # fmt: skip
    s.add_argument("--dataset", type=Path, default=None, help="Lance dataset (default: built-in)")
    s.add_argument("--index", type=int, default=0,
                   help="which demonstration of the pair; without --pair, which row")  # fmt: skip
    s.add_argument("--out", type=Path, required=True, help="output dataset directory (*.lance)")
    s.add_argument(
        "--object", default=None, help="simulate another catalogue object (cube2h for a cube2 demo)"
    )
    s.add_argument("--no-plot", action="store_true", help="skip the per-finger force PNG")
    add_allow_implausible(s)
    add_object_options(s)
    _add_tracker_args(s)

    s = sub.add_parser(
        "synthesize", help="expand a dataset with perturbed, physically tracked rollouts"
    )
    s.add_argument("--dataset", type=Path, required=True, help="source Lance dataset")
    s.add_argument("--expand", type=int, default=10, help="rollouts per source row")
    s.add_argument("--out", type=Path, required=True, help="output dataset directory (*.lance)")
    s.add_argument("--workers", type=int, default=1, help="processes")
    s.add_argument("--limit", type=int, default=None, help="only the first N source rows")
    add_allow_implausible(s)
    from dexcanvas_core.sim.synthesis import PerturbationRanges  # lazy: mujoco ~0.5 s on --help

    d = PerturbationRanges()
    g = s.add_argument_group("perturbation half-widths (uniform, relative unless noted)")
    g.add_argument("--size", type=float, default=d.size, help="object size (default ±20 %%)")
    g.add_argument("--mass", type=float, default=d.mass)
    g.add_argument("--friction", type=float, default=d.friction)
    g.add_argument("--hand-scale", type=float, default=d.hand, help="hand skeleton scale")
    g.add_argument("--shift", type=float, default=d.shift_m, help="rigid table shift [m]")
    g.add_argument("--yaw-deg", type=float, default=float(np.rad2deg(d.yaw_rad)),
                   help="rigid yaw [deg]")  # fmt: skip
    g.add_argument("--object-offset", type=float, default=d.object_offset_m,
                   help="object-only offset from the hand [m]")  # fmt: skip
    g.add_argument("--object-offset-yaw-deg", type=float,
                   default=float(np.rad2deg(d.object_offset_yaw_rad)))  # fmt: skip
    add_object_options(s)
    _add_tracker_args(s)

    add_import_parser(sub)
    add_allow_implausible(sub.choices["import"])

    s = sub.add_parser("example", help="write the built-in synthetic example dataset")
    s.add_argument("--out", type=Path, required=True, help="output dataset directory (*.lance)")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--overwrite", action="store_true", help="replace an existing dataset")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(message)s"
    )

    def run() -> int:
        if args.command != "import":  # import reads its --objects for masses only
            use_object_options(args)
        if args.command == "info":
            run_info(InfoConfig(args.path, args.json))
        elif args.command == "validate":
            return EXIT_FAILED if run_validate(ValidateConfig(args.path)) else EXIT_OK
        elif args.command == "export":
            run_export(
                ExportConfig(
                    args.path,
                    args.out,
                    tuple(args.objects),
                    tuple(args.types),
                    tuple(args.operators),
                    args.overwrite,
                )
            )
        elif args.command == "demos":
            return EXIT_FAILED if run_demos_build_command(args) else EXIT_OK
        elif args.command == "fit":
            run_fit_command(args)
        elif args.command == "simulate":
            m = run_simulate_command(args)
            return EXIT_OK if m["success"] else EXIT_FAILED
        elif args.command == "synthesize":
            run_synthesize_command(args)
        elif args.command == "import":
            run_import_command(args)
        elif args.command == "example":
            run_example(ExampleConfig(args.out, args.seed, args.overwrite))
        return EXIT_OK

    def run_checked() -> int:
        with allowing_implausible(getattr(args, "allow_implausible", False)):
            return run()

    return run_command("dexcanvas", args.command, run_checked)


if __name__ == "__main__":
    sys.exit(main())
