"""The arguments of the ``retarget`` sub-commands and the configs they parse into.

Each sub-command of :data:`retarget.cli.COMMANDS` has here its ``_add_*_args`` (the options of
its parser) and its ``_*_config`` (the parsed arguments as a frozen config). The configs' modules
are imported inside the functions that make them, for start-up time (``retarget --help`` needs
none of them).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from dexcanvas_core.cli_help import BUILTIN, add_dataset_option
from dexcanvas_core.plausibility import add_allow_implausible, check_fps
from retarget.cli_commands import HandsConfig, RunAndSnapshotConfig
from retarget.overrides import parse_override

# ---------------------------------------------------------------------------- retarget hands


def _add_hands_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")


def _hands_config(args: argparse.Namespace) -> HandsConfig:
    return HandsConfig(as_json=args.json)


# ---------------------------------------------------------------------------- retarget run


def _non_negative_int(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = -1
    if n < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}")
    return n


def _positive_float(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        x = float("nan")
    if not (math.isfinite(x) and x > 0):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
    return x


def _positive_int(text: str) -> int:
    n = _non_negative_int(text)
    if n == 0:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}")
    return n


def _add_run_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--hand", required=True, help="robot hand (see `retarget hands`)")
    p.add_argument(
        "--pair", default=None,
        help="OBJECT/TYPE, e.g. cube2/tripod (with --dataset: optional, the row --index is used)",
    )  # fmt: skip
    add_dataset_option(p)
    p.add_argument("--index", type=int, default=0, help="which demonstration of the pair")
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="output directory (default runs/<hand>_<object>_<type>_<index>)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the run already in --out (metrics.json, robot_trajectory.npz)",
    )
    p.add_argument(
        "--backend", choices=["pinocchio", "mink"], default="pinocchio", help="IK backend"
    )
    p.add_argument(
        "--forces",
        action="store_true",
        help="force matching: press like the human (runs the force pipeline first if needed)",
    )
    p.add_argument(
        "--force-scale",
        type=_positive_float,
        default=1.0,
        metavar="X",
        help="with --forces: press with X times the human's forces (a grip margin; default 1)",
    )
    p.add_argument(
        "--time-scale",
        default=1.0,  # RunConfig.time_scale, which checks the text (one-line errors)
        metavar="S",
        help="execute the demonstration S times slower (1 to 10; its timestamps stretched, "
        "frames unchanged), for arms that cannot follow a human wrist at full speed; "
        "recorded in metrics.json (default 1)",
    )
    p.add_argument(
        "--human-replay",
        action="store_true",
        help="with --forces: simulate the human again with another MPC seed and score its "
        "forces like the robot's (the force correlation's ceiling)",
    )
    p.add_argument(
        "--refine",
        action="store_true",
        help="if the re-simulation fails, refine the commands by sampling MPC on the robot",
    )
    p.add_argument(
        "--calibrate-iterations",
        type=_non_negative_int,
        default=10,  # RunConfig.calibrate_iterations
        metavar="N",
        help="with --forces: re-simulations correcting the commands until the fingers press "
        "like the human's (force calibration; default 10; 0: the planned commands)",
    )
    p.add_argument(
        "--refine-retries",
        type=_non_negative_int,
        default=4,  # RunConfig.refine_retries (retarget.run is imported only to run)
        metavar="N",
        help="times the refinement backtracks 0.5 s (× attempt) when it loses the object "
        "(default 4; 0: one attempt)",
    )
    p.add_argument(
        "--set",
        action="append",
        type=parse_override,
        metavar="NAME=VALUE",
        help="change a RetargetConfig field (repeatable), e.g. --set w_contacts=100 --set "
        "contact_tangent_weight=0.05; recorded in metrics.json (retarget_overrides)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars or summary")
    p.add_argument(
        "--snapshot",
        action="store_true",
        help="also write stills and scene.html of the run into its directory (retarget snapshot)",
    )
    p.add_argument(
        "--renderer",
        choices=["auto", "chromium", "mujoco"],
        default="auto",
        help="renderer of the --snapshot stills (default: Chromium if installed, else MuJoCo)",
    )
    add_allow_implausible(p)


def _dataset(value: Path | str | None) -> Path | None:
    """``--dataset``: ``builtin`` is the built-in demonstrations (``None`` in the configs)."""
    return None if value == BUILTIN else value


def _run_config(args: argparse.Namespace):
    cfg = _plain_run_config(args)
    if getattr(args, "snapshot", False):
        return RunAndSnapshotConfig(run=cfg, renderer=args.renderer)
    return cfg


def _plain_run_config(args: argparse.Namespace):
    # Lazy: start-up time of ``retarget --help`` (module docstring).
    from retarget.pipeline import RunConfig

    return RunConfig(
        hand=args.hand,
        pair=args.pair,
        dataset=_dataset(args.dataset),
        index=args.index,
        out=args.out,
        overwrite=args.overwrite,
        backend=args.backend,
        forces=args.forces,
        refine=args.refine,
        refine_retries=args.refine_retries,
        calibrate_iterations=args.calibrate_iterations,
        force_scale=args.force_scale,
        human_replay=args.human_replay,
        time_scale=args.time_scale,
        overrides=dict(args.set or ()),
        progress=not args.quiet,
    )


# ---------------------------------------------------------------------------- retarget snapshot


def _add_snapshot_args(p: argparse.ArgumentParser) -> None:
    src = p.add_argument_group("what to draw (--hand and --pair, or --run)")
    src.add_argument("--hand", default=None, help="robot hand (see `retarget hands`)")
    src.add_argument("--pair", default=None, help="OBJECT/TYPE, e.g. cube2/tripod")
    add_dataset_option(src)
    src.add_argument("--index", type=int, default=0, help="which demonstration of the pair")
    src.add_argument(
        "--run", type=Path, default=None, metavar="RUN_DIR", help="draw an existing run directory"
    )
    p.add_argument("--out", type=Path, required=True, help="output directory")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the stills (and, retargeting, the run) already in --out",
    )
    which = p.add_mutually_exclusive_group()
    which.add_argument("--frames", default=None, help="frames to draw, e.g. 0,60,120")
    which.add_argument("--every", type=int, default=None, metavar="N", help="every N-th frame")
    p.add_argument(
        "--renderer",
        choices=["auto", "chromium", "mujoco"],
        default="auto",
        help="headless Chromium (meshcat page) or MuJoCo offscreen; auto: Chromium if installed",
    )
    p.add_argument(
        "--layout",
        choices=["side_by_side", "overlay"],
        default="side_by_side",
        help="human and robot next to each other, or drawn over each other",
    )
    p.add_argument(
        "--robot",
        choices=["sim", "kinematic"],
        default="sim",
        help="draw the re-simulated hand (with its contacts) or the retargeted joint solution",
    )
    p.add_argument("--width", type=int, default=800, help="picture width [px]")
    p.add_argument("--height", type=int, default=600, help="picture height [px]")
    p.add_argument("--no-html", action="store_true", help="do not write scene.html")
    p.add_argument(
        "--backend", choices=["pinocchio", "mink"], default="pinocchio", help="IK backend"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars or summary")
    add_allow_implausible(p)


def _snapshot_config(args: argparse.Namespace):
    # Lazy: start-up time of ``retarget --help`` (module docstring).
    from retarget.viz.snapshot import SnapshotConfig, parse_frames

    return SnapshotConfig(
        out=args.out,
        hand=args.hand,
        pair=args.pair,
        dataset=_dataset(args.dataset),
        index=args.index,
        run_dir=args.run,
        frames=parse_frames(args.frames) if args.frames is not None else None,
        every=args.every,
        renderer=args.renderer,
        layout=args.layout,
        robot=args.robot,
        width=args.width,
        height=args.height,
        scene_html=not args.no_html,
        backend=args.backend,
        overwrite=args.overwrite,
        progress=not args.quiet,
    ).validate()


# ---------------------------------------------------------------------------- retarget report


def _add_report_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("run_dirs", nargs="+", type=Path, metavar="RUN_DIR", help="run directories")
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="HTML file (default RUN_DIR/report.html; several runs: in their common parent)",
    )
    p.add_argument(
        "--no-snapshots", action="store_true", help="do not render stills for runs without them"
    )
    p.add_argument(
        "--renderer",
        choices=["auto", "chromium", "mujoco"],
        default="auto",
        help="renderer of the missing stills (auto: Chromium if installed, else MuJoCo)",
    )
    p.add_argument(
        "--plot-format", choices=["png", "svg"], default="png", help="format of the plots"
    )
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out file")


def _report_config(args: argparse.Namespace):
    # Lazy: start-up time of ``retarget --help`` (module docstring).
    from retarget.viz.report import ReportConfig

    return ReportConfig(
        run_dirs=tuple(args.run_dirs),
        out=args.out,
        snapshots=not args.no_snapshots,
        renderer=args.renderer,
        plot_format=args.plot_format,
        overwrite=args.overwrite,
    ).validate()


def _add_keypoints_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--hand", required=True, help="registered hand (retarget hands)")
    p.add_argument(
        "--input",
        type=Path,
        required=True,
        help="(T, 21, 3) keypoints: .npy, .npz (key 'keypoints') or .csv (63 columns)",
    )
    p.add_argument(
        "--order",
        choices=["mano21", "openpose21"],
        default="mano21",
        help="keypoint order of the input",
    )
    p.add_argument(
        "--units", choices=["m", "cm", "mm"], default="m", help="length unit of the input"
    )
    p.add_argument("--fps", type=float, required=True, help="frame rate [Hz]")
    p.add_argument("--out", type=Path, required=True, help="output directory")  # fmt: skip
    p.add_argument(
        "--overwrite", action="store_true", help="replace the trajectory already in --out"
    )
    add_allow_implausible(p)


def _keypoints_config(args: argparse.Namespace):
    check_fps(args.fps)
    # Lazy: start-up time of ``retarget --help`` (module docstring).
    from retarget.keypoint_input import KeypointsConfig

    return KeypointsConfig(
        args.hand, args.input, args.fps, args.out, args.order, args.units, args.overwrite
    )


# ------------------------------------------------------------------ retarget calibrate-wrist
def _add_calibrate_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--hand", required=True, help="robot hand (see `retarget hands`)")
    p.add_argument("--pairs", type=_positive_int, default=8, help="generated demonstration pairs")
    p.add_argument("--operator", default="operator2", help="operator of the demonstrations")
    p.add_argument("--seed", type=_non_negative_int, default=1, help="demonstration seed")
    p.add_argument(
        "--max-frames", type=_non_negative_int, default=300,
        help="crop each demonstration to this many frames (0: whole)",
    )  # fmt: skip
    p.add_argument("--json", action="store_true", help="print the result as JSON")


def _calibrate_config(args: argparse.Namespace):
    # Lazy: start-up time of ``retarget --help`` (module docstring).
    from retarget.calibration import CalibrateConfig

    return CalibrateConfig(
        args.hand, args.pairs, args.operator, args.seed, args.max_frames or None, args.json
    )


# ---------------------------------------------------------------------------- retarget export

EXPORT_FORMATS = ("mujoco", "robomimic", "lerobot")
"""The values of ``retarget export --format`` (``retarget.export.FORMATS``; repeated here so
that ``retarget --help`` imports no MuJoCo, h5py or pyarrow)."""


def _add_export_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "run_dir", type=Path, metavar="RUN_DIR", nargs="?", default=None,
        help="run directory (retarget run); or give --dataset and --row",
    )  # fmt: skip
    p.add_argument(
        "--dataset", type=Path, default=None, metavar="B.lance",
        help="a robot dataset written by retarget batch, instead of RUN_DIR",
    )  # fmt: skip
    p.add_argument(
        "--row", type=_non_negative_int, default=None,
        help="with --dataset: the row to export (0-based, dataset order)",
    )  # fmt: skip
    p.add_argument(
        "--format",
        required=True,
        choices=EXPORT_FORMATS,
        help="mujoco: scene.xml (hand + object + table, a keyframe per frame), its meshes and "
        "trajectory.npz; robomimic: one HDF5 file; lerobot: a LeRobot v3.0 dataset directory",
    )
    p.add_argument(
        "--out",
        type=Path,
        required=True,
        help="output directory (mujoco, lerobot) or .hdf5 file (robomimic)",
    )
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out")


def _export_config(args: argparse.Namespace):
    # Lazy: start-up time of ``retarget --help`` (module docstring).
    from retarget.export import ExportConfig

    return ExportConfig(
        run_dir=args.run_dir, format=args.format, out=args.out, overwrite=args.overwrite,
        dataset=args.dataset, row=args.row,
    ).validate()  # fmt: skip
