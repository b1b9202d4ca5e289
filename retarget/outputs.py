"""The files of a run directory: ``robot_trajectory.npz`` (joint positions and servo commands,
the re-simulated object and forces) and ``metrics.json``, each written atomically (a unique
temporary file, then rename: :mod:`dexcanvas_core.safe_io`), by one process at a time
(:func:`open_run_dir`)."""

from __future__ import annotations

import contextlib
import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from dexcanvas_core.checks import check_path, check_type
from dexcanvas_core.safe_io import atomic_write_text, check_output, output_lock
from retarget.errors import RetargetError
from retarget.pipeline import PipelineResult

RUN_FILES = ("robot_trajectory.npz", "metrics.json")
"""The files that make a directory a run directory (an existing run, for ``--overwrite``)."""


@contextlib.contextmanager
def open_run_dir(
    out_dir, *, overwrite: bool, what: str = "--out", contents: tuple[str, ...] = RUN_FILES
) -> Iterator[Path]:
    """Check run directory ``out_dir`` (:func:`dexcanvas_core.safe_io.check_output`: an
    existing run without ``overwrite``, a file, a read-only place, a full disk), create it and
    hold its lock (:func:`dexcanvas_core.safe_io.output_lock`, inside it) while the block
    runs; yield it as a ``Path``. Directories made here and left empty by an error are removed.
    ``contents``: the files that make it an existing output (default: a run's).

    Raises:
        dexcanvas_core.safe_io.OutputError: the checks; ``OutputBusyError`` when another
            process holds the lock.
    """
    out_dir = check_output(out_dir, overwrite=overwrite, kind="dir", what=what, contents=contents)
    created = [d for d in (out_dir, *out_dir.parents) if not d.exists()]  # leaf first
    out_dir.mkdir(parents=True, exist_ok=True)
    try:
        with output_lock(out_dir, where="inside"):
            # again under the lock: a run that finished between the check and the lock
            check_output(out_dir, overwrite=overwrite, kind="dir", what=what, contents=contents)
            yield out_dir
    except BaseException:
        for d in created:
            try:
                d.rmdir()  # only when empty
            except OSError:
                break
        raise


def write_run(out_dir: Path, result: PipelineResult, metrics: dict) -> None:
    """Write ``result``'s trajectory and ``metrics`` into ``out_dir`` (which must exist),
    holding its lock (:func:`dexcanvas_core.safe_io.output_lock`; re-entrant, so callers
    holding :func:`open_run_dir` keep it).

    >>> import tempfile
    >>> from dexcanvas_core import load_demonstration
    >>> from retarget.metrics import run_metrics
    >>> from retarget.pipeline import RunConfig, retarget_demonstration
    >>> human = load_demonstration("cube2/tripod").slice(0, 30)
    >>> result = retarget_demonstration(human, "cube2/tripod", "panda")
    >>> out = Path(tempfile.mkdtemp())
    >>> write_run(out, result, run_metrics(result, RunConfig(hand="panda", pair="cube2/tripod")))
    >>> np.load(out / "robot_trajectory.npz")["q_command"].shape
    (30, 8)
    """
    check_path("out_dir", out_dir, error=RetargetError)
    check_type("result", result, PipelineResult, error=RetargetError)
    check_type("metrics", metrics, dict, error=RetargetError)
    with output_lock(out_dir, where="inside"):
        _save(out_dir, result.robot, result.sim, result.refined, result.planned_commands)
        atomic_write_text(out_dir / "metrics.json", json.dumps(metrics, indent=2, sort_keys=True))


def _save(out_dir: Path, robot, sim, refined=None, planned=None) -> None:
    """``planned``: the force-matched commands before force calibration (``q_command`` is the
    calibrated ones)."""
    extra = {} if refined is None else {"ctrl_refined": refined.ctrl}
    if planned is not None:
        extra["q_command_planned"] = planned
    robot.save_npz(
        out_dir / "robot_trajectory.npz",
        extra=extra
        | {
            "object_pos_sim": sim.object_pos_sim,
            "object_rot_sim": sim.object_rot_sim,
            "object_pos_err": sim.object_pos_err,
            "object_rot_err": sim.object_rot_err,
            "finger_force_world": sim.finger_force_world,
            "force_parts": np.array([*sim.fingers, "palm"]),
            "q_sim": sim.q_sim,
            "finger_servo_err": sim.finger_servo_err,
            "wrist_pos_tracking_err": sim.wrist_pos_err,
            "wrist_rot_tracking_err": sim.wrist_rot_err,
        },
    )
