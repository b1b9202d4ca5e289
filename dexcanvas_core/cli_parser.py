"""The ``dexcanvas`` argument parser: every sub-command's options, help and examples.

:func:`dexcanvas_core.cli.main` parses with :func:`build_parser` and runs the command.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from dexcanvas_core import __version__
from dexcanvas_core.capture.cli import add_import_parser
from dexcanvas_core.cli_help import (
    EXIT_CODES_EPILOG,
    HelpFormatter,
    add_dataset_option,
    add_legacy_dataset_positional,
    examples_epilog,
)
from dexcanvas_core.objects.options import add_object_options
from dexcanvas_core.plausibility import add_allow_implausible


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
        "dexcanvas simulate --dataset real.lance --all --workers 2 --out sim.lance",
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
    s.add_argument("--all", action="store_true", dest="all_rows",
                   help="track every row of --dataset (resumable; the rows that keep their "
                   "object are written, every row's metrics to OUT.report.json)")  # fmt: skip
    s.add_argument("--limit", type=int, default=None,
                   help="with --all: only the first N rows (default: all)")  # fmt: skip
    s.add_argument("--workers", type=int, default=1, help="with --all: local processes")
    s.add_argument("--ray-address", default=None, metavar="auto|HOST:PORT|local",
                   help="with --all: run the rows as Ray tasks on that cluster; local: a "
                   "private local Ray (default: the local processes)")  # fmt: skip
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
