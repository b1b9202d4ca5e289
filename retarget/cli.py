"""``retarget``: the command line of the robot side.

A thin layer: each sub-command parses into a frozen config dataclass and calls one ``run_*``
function that library users can call too. Sub-commands are entries of ``COMMANDS``: a new one
(``run``, ``validate``, …) adds its config, its ``run_*`` function and one ``Command`` entry.
Errors of the toolkit are printed as one line, ``retarget <command>: error: <message>``, and give
exit code 2.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from dexcanvas_core.errors import DexCanvasError
from retarget import __version__
from retarget.errors import RetargetError

# ---------------------------------------------------------------------------- retarget hands


@dataclass(frozen=True)
class HandsConfig:
    """``retarget hands``: list the registered robot hands."""

    as_json: bool = False
    """Print a JSON list (one object per hand) instead of a table."""


def _fingers_cell(fingers: dict) -> str:
    return ",".join(r or "–" for r in fingers.values())


def run_hands(cfg: HandsConfig) -> list[dict]:
    """Print every registered hand with its DoF, actuators, finger mapping and model source.

    Returns the rows (``retarget.hands.hands_table()``).
    """
    from retarget.hands import hands_table

    rows = hands_table()
    if cfg.as_json:
        print(json.dumps(rows, indent=2, sort_keys=True))
        return rows
    from rich import box
    from rich.console import Console
    from rich.table import Table

    t = Table(title="robot hands (--hand NAME)", box=box.SIMPLE_HEAD)
    t.add_column("hand", style="bold")
    t.add_column("DoF", justify="right")
    t.add_column("act.", justify="right")
    t.add_column("coupl.", justify="right")
    t.add_column("thumb,index,middle,ring,pinky →", no_wrap=True)
    t.add_column("scale", justify="right")
    t.add_column("source", no_wrap=True)
    t.add_column("licence")
    for r in rows:
        t.add_row(
            r["name"],
            f"{r['dof_wrist']}+{r['dof_fingers']}",
            f"{r['dof_wrist']}+{r['actuators_fingers']}",
            str(r["couplings"]),
            _fingers_cell(r["fingers"]),
            f"{r['scale']:.2f}",
            r["source"],
            r["licence"],
        )
    con = Console()
    if not con.is_terminal:  # piped: do not squeeze the table into 80 columns
        con = Console(width=120)
    con.print(t)
    con.print(
        "DoF, act.: 6 floating-wrist + the hand's joints / actuators; coupl.: tendon and "
        "equality couplings;\nfingers: the robot finger each human finger drives (– dropped); "
        "scale: robot/human hand size"
    )
    return rows


def _add_hands_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")


def _hands_config(args: argparse.Namespace) -> HandsConfig:
    return HandsConfig(as_json=args.json)


# ---------------------------------------------------------------------------- retarget run


def _add_run_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--hand", required=True, help="robot hand (see `retarget hands`)")
    p.add_argument("--pair", required=True, help="OBJECT/TYPE, e.g. cube2/tripod")
    p.add_argument(
        "--dataset",
        type=Path,
        default=None,
        help="DexCanvas Lance dataset (default: the built-in demonstrations)",
    )
    p.add_argument("--index", type=int, default=0, help="which demonstration of the pair")
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="output directory (default runs/<hand>_<object>_<type>_<index>)",
    )
    p.add_argument("--backend", choices=["pinocchio", "mink"], default="pinocchio")
    p.add_argument("--quiet", action="store_true", help="no progress bars or summary")


def _run_config(args: argparse.Namespace):
    from retarget.run import RunConfig

    return RunConfig(
        hand=args.hand,
        pair=args.pair,
        dataset=args.dataset,
        index=args.index,
        out=args.out,
        backend=args.backend,
        progress=not args.quiet,
    )


def _run(cfg) -> dict:
    from retarget.run import run_retarget

    return run_retarget(cfg)


# ---------------------------------------------------------------------------- command table


@dataclass(frozen=True)
class Command:
    """One sub-command: its help, its arguments, how they become a config, what runs it."""

    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    make_config: Callable[[argparse.Namespace], object]
    run: Callable[[object], object]
    exit_code: Callable[[object], int] = lambda result: 0


COMMANDS: dict[str, Command] = {
    "run": Command(
        help="retarget a demonstration onto a robot hand, re-simulate it, write metrics",
        add_arguments=_add_run_args,
        make_config=_run_config,
        run=_run,
    ),
    "hands": Command(
        help="list the robot hands: DoF, actuators, finger mapping, model source",
        add_arguments=_add_hands_args,
        make_config=_hands_config,
        run=run_hands,
    ),
}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="retarget",
        description="Retarget DexCanvas human demonstrations onto robot hands.",
    )
    p.add_argument("--version", action="version", version=f"dexcanvas-retarget {__version__}")
    p.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    for name, cmd in COMMANDS.items():
        cmd.add_arguments(sub.add_parser(name, help=cmd.help, description=cmd.help))
    return p


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
    try:
        result = cmd.run(cmd.make_config(args))
    except (RetargetError, DexCanvasError) as e:
        print(f"retarget {args.command}: error: {e}", file=sys.stderr)
        return 2
    return cmd.exit_code(result)


if __name__ == "__main__":
    sys.exit(main())
