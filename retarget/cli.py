"""``retarget``: the command line of the robot side.

A thin layer: each sub-command parses into a frozen config dataclass and calls one ``run_*``
function that library users can call too. Sub-commands are entries of ``COMMANDS``: a new one
(``run``, ``validate``, …) adds its arguments and config in :mod:`retarget.cli_args`, the
function running it in :mod:`retarget.cli_commands`, and one ``Command`` entry. The configs'
modules are imported inside the functions that make them, for start-up time (``retarget --help``
needs none of them).
Errors of the toolkit are printed as one line, ``retarget <command>: error: <message>``, and give
exit code 2.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Callable
from dataclasses import dataclass

from dexcanvas_core.cli_help import EXIT_CODES_EPILOG, HelpFormatter, examples_epilog
from dexcanvas_core.errors import DexCanvasError
from dexcanvas_core.exits import EXIT_FAILED, EXIT_OK, run_command
from dexcanvas_core.objects.options import add_object_options, use_object_options
from dexcanvas_core.plausibility import allowing_implausible
from retarget import __version__
from retarget.cli_args import (
    _add_calibrate_args,
    _add_export_args,
    _add_hands_args,
    _add_keypoints_args,
    _add_report_args,
    _add_run_args,
    _add_snapshot_args,
    _calibrate_config,
    _export_config,
    _hands_config,
    _keypoints_config,
    _report_config,
    _run_config,
    _snapshot_config,
)
from retarget.cli_batch import (
    BATCH_DESCRIPTION,
    BATCH_EXAMPLES,
    BATCH_HELP,
    add_batch_args,
    batch_config,
    batch_exit_code,
    run_batch_command,
)
from retarget.cli_commands import (
    cmd_calibrate,
    cmd_export,
    cmd_keypoints,
    cmd_report,
    cmd_run,
    cmd_snapshot,
    run_hands,
)
from retarget.errors import RetargetError

# ---------------------------------------------------------------------------- command table


@dataclass(frozen=True)
class Command:
    """One sub-command: its help, its arguments, how they become a config, what runs it."""

    help: str
    """One line, in the list of ``retarget --help``."""
    description: str
    """What the command does, at the top of its ``--help`` (line breaks kept)."""
    examples: tuple[str, ...]
    """One to three example invocations, the epilog of its ``--help``."""
    add_arguments: Callable[[argparse.ArgumentParser], None]
    make_config: Callable[[argparse.Namespace], object]
    run: Callable[[object], object]
    exit_code: Callable[[object], int] = lambda result: 0


COMMANDS: dict[str, Command] = {
    "run": Command(
        help="retarget a demonstration onto a robot hand, re-simulate it, write metrics",
        description="Retarget one human demonstration onto a robot hand, re-simulate the "
        "robot in MuJoCo and write\nrobot_trajectory.npz, metrics.json and a summary into the "
        "output directory.\nExit 3 when the re-simulated robot loses the object.",
        examples=(
            "retarget run --hand shadow --pair cube2/tripod",
            "retarget run --hand allegro --pair cube2/tripod --forces --out runs/allegro_forces",
            "retarget run --hand leap --dataset real.lance --index 3 --snapshot",
        ),
        add_arguments=_add_run_args,
        make_config=_run_config,
        run=cmd_run,
        exit_code=lambda m: EXIT_OK if m["success"] or m.get("success_refined") else EXIT_FAILED,
    ),
    "batch": Command(
        help=BATCH_HELP,
        description=BATCH_DESCRIPTION,
        examples=BATCH_EXAMPLES,
        add_arguments=add_batch_args,
        make_config=batch_config,
        run=run_batch_command,
        exit_code=batch_exit_code,
    ),
    "hands": Command(
        help="list the robot hands: DoF, actuators, finger mapping, model source",
        description="List the registered robot hands (the values of --hand): degrees of "
        "freedom, actuators,\ncouplings, which robot finger each human finger drives, size "
        "and model source.",
        examples=("retarget hands", "retarget hands --json"),
        add_arguments=_add_hands_args,
        make_config=_hands_config,
        run=run_hands,
    ),
    "keypoints": Command(
        help="retarget a bare 21-keypoint sequence (video or teleoperation; no object)",
        description="Retarget a bare sequence of 21 hand keypoints (from video or "
        "teleoperation; no object)\nonto a robot hand and write the joint trajectory.",
        examples=(
            "retarget keypoints --hand leap --input hand.npy --fps 30 --out runs/video",
            "retarget keypoints --hand shadow --input kp.csv --fps 120 --units mm "
            "--order openpose21 --out runs/kp",
        ),
        add_arguments=_add_keypoints_args,
        make_config=_keypoints_config,
        run=cmd_keypoints,
    ),
    "calibrate-wrist": Command(
        help="measure a hand's wrist offset from the human wrist (for HandModel.wrist_offset)",
        description="Measure a robot hand's wrist offset from the human wrist on generated "
        "demonstrations,\nthe value for HandModel.wrist_offset in its hands/ file.",
        examples=(
            "retarget calibrate-wrist --hand leap",
            "retarget calibrate-wrist --hand shadow --pairs 4 --max-frames 0 --json",
        ),
        add_arguments=_add_calibrate_args,
        make_config=_calibrate_config,
        run=cmd_calibrate,
    ),
    "snapshot": Command(
        help="stills of chosen frames (headless Chromium or MuJoCo) and the scene as HTML",
        description="Draw stills of chosen frames of a run (an existing run directory, or "
        "--hand and --pair run now)\nwith headless Chromium or MuJoCo, and the animated scene "
        "as one HTML file.",
        examples=(
            "retarget snapshot --run runs/shadow_cube2_tripod_0 --out stills",
            "retarget snapshot --hand shadow --pair cube2/tripod --frames 0,60,120 --out stills",
        ),
        add_arguments=_add_snapshot_args,
        make_config=_snapshot_config,
        run=cmd_snapshot,
    ),
    "report": Command(
        help="one offline HTML page of runs: metrics, stills, force and error plots, heatmap",
        description="One self-contained HTML page of one or more runs: metrics, stills, force "
        "and error plots,\ncontact heatmap. Renders stills for runs without them.",
        examples=(
            "retarget report runs/shadow_cube2_tripod_0",
            "retarget report runs/* --out report.html --no-snapshots",
        ),
        add_arguments=_add_report_args,
        make_config=_report_config,
        run=cmd_report,
    ),
    "export": Command(
        help="a run as a MuJoCo scene with keyframes, robomimic HDF5 or a LeRobot v3 dataset",
        description="Write a run (retarget run) in a format robot-learning code loads "
        "directly: a self-contained\nMuJoCo scene with one keyframe per frame, a "
        "robomimic-style HDF5 file, or a LeRobot v3.0\ndataset (state = the re-simulated "
        "joints q_sim, action = the servo commands q_command).",
        examples=(
            "retarget export runs/shadow_cube2_tripod_0 --format mujoco --out exports/mj",
            "retarget export runs/shadow_cube2_tripod_0 --format robomimic --out demo.hdf5",
            "retarget export --dataset B.lance --row 0 --format lerobot --out exports/lerobot",
        ),
        add_arguments=_add_export_args,
        make_config=_export_config,
        run=cmd_export,
    ),
}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="retarget",
        description="Retarget DexCanvas human demonstrations onto robot hands.",
        epilog=examples_epilog(
            "retarget hands",
            "retarget run --hand shadow --pair cube2/tripod",
            "retarget COMMAND --help     # each command's options and examples",
        )
        + "\n\n"
        + EXIT_CODES_EPILOG,
        formatter_class=HelpFormatter,
    )
    p.add_argument("--version", action="version", version=f"dexcanvas-retarget {__version__}")
    p.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    for name, cmd in COMMANDS.items():
        s = sub.add_parser(
            name,
            help=cmd.help,
            description=cmd.description,
            epilog=examples_epilog(*cmd.examples),
            formatter_class=HelpFormatter,
        )
        cmd.add_arguments(s)
        if name in SCENE_COMMANDS:
            add_object_options(s)
    return p


SCENE_COMMANDS = ("run", "snapshot", "report", "calibrate-wrist")
"""Sub-commands that build object scenes: they take ``--objects`` and ``--objects-dir``."""


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(message)s"
    )
    cmd = COMMANDS[args.command]

    def run() -> int:
        use_object_options(args)
        with allowing_implausible(getattr(args, "allow_implausible", False)):
            return cmd.exit_code(cmd.run(cmd.make_config(args)))

    return run_command("retarget", args.command, run, (RetargetError, DexCanvasError))


if __name__ == "__main__":
    sys.exit(main())
