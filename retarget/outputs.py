"""The files of a run directory: ``robot_trajectory.npz`` (joint positions and servo commands,
the re-simulated object and forces) and ``metrics.json``, each written atomically (temporary
file, then rename)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from dexcanvas_core.checks import check_path, check_type
from retarget.errors import RetargetError
from retarget.pipeline import PipelineResult


def write_run(out_dir: Path, result: PipelineResult, metrics: dict) -> None:
    """Write ``result``'s trajectory and ``metrics`` into ``out_dir`` (which must exist).

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


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file renamed over it."""
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
