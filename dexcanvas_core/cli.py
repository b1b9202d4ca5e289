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
from dexcanvas_core.builtin import default_dataset_path, rebuild_builtin
from dexcanvas_core.cache import cache_dir, cache_entries, clear_cache, clearable_entries
from dexcanvas_core.capture.cli import add_import_parser, run_import_command
from dexcanvas_core.checks import check_bool, check_int, check_path, check_str_seq
from dexcanvas_core.cli_help import (
    BUILTIN,
    EXIT_CODES_EPILOG,
    HelpFormatter,
    add_dataset_option,
    add_legacy_dataset_positional,
    dataset_from_args,
    examples_epilog,
)
from dexcanvas_core.demos import BuildConfig, run_build
from dexcanvas_core.errors import DatasetError, DexCanvasError, ValidationError
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

    return run_simulate(
        SimulateConfig(
            pair=args.pair,
            out=args.out,
            dataset=None if args.dataset == BUILTIN else args.dataset,
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


def _add_tracker_args(s: argparse.ArgumentParser) -> None:
    s.add_argument("--tracker", choices=["mpc", "open_loop"], default="mpc",
                   help="sampling MPC (default) or the reference replayed open loop")  # fmt: skip
    s.add_argument("--samples", type=int, default=16, help="MPC samples per replan")
    s.add_argument("--seed", type=int, default=0, help="seed of the MPC's sampling")
    s.add_argument("--overwrite", action="store_true", help="replace an existing output")


def _command(sub, name: str, help: str, description: str, *examples: str):
    """A sub-command parser with its one-line help, a description and an examples epilog."""
    return sub.add_parser(
        name,
        help=help,
        description=description,
        epilog=examples_epilog(*examples),
        formatter_class=HelpFormatter,
    )


def _add_dataset_reading(s: argparse.ArgumentParser) -> None:
    """``--dataset`` of a command that reads a whole dataset, with the deprecated positional."""
    add_dataset_option(s, note="required; the whole built-in set is built on first use")
    add_legacy_dataset_positional(s)


def build_parser() -> argparse.ArgumentParser:
    import numpy as np

    p = argparse.ArgumentParser(
        prog="dexcanvas",
        description="DexCanvas human demonstrations: inspect, validate, export, build examples, "
        "fit mocap, simulate forces, synthesize, import captures, manage the cache.",
        epilog=examples_epilog(
            "dexcanvas info --dataset builtin",
            "dexcanvas simulate --pair cube2/tripod --out sim.lance",
            "dexcanvas COMMAND --help     # each command's options and examples",
        )
        + "\n\n"
        + EXIT_CODES_EPILOG,
        formatter_class=HelpFormatter,
    )
    p.add_argument("--version", action="version", version=f"dexcanvas-retarget {__version__}")
    p.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    s = _command(
        sub, "info", "summarise a Lance dataset (rows, pairs, operators, frames, fps, size)",
        "Summarise a DexCanvas-layout Lance dataset: rows, (object, manipulation type) pairs, "
        "operators, frames,\nframe rates, contacts, size on disk and schema version. Reads the "
        "metadata only.",
        "dexcanvas info --dataset builtin",
        "dexcanvas info --dataset ex.lance --json",
    )  # fmt: skip
    _add_dataset_reading(s)
    s.add_argument("--json", action="store_true", help="print JSON instead of tables")

    s = _command(
        sub, "validate", "check every row of a dataset (shapes, NaNs, rotations, fps)",
        "Read every row of a dataset with full validation (shapes, finiteness, rotations, "
        "timestamps, fps)\nand print the first problem of each bad row. Exit 3 when a row is "
        "invalid.",
        "dexcanvas validate --dataset ex.lance",
        "dexcanvas validate --dataset builtin",
    )  # fmt: skip
    _add_dataset_reading(s)
    add_allow_implausible(s)

    s = _command(
        sub, "export", "export a dataset (optionally filtered) to Parquet",
        "Export a dataset's rows to one Parquet file, optionally only some objects, "
        "manipulation types\nor operators (each filter: one or more values).",
        "dexcanvas export --dataset ex.lance --parquet ex.parquet",
        "dexcanvas export --dataset builtin --parquet cubes.parquet --objects cube2 cube2h",
    )  # fmt: skip
    _add_dataset_reading(s)
    s.add_argument("--parquet", type=Path, required=True, dest="out", help="output .parquet file")
    s.add_argument("--objects", nargs="*", default=[],
                   help="only these object ids, e.g. cube2 sphere1 (default: all)")  # fmt: skip
    s.add_argument("--types", nargs="*", default=[],
                   help="only these manipulation types, names or codes (default: all)")  # fmt: skip
    s.add_argument("--operators", nargs="*", default=[],
                   help="only these operators (default: all)")  # fmt: skip
    s.add_argument("--overwrite", action="store_true", help="replace an existing --parquet file")
    add_allow_implausible(s)

    s = _command(
        sub, "demos", "generated human demonstrations",
        "Generated human demonstrations (the generator behind the built-in set).",
        "dexcanvas demos build --out demos.lance --pairs cube2/tripod --reps 3",
    )  # fmt: skip
    demos_sub = s.add_subparsers(dest="demos_command", required=True, metavar="SUBCOMMAND")
    b = _command(
        demos_sub, "build", "generate demonstrations into a Lance dataset",
        "Generate demonstrations of (object, manipulation type) pairs into a Lance dataset; "
        "every one\npasses the plausibility checks or is reported as failed (exit 3).",
        "dexcanvas demos build --out demos.lance",
        "dexcanvas demos build --out two.lance --pairs cube2/tripod sphere1/power_sphere "
        "--reps 2 --workers 2",
    )  # fmt: skip
    b.add_argument("--out", type=Path, required=True, help="output dataset directory (*.lance)")
    b.add_argument(
        "--pairs", nargs="*", default=None, help="OBJECT/TYPE pairs (default: every feasible pair)"
    )
    b.add_argument("--reps", type=int, default=1, help="demonstrations per pair")
    b.add_argument("--seed", type=int, default=0, help="generator seed")
    b.add_argument("--workers", type=int, default=1, help="generator processes")
    b.add_argument("--overwrite", action="store_true", help="replace an existing dataset")
    add_object_options(b)

    s = _command(
        sub, "fit", "fit MANO hand + object poses to mocap markers (C3D or CSV)",
        "Fit the MANO hand and the object's pose to motion-capture markers (C3D or CSV) and "
        "write a\ndataset with per-frame quality flags; prints the fit report as JSON.",
        "dexcanvas fit grasp.c3d --out grasp.lance --object cube2",
        "dexcanvas fit grasp.csv --out grasp.lance --units mm --fps 100 --mapping names.json",
    )  # fmt: skip
    s.add_argument("markers", type=Path, help="marker file (.c3d or .csv)")
    s.add_argument("--out", type=Path, required=True, help="output dataset directory (*.lance)")
    s.add_argument("--format", choices=["auto", "c3d", "csv"], default="auto",
                   help="marker file format (auto: from the suffix)")  # fmt: skip
    s.add_argument("--mapping", type=Path, default=None, help="marker-name mapping (JSON or CSV)")
    s.add_argument("--object", default=None, help="catalogue object id carrying obj1..obj4")
    s.add_argument("--fps", type=float, default=None, help="frame rate [Hz] (default: the file's)")
    s.add_argument("--units", default=None,
                   help="length unit of the file: mm, cm or m (default: the file's)")  # fmt: skip
    s.add_argument("--up", choices=["y", "z"], default="y", help="vertical axis of the mocap frame")
    s.add_argument("--side", choices=["right", "left"], default=None,
                   help="hand side (default: from the marker names)")  # fmt: skip
    s.add_argument("--calibration", type=Path, default=None,
                   help="saved subject calibration to reuse (default: calibrate now)")  # fmt: skip
    s.add_argument("--save-calibration", type=Path, default=None, metavar="PATH",
                   help="write the subject calibration to PATH")  # fmt: skip
    s.add_argument("--overwrite", action="store_true", help="replace an existing output")
    add_allow_implausible(s)

    s = _command(
        sub, "simulate",
        "track a demonstration with the simulated MANO hand; write contacts and forces",
        "Track one demonstration with the simulated MANO hand (sampling MPC or open loop) and "
        "write it\nwith its contacts and contact forces, plus a per-finger force plot. Exit 3 "
        "when the hand loses the object.",
        "dexcanvas simulate --pair cube2/tripod --out sim.lance",
        "dexcanvas simulate --dataset real.lance --index 2 --out sim.lance --samples 32",
    )  # fmt: skip
    s.add_argument("--pair", default=None,
                   help="OBJECT/TYPE, e.g. cube2/tripod (optional with --dataset)")  # fmt: skip
    add_dataset_option(s)
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

    s = _command(
        sub, "synthesize", "expand a dataset with perturbed, physically tracked rollouts",
        "Expand a dataset with perturbed copies of each row (object size, mass, friction, hand "
        "scale,\nplacement), each tracked in physics; only the rollouts that keep the object are "
        "kept.\nAn interrupted run resumes where it stopped.",
        "dexcanvas synthesize --dataset builtin --out synth.lance --expand 4 --limit 2",
        "dexcanvas synthesize --dataset real.lance --out synth.lance --workers 2 --size 0.1",
    )  # fmt: skip
    add_dataset_option(s, required=True, what="source Lance dataset")
    s.add_argument("--expand", type=int, default=10, help="rollouts per source row")
    s.add_argument("--out", type=Path, required=True, help="output dataset directory (*.lance)")
    s.add_argument("--workers", type=int, default=1, help="processes")
    s.add_argument("--ray-address", default=None, metavar="auto|HOST:PORT|local",
                   help="run the source rows as Ray tasks on that cluster ('local': a private "
                   "local Ray on 127.0.0.1; default: local processes)")  # fmt: skip
    s.add_argument("--limit", type=int, default=None,
                   help="only the first N source rows (default: all)")  # fmt: skip
    add_allow_implausible(s)
    from dexcanvas_core.sim.synthesis import PerturbationRanges  # lazy: mujoco ~0.5 s on --help

    d = PerturbationRanges()
    g = s.add_argument_group("perturbation half-widths (uniform, relative unless noted)")
    g.add_argument("--size", type=float, default=d.size, help="object size")
    g.add_argument("--mass", type=float, default=d.mass, help="object mass")
    g.add_argument("--friction", type=float, default=d.friction, help="object friction")
    g.add_argument("--hand-scale", type=float, default=d.hand, help="hand skeleton scale")
    g.add_argument("--shift", type=float, default=d.shift_m, help="rigid table shift [m]")
    g.add_argument("--yaw-deg", type=float, default=float(np.rad2deg(d.yaw_rad)),
                   help="rigid yaw [deg]")  # fmt: skip
    g.add_argument("--object-offset", type=float, default=d.object_offset_m,
                   help="object-only offset from the hand [m]")  # fmt: skip
    g.add_argument("--object-offset-yaw-deg", type=float,
                   default=float(np.rad2deg(d.object_offset_yaw_rad)),
                   help="object-only yaw about the hand [deg]")  # fmt: skip
    add_object_options(s)
    _add_tracker_args(s)

    add_import_parser(sub)
    add_allow_implausible(sub.choices["import"])

    s = _command(
        sub, "example", "write the built-in synthetic example dataset",
        "Write the small synthetic example dataset (public layout: 6 pairs x 3 operators) to "
        "OUT;\nquick to build, for trying the other commands.",
        "dexcanvas example --out ex.lance",
        "dexcanvas example --out ex.lance --seed 1 --overwrite",
    )  # fmt: skip
    s.add_argument("--out", type=Path, required=True, help="output dataset directory (*.lance)")
    s.add_argument("--seed", type=int, default=0, help="generator seed")
    s.add_argument("--overwrite", action="store_true", help="replace an existing dataset")

    _add_cache_parser(sub)
    return p


def _add_cache_parser(sub) -> None:
    s = _command(
        sub, "cache", "the cache of built-in demonstrations and object shapes: path, clear, "
        "rebuild",
        "The cache directory ($DEXCANVAS_CACHE_DIR, else the platform's user cache) holds the "
        "built-in\ndemonstrations (built on first use), object collision shapes and the "
        "tracebacks of internal errors.",
        "dexcanvas cache path",
        "dexcanvas cache rebuild --pairs cube2/tripod",
        "dexcanvas cache clear --yes",
    )  # fmt: skip
    cache_sub = s.add_subparsers(dest="cache_command", required=True, metavar="SUBCOMMAND")
    _command(
        cache_sub, "path", "print the cache directory and what it holds",
        "Print the cache directory, then one line per entry: its size and what it is.",
        "dexcanvas cache path",
        'du -sh "$(dexcanvas cache path | head -1)"',
    )  # fmt: skip
    c = _command(
        cache_sub, "clear", "remove the built-in demonstrations and object shapes",
        "Remove the built-in demonstrations and the object collision shapes from the cache "
        "(rebuilt on\nnext use; tracebacks stay). Asks first, unless --yes; without a terminal "
        "--yes is required.",
        "dexcanvas cache clear",
        "dexcanvas cache clear --yes",
    )  # fmt: skip
    c.add_argument("--yes", action="store_true", help="do not ask for confirmation")
    r = _command(
        cache_sub, "rebuild", "build the built-in demonstrations again (a corrupt cache too)",
        "Build the built-in demonstrations again, replacing what the cache holds (the repair for "
        "a corrupt\nor partial cache), with a progress bar. --pairs: only these pairs' own "
        "caches (seconds each).",
        "dexcanvas cache rebuild",
        "dexcanvas cache rebuild --pairs cube2/tripod sphere1/power_sphere",
    )  # fmt: skip
    r.add_argument("--pairs", nargs="+", default=None, metavar="OBJECT/TYPE",
                   help="only these pairs (default: the whole built-in set)")  # fmt: skip
    r.add_argument("--workers", type=int, default=None,
                   help="processes building the whole set (default: the CPU count)")  # fmt: skip


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
