"""What the ``retarget`` sub-commands do once their arguments are parsed (:mod:`retarget.cli`).

Each ``cmd_*`` function takes the config its parser made and runs the library's ``run_*``
function; they alone print to the terminal. The library modules are imported inside the
functions, for start-up time: ``retarget --help`` imports this module and needs none of them.
"""

from __future__ import annotations

import contextlib
import json
import signal
import threading
from dataclasses import dataclass
from pathlib import Path


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
    # Lazy: start-up time of ``retarget --help`` (module docstring).
    from retarget.hands import hands_table

    rows = hands_table()
    if cfg.as_json:
        print(json.dumps(rows, indent=2, sort_keys=True))
        return rows
    # Lazy: start-up time of ``retarget --help`` (module docstring).
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


@dataclass(frozen=True)
class RunAndSnapshotConfig:
    """``retarget run --snapshot``: the run, then stills of it into its directory."""

    run: object
    """The ``retarget.pipeline.RunConfig``."""
    renderer: str = "auto"


def cmd_run(cfg) -> dict:
    """``retarget run``: :func:`retarget.run.run_retarget`, then the stills with ``--snapshot``."""
    # Lazy: start-up time of ``retarget --help`` (module docstring).
    from retarget.outputs import open_run_dir
    from retarget.run import run_retarget

    if isinstance(cfg, RunAndSnapshotConfig):
        # Lazy: start-up time of ``retarget --help`` (module docstring).
        from retarget.viz.snapshot import check_renderer, snapshot_run

        check_renderer(cfg.renderer)  # before the long part
        run = cfg.run
        # The run and its stills under one lock (run_retarget and snapshot_run re-enter it).
        with open_run_dir(run.output_dir(), overwrite=run.overwrite) as out_dir:
            metrics = run_retarget(run)
            with _sigterm_as_exit():
                manifest = snapshot_run(out_dir, renderer=cfg.renderer, overwrite=run.overwrite)
        if cfg.run.progress:
            _print_snapshot(manifest, cfg.run.output_dir())
        return metrics
    return run_retarget(cfg)


@contextlib.contextmanager
def _sigterm_as_exit():
    """Turn SIGTERM into SystemExit while the block runs, so that the ``with`` blocks holding
    child processes (meshcat server, Chromium, MuJoCo renderer) end them on ``kill`` too."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise SystemExit(128 + signum)

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _print_snapshot(manifest: dict, out_dir: Path) -> None:
    files = ", ".join(manifest["files"])
    print(f"{len(manifest['files'])} still(s) by {manifest['renderer']} in {out_dir}: {files}")
    if manifest.get("scene_html"):
        print(f"animated scene: {out_dir / manifest['scene_html']}")


def cmd_snapshot(cfg) -> dict:
    """``retarget snapshot``: :func:`retarget.viz.snapshot.run_snapshot`; prints the files."""
    # Lazy: start-up time of ``retarget --help`` (module docstring).
    from retarget.viz.snapshot import run_snapshot

    with _sigterm_as_exit():
        manifest = run_snapshot(cfg)
    if cfg.progress:
        _print_snapshot(manifest, Path(cfg.out))
    return manifest


def cmd_report(cfg) -> Path:
    """``retarget report``: :func:`retarget.viz.report.run_report`; prints the page's path."""
    # Lazy: start-up time of ``retarget --help`` (module docstring).
    from retarget.viz.report import run_report

    with _sigterm_as_exit():
        out = run_report(cfg)
    print(f"report: {out}")
    return out


def cmd_keypoints(cfg) -> dict:
    """``retarget keypoints``: :func:`retarget.keypoint_input.run_keypoints`."""
    # Lazy: start-up time of ``retarget --help`` (module docstring).
    from retarget.keypoint_input import run_keypoints

    return run_keypoints(cfg)


def cmd_calibrate(cfg) -> object:
    """``retarget calibrate-wrist``: :func:`retarget.calibration.run_calibrate`."""
    # Lazy: start-up time of ``retarget --help`` (module docstring).
    from retarget.calibration import run_calibrate

    return run_calibrate(cfg)


def cmd_export(cfg) -> Path:
    """``retarget export``: :func:`retarget.export.run_export`; prints the output's path."""
    # Lazy: start-up time of ``retarget --help`` (module docstring).
    from retarget.export import run_export

    out = run_export(cfg)
    print(f"{cfg.format} export of {cfg.run_dir}: {out}")
    return out
