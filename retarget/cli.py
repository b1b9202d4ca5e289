"""``retarget``: the command line of the robot side.

Sub-commands arrive with the robot-hand registry and the retargeting solver; until then the
entry point reports the version and which sub-commands exist.
"""

from __future__ import annotations

import argparse
import sys

from retarget import __version__


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="retarget",
        description="Retarget DexCanvas human demonstrations onto robot hands.",
    )
    p.add_argument("--version", action="version", version=f"dexcanvas-retarget {__version__}")
    p.add_subparsers(dest="command", metavar="COMMAND")
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
