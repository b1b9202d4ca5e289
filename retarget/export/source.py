"""What an export is made from: one robot trajectory with its object track and metrics.

:class:`ExportSource` is the one thing every writer (:mod:`retarget.export.mujoco`,
:mod:`retarget.export.robomimic`, :mod:`retarget.export.lerobot`) reads. A source is a run
directory (``retarget run``: ``robot_trajectory.npz`` and ``metrics.json``, read with the checks
of :func:`retarget.viz.data.load_run`); a row of a robot dataset becomes one through another
adapter, :func:`source_from_robot_row` (``retarget batch``'s Lance dataset,
:mod:`retarget.robot_dataset`), chosen by :func:`load_export_source`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dexcanvas_core.table import DEFAULT_TABLE, Table
from retarget.errors import RetargetError
from retarget.robot_dataset import read_robot_rows
from retarget.viz.data import RunFiles, load_run
from retarget.viz.errors import VizError


class ExportError(RetargetError):
    """An export cannot be made: a bad source, format or output."""


@dataclass(frozen=True)
class ExportSource:
    """One robot trajectory to export (world frame, z up, metres, radians, seconds)."""

    hand: str
    """Registered hand name (``retarget hands``)."""
    joint_names: list[str]
    """(nq,) the hand's joints in MuJoCo ``qpos`` order; the first 6 are the floating wrist."""
    q: np.ndarray
    """(T, nq) retargeted (kinematic) joint positions."""
    q_command: np.ndarray
    """(T, nq) position-servo targets sent to the re-simulation (the actions). A ``--refine``
    run's refined commands (``ctrl_refined``) are not part of the source."""
    q_sim: np.ndarray
    """(T, nq) the re-simulated hand's joint positions (the re-simulation of ``q_command``)."""
    timestamp: np.ndarray
    """(T,) [s] from the first frame (the run's timestamps minus the first)."""
    fps: float
    """Data frame rate [Hz]."""
    object_id: str
    """Catalogue object id (``dexcanvas_core.objects``)."""
    object_pos: np.ndarray
    """(T, 3) [m] the re-simulated object's position."""
    object_rot_aa: np.ndarray
    """(T, 3) [rad] the re-simulated object's orientation, axis-angle."""
    tip_sites: list[str]
    """(F,) the hand's fingertip site names."""
    tip_pos: np.ndarray
    """(T, F, 3) [m] the fingertip sites at ``q`` (the retargeted solution)."""
    force_parts: list[str]
    """The robot fingers and ``palm``: the rows of ``finger_force``."""
    finger_force: np.ndarray
    """(T, len(force_parts), 3) [N] contact force on the object per part, re-simulated."""
    table: Table
    """The table the demonstration was performed on."""
    metrics: dict
    """Everything ``metrics.json`` holds (hand, pair, uuid, dataset, success, …)."""

    @property
    def num_frames(self) -> int:
        return int(self.q.shape[0])

    @property
    def pair(self) -> str:
        return str(self.metrics.get("pair", self.object_id))

    @property
    def success(self) -> bool:
        return bool(self.metrics.get("success", False))


def load_export_source(
    run_dir: str | Path | None = None, *, dataset: str | Path | None = None, row: int | None = None
) -> ExportSource:
    """The source named by ``run_dir`` (a ``retarget run`` directory) or by ``dataset`` and
    ``row`` (a robot dataset of ``retarget batch``); exactly one of the two.

    Raises:
        ExportError: neither or both given, a malformed run directory, a row that is not
            in the robot dataset or that failed.
    """
    if (run_dir is None) == (dataset is None):
        raise ExportError("give a run directory or --dataset with --row (exactly one)")
    if dataset is not None:
        return source_from_robot_row(dataset, 0 if row is None else row)
    try:
        run = load_run(run_dir)
    except VizError as e:
        raise ExportError(str(e)) from e
    return source_from_run(run)


def source_from_run(run: RunFiles) -> ExportSource:
    """An :class:`ExportSource` of a run directory read by :func:`retarget.viz.data.load_run`."""
    a, m = run.arrays, run.metrics
    where = run.run_dir / "robot_trajectory.npz"
    for k in ("q_sim", "tip_sites", "tip_pos_world"):
        if k not in a:
            raise ExportError(
                f"{where}: missing array {k} (written by an older retarget run? run it again)"
            )
    T, nq = a["q"].shape
    if T == 0:
        raise ExportError(f"{where}: the run has no frames")
    for k in ("q_command", "q_sim"):
        if a[k].shape != (T, nq):
            raise ExportError(f"{where}: {k} has shape {a[k].shape}, q has {(T, nq)}")
    fps = float(m["fps"])
    if not (np.isfinite(fps) and fps > 0):
        raise ExportError(f"{run.run_dir / 'metrics.json'}: fps must be > 0, got {m['fps']!r}")
    return _source(str(m["hand"]), a, run.timestamp, fps, m)


def source_from_robot_row(dataset: str | Path, row: int) -> ExportSource:
    """An :class:`ExportSource` of row ``row`` (0-based, dataset order) of a robot dataset
    written by ``retarget batch`` (:func:`retarget.robot_dataset.read_robot_rows`).

    Raises:
        ExportError: no such row, or the row's job failed (it has no trajectory).
    """
    if isinstance(row, bool) or not isinstance(row, int | np.integer) or row < 0:
        raise ExportError(f"--row must be an int >= 0, got {row!r}")
    try:
        rows = read_robot_rows(dataset)
    except RetargetError as e:
        raise ExportError(str(e)) from e
    if row >= len(rows):
        raise ExportError(f"{dataset} has {len(rows)} rows; --row {row} is not one of them")
    r = rows[row]
    if r["status"] != "ok":
        raise ExportError(
            f"{dataset} row {row} ({r['pair']}, {r['hand']}) failed in the batch: {r['reason']}; "
            "it has no trajectory to export (rerun it with retarget batch --retry-failed)"
        )
    arrays = {k: np.array(v, dtype=np.float64) if isinstance(v, np.ndarray) else v
              for k, v in r.items()}  # fmt: skip  # copies: Arrow's buffers are read-only
    return _source(str(r["hand"]), arrays, arrays["timestamp"], float(r["fps"]), dict(r["metrics"]))


def _source(hand: str, a, timestamp: np.ndarray, fps: float, m: dict) -> ExportSource:
    """The :class:`ExportSource` of arrays ``a`` (the keys of ``robot_trajectory.npz``, which
    a robot-dataset row shares) and metrics ``m``."""
    obj = m.get("object") or {}
    table = Table.from_dict(m["table"]) if isinstance(m.get("table"), dict) else DEFAULT_TABLE
    return ExportSource(
        hand=hand,
        joint_names=[str(n) for n in a["joint_names"]],
        q=np.asarray(a["q"], dtype=np.float64),
        q_command=np.asarray(a["q_command"], dtype=np.float64),
        q_sim=np.asarray(a["q_sim"], dtype=np.float64),
        timestamp=np.asarray(timestamp, dtype=np.float64) - timestamp[0],
        fps=fps,
        object_id=str(obj.get("id") or str(m["pair"]).split("/", 1)[0]),
        object_pos=np.asarray(a["object_pos_sim"], dtype=np.float64),
        object_rot_aa=np.asarray(a["object_rot_sim"], dtype=np.float64),
        tip_sites=[str(x) for x in a["tip_sites"]],
        tip_pos=np.asarray(a["tip_pos_world"], dtype=np.float64),
        force_parts=[str(x) for x in a["force_parts"]],
        finger_force=np.asarray(a["finger_force_world"], dtype=np.float64),
        table=table,
        metrics=m,
    )
