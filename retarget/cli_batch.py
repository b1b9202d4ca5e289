"""The arguments of ``retarget batch`` and the :class:`~retarget.batch.BatchConfig` they make
(:mod:`retarget.cli` lists the command; :mod:`retarget.batch` runs it, imported only then, for
the start-up time of ``retarget --help``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from dexcanvas_core.cli_help import BUILTIN, add_dataset_option
from dexcanvas_core.exits import EXIT_FAILED, EXIT_OK
from retarget.overrides import parse_override


def _names(text: str) -> tuple[str, ...]:
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise argparse.ArgumentTypeError(f"expected NAME[,NAME...], got {text!r}")
    return names


def _rows(text: str) -> tuple[int, ...]:
    """``0,3,5-7`` → ``(0, 3, 5, 6, 7)``."""
    out: list[int] = []
    try:
        for part in text.split(","):
            lo, _, hi = part.strip().partition("-")
            first, last = int(lo), int(hi or lo)
            if first < 0 or last < first:
                raise ValueError
            out.extend(range(first, last + 1))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected 0-based row positions like 0,3,5-7, got {text!r}"
        ) from None
    return tuple(out)


def _count(minimum: int):
    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            n = minimum - 1
        if n < minimum:
            raise argparse.ArgumentTypeError(f"expected a whole number >= {minimum}, got {text!r}")
        return n

    return parse


def add_batch_args(p: argparse.ArgumentParser) -> None:
    src = p.add_argument_group("which demonstrations")
    add_dataset_option(src, note="default: the whole built-in set")
    src.add_argument(
        "--types",
        type=_names,
        default=None,
        metavar="T[,T...]",
        help="only these manipulation types (names or gesture codes)",
    )
    src.add_argument(
        "--objects", type=_names, default=None, metavar="O[,O...]", help="only these objects"
    )
    src.add_argument(
        "--operators", type=_names, default=None, metavar="OP[,OP...]", help="only these operators"
    )
    src.add_argument(
        "--rows",
        type=_rows,
        default=None,
        metavar="R[,R-R...]",
        help="only these 0-based row positions, e.g. 0,3,5-7",
    )
    src.add_argument(
        "--limit",
        type=_count(1),
        default=None,
        metavar="N",
        help="at most N demonstrations (the first, in dataset order)",
    )
    src.add_argument(
        "--max-frames",
        type=_count(2),
        default=None,
        metavar="N",
        help="crop each demonstration to its first N frames (default: whole)",
    )
    how = p.add_argument_group("how")
    how.add_argument(
        "--hands",
        type=_names,
        required=True,
        metavar="H[,H...]",
        help="robot hands, e.g. shadow,allegro (see `retarget hands`)",
    )
    how.add_argument("--forces", action="store_true", help="force matching (as retarget run)")
    how.add_argument(
        "--refine", action="store_true", help="refine runs that lose the object (as retarget run)"
    )
    how.add_argument(
        "--set",
        action="append",
        type=parse_override,
        metavar="NAME=VALUE",
        help="change a RetargetConfig field (repeatable); part of the method",
    )
    where = p.add_argument_group("where")
    where.add_argument(
        "--out",
        type=Path,
        required=True,
        help="robot trajectory dataset (*.lance); resumed when it exists",
    )
    where.add_argument(
        "--overwrite", action="store_true", help="replace --out instead of resuming it"
    )
    where.add_argument(
        "--retry-failed",
        action="store_true",
        help="run the jobs recorded as failed again (their rows replaced)",
    )
    where.add_argument(
        "--workers",
        type=_count(1),
        default=None,
        metavar="N",
        help="local worker processes (default: all cores); with --ray-address local, its CPUs",
    )
    where.add_argument(
        "--ray-address",
        default=None,
        metavar="auto|HOST:PORT|local",
        help="run the jobs as Ray tasks on that cluster ('local': a private "
        "local Ray on 127.0.0.1, no dashboard); default: a local process pool",
    )
    where.add_argument(
        "--commit-every",
        type=_count(1),
        default=8,
        metavar="N",
        help="commit finished rows in chunks of N (default 8; also every 60 s)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")


def batch_config(args: argparse.Namespace):
    # Lazy: start-up time of ``retarget --help`` (module docstring).
    from retarget.batch import BatchConfig

    return BatchConfig(
        hands=args.hands,
        out=args.out,
        dataset=None if args.dataset in (None, BUILTIN) else args.dataset,
        types=args.types or (),
        objects=args.objects or (),
        operators=args.operators or (),
        rows=args.rows or (),
        limit=args.limit,
        max_frames=args.max_frames,
        forces=args.forces,
        refine=args.refine,
        overrides=dict(args.set or ()),
        workers=args.workers,
        ray_address=args.ray_address,
        retry_failed=args.retry_failed,
        overwrite=args.overwrite,
        commit_every=args.commit_every,
        progress=not args.quiet,
    )


def run_batch_command(cfg) -> dict:
    """``retarget batch``: :func:`retarget.batch.run_batch`."""
    # Lazy: start-up time of ``retarget --help`` (module docstring).
    from retarget.batch import run_batch

    return run_batch(cfg)


def batch_exit_code(summary: dict) -> int:
    """0 when every job gave a row of status ``ok`` (some may have lost the object: that is
    their ``success``, not a failure of the batch); 3 when a job failed."""
    return EXIT_OK if summary["failed"] == 0 else EXIT_FAILED


BATCH_HELP = "retarget a dataset × hands into one Lance dataset of robot trajectories"
BATCH_DESCRIPTION = (
    "Retarget many demonstrations onto several hands (one job per demonstration × hand) on a\n"
    "local process pool or a Ray cluster, into one resumable Lance dataset of robot "
    "trajectories.\nRerun the same command to resume; jobs already in --out are skipped.\n"
    "Exit 3 when a job failed (its row says why); a run that loses the object is not a failure."
)
BATCH_EXAMPLES = (
    "retarget batch --hands shadow,allegro --limit 4 --out B.lance",
    "retarget batch --dataset real.lance --types tripod --hands leap --forces --out leap.lance",
    "retarget batch --hands shadow --ray-address auto --out all.lance",
)
