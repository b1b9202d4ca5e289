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

from dexcanvas_core.builtin import default_dataset_path, rebuild_builtin
from dexcanvas_core.cache import cache_dir, cache_entries, clear_cache, clearable_entries
from dexcanvas_core.capture.cli import run_import_command
from dexcanvas_core.checks import check_bool, check_int, check_path, check_str_seq
from dexcanvas_core.cli_help import BUILTIN, dataset_from_args
from dexcanvas_core.cli_parser import build_parser
from dexcanvas_core.demos import BuildConfig, run_build
from dexcanvas_core.errors import DatasetError, DexCanvasError, ValidationError
from dexcanvas_core.example import build_example_dataset
from dexcanvas_core.exits import EXIT_FAILED, EXIT_OK, run_command
from dexcanvas_core.io import export_parquet, open_dataset
from dexcanvas_core.io.decode import row_to_trajectory
from dexcanvas_core.loaders.selection import select_rows
from dexcanvas_core.objects.options import use_object_options
from dexcanvas_core.plausibility import allowing_implausible, check_fps
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
    """``dexcanvas info``: which dataset to summarise, and how."""

    path: Path
    """The Lance dataset (``str`` or ``Path``)."""
    as_json: bool = False
    """Print JSON instead of tables."""

    def __post_init__(self) -> None:
        check_path("path", self.path)
        check_bool("as_json", self.as_json)


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
    """``dexcanvas validate``: the dataset whose every row is checked."""

    path: Path
    """The Lance dataset (``str`` or ``Path``)."""

    def __post_init__(self) -> None:
        check_path("path", self.path)


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
    """``dexcanvas export``: a dataset, the Parquet file to write and the optional filters."""

    path: Path
    """The Lance dataset (``str`` or ``Path``)."""
    out: Path
    """The ``.parquet`` file written."""
    objects: tuple[str, ...] = ()
    """Only these object ids (empty: all)."""
    manipulation_types: tuple[str, ...] = ()
    """Only these manipulation types, names or codes (empty: all)."""
    operators: tuple[str, ...] = ()
    """Only these operators (empty: all)."""

    overwrite: bool = False
    """Replace an existing Parquet file; without it one is refused before any work."""

    def __post_init__(self) -> None:
        check_path("path", self.path)
        check_path("out", self.out)
        check_str_seq("objects", self.objects, optional=False)
        check_str_seq("manipulation_types", self.manipulation_types, optional=False, codes=True)
        check_str_seq("operators", self.operators, optional=False)
        check_bool("overwrite", self.overwrite)


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
    """``dexcanvas example``: where to write the example dataset."""

    out: Path
    """Output dataset directory (``*.lance``)."""
    seed: int = 0
    """Generator seed."""
    overwrite: bool = False
    """Replace an existing dataset at ``out``."""

    def __post_init__(self) -> None:
        check_path("out", self.out)
        check_int("seed", self.seed, min=0)
        check_bool("overwrite", self.overwrite)


def run_example(cfg: ExampleConfig) -> Path:
    """Write the built-in example dataset (synthetic, public layout) to ``cfg.out``."""
    out = build_example_dataset(cfg.out, seed=cfg.seed, overwrite=cfg.overwrite, progress=True)
    print(f"wrote {out}")
    return out


def read_dataset_path(value: Path | str) -> Path:
    """The dataset a reading command opens: ``--dataset builtin`` is the whole built-in set
    (built on first use, with progress), a path is itself."""
    return default_dataset_path(progress=True) if value == BUILTIN else Path(value)


def run_cache_path() -> Path:
    """``dexcanvas cache path``: the cache directory, then each entry's size and kind."""
    root = cache_dir()
    print(root)
    entries = cache_entries(root)
    if not entries:
        print("  (empty)" if root.is_dir() else "  (not created yet)")
    for path, kind, size in entries:
        print(f"  {_human_bytes(size):>10}  {path.name}  ({kind})")
    return root


def run_cache_clear(yes: bool) -> int:
    """``dexcanvas cache clear``: remove the built-in demonstrations and object shapes after a
    confirmation (``yes``: without); the exit code."""
    root = cache_dir()
    entries = clearable_entries(root)
    if not entries:
        print(f"nothing to clear in {root}")
        return EXIT_OK
    total = _human_bytes(sum(size for _, _, size in entries))
    if not yes:
        if not sys.stdin.isatty():
            raise ValidationError(
                f"would remove {len(entries)} entries ({total}) from {root}; no terminal to "
                "confirm: pass --yes"
            )
        for path, kind, size in entries:
            print(f"  {_human_bytes(size):>10}  {path.name}  ({kind})")
        answer = input(f"remove these {len(entries)} entries ({total}) from {root}? [y/N] ")
        if answer.strip().lower() not in ("y", "yes"):
            print("nothing removed")
            return EXIT_OK
    removed = clear_cache(root)
    print(f"removed {len(removed)} entries ({total}) from {root}")
    return EXIT_OK


def run_cache_rebuild(pairs: list[str] | None, workers: int | None) -> list[Path]:
    """``dexcanvas cache rebuild``: the built-in set (or ``pairs``' own caches) built again."""
    if workers is not None:
        check_int("--workers", workers, min=1)
    built = rebuild_builtin(pairs, progress=True, workers=workers)
    for path in built:
        print(f"built {path}")
    return built


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

    all_rows = args.all_rows
    if all_rows and args.dataset == BUILTIN:
        dataset = read_dataset_path(BUILTIN)  # --all of the built-in set: the whole set
    else:
        dataset = None if args.dataset == BUILTIN else args.dataset
    return run_simulate(
        SimulateConfig(
            pair=args.pair,
            out=args.out,
            dataset=dataset,
            index=args.index,
            sim=_sim_config(args),
            overwrite=args.overwrite,
            plot=not args.no_plot,
            all_rows=all_rows,
            limit=args.limit,
            workers=args.workers,
            ray_address=args.ray_address,
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
            dataset=read_dataset_path(args.dataset),
            out=args.out,
            expand=args.expand,
            seed=args.seed,
            workers=args.workers,
            ray_address=args.ray_address,
            sim=_sim_config(args),
            limit=args.limit,
            overwrite=args.overwrite,
            ranges=ranges,
        )
    )


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(message)s"
    )

    def run() -> int:
        if args.command not in ("import", "cache"):  # import reads its --objects for masses
            use_object_options(args)
        if args.command == "info":
            run_info(InfoConfig(read_dataset_path(dataset_from_args(args)), args.json))
        elif args.command == "validate":
            cfg = ValidateConfig(read_dataset_path(dataset_from_args(args)))
            return EXIT_FAILED if run_validate(cfg) else EXIT_OK
        elif args.command == "export":
            run_export(
                ExportConfig(
                    read_dataset_path(dataset_from_args(args)),
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
        elif args.command == "cache":
            if args.cache_command == "path":
                run_cache_path()
            elif args.cache_command == "clear":
                return run_cache_clear(args.yes)
            else:
                run_cache_rebuild(args.pairs, args.workers)
        return EXIT_OK

    def run_checked() -> int:
        with allowing_implausible(getattr(args, "allow_implausible", False)):
            return run()

    return run_command("dexcanvas", args.command, run_checked)


if __name__ == "__main__":
    sys.exit(main())
