"""The terminal side of ``retarget batch``: its progress bar (jobs, rate, ETA) and the
per-hand summary table and failures list at the end (rich, on stderr and stdout)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

from rich import box
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Table
from rich.text import Text


class _RateColumn(ProgressColumn):
    """Jobs per minute since the bar started."""

    def render(self, task) -> Text:
        if not task.completed or not task.elapsed:
            return Text("–/min")
        return Text(f"{60 * task.completed / task.elapsed:.1f}/min")


@contextlib.contextmanager
def job_progress(show: bool, total: int) -> Iterator:
    """A function ``advance(row)`` moving a bar of ``total`` jobs (nothing when not ``show``);
    the bar's text counts the failed rows."""
    if not show:
        yield lambda row: None
        return
    failed = [0]
    with Progress(
        TextColumn("[bold]batch[/] {task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        _RateColumn(),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        transient=False,
    ) as bar:
        task = bar.add_task("jobs", total=total)

        def advance(row: dict) -> None:
            failed[0] += row.get("status") == "failed"
            desc = f"{row.get('hand')} {row.get('pair')}"
            if failed[0]:
                desc += f" ({failed[0]} failed)"
            bar.update(task, advance=1, description=desc)

        yield advance


def _cell(x, fmt: str) -> str:
    return "–" if x is None else format(x, fmt)


def print_summary(summary: dict, out: Path) -> None:
    """The per-hand table (jobs, ok, failed, success rate, mean keypoint error, CPU time) and
    the failures with their reasons."""
    con = Console()
    t = Table(title=f"retarget batch → {out}", box=box.SIMPLE_HEAD)
    for name in ("hand", "jobs", "ok", "failed", "success", "keypoint err (mm)", "CPU (s)"):
        t.add_column(name, justify="left" if name == "hand" else "right")
    for hand, h in summary["hands"].items():
        kp = None if h["keypoint_err_mean_m"] is None else 1e3 * h["keypoint_err_mean_m"]
        rate = None if h["success_rate"] is None else 100 * h["success_rate"]
        t.add_row(
            hand,
            str(h["jobs"]),
            str(h["ok"]),
            str(h["failed"]),
            _cell(rate, ".0f") + ("%" if rate is not None else ""),
            _cell(kp, ".1f"),
            f"{h['cpu_s']:.0f}",
        )
    con.print(t)
    con.print(
        f"{summary['ran']} job(s) run, {summary['skipped']} already in the dataset; "
        f"{summary['rows']} row(s) of this batch in {out} ({summary['seconds']:.0f} s)",
        highlight=False,
    )
    if summary["failures"]:
        con.print(f"[bold red]{len(summary['failures'])} failed job(s)[/]:")
        for f in summary["failures"]:
            con.print(
                f"  {f['hand']} {f['pair']} ({f['uuid']}): {f['reason']}",
                markup=False,
                highlight=False,
            )
        con.print("rerun with --retry-failed to run them again", highlight=False)
