"""What a picture of a run shows, frame by frame: robot hand, object, human hand, contacts.

A *run directory* is what ``retarget run`` writes (``robot_trajectory.npz``, ``metrics.json``).
:func:`load_run` reads it with checks; :func:`load_human` finds the human demonstration it was
made from (dataset and ``uuid`` are in ``metrics.json``); the re-simulation is replayed by
:mod:`retarget.viz.resim` (what ``retarget run`` does not store: the simulated hand joints and
every robot contact point with its force); :func:`scene_data` puts it all into one
:class:`SceneData`, with the contacts of :mod:`retarget.viz.contacts`.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from dexcanvas_core.builtin import builtin_demonstration_path
from dexcanvas_core.capture import use_dataset_objects
from dexcanvas_core.io import open_dataset
from dexcanvas_core.loaders.selection import select_rows
from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.table import DEFAULT_TABLE, Table, table_of
from dexcanvas_core.taxonomy import Pair
from dexcanvas_core.trajectory import Trajectory
from retarget.hands import get_hand
from retarget.time_scale import time_scaled
from retarget.viz.contacts import ContactFrames, human_contacts
from retarget.viz.errors import VizError
from retarget.viz.resim import RobotSimRecord, record_resimulation

RUN_FILES = ("robot_trajectory.npz", "metrics.json")
"""The files of a run directory (``retarget run``)."""

_NPZ_KEYS = (
    "q",
    "q_command",
    "timestamp",
    "joint_names",
    "object_pos_sim",
    "object_rot_sim",
    "object_pos_err",
    "object_rot_err",
    "finger_force_world",
    "force_parts",
)
_METRICS_KEYS = ("hand", "pair", "uuid", "dataset", "frames", "fps")


# ---------------------------------------------------------------------------- run directory


@dataclass
class RunFiles:
    """The contents of a run directory."""

    run_dir: Path
    metrics: dict
    arrays: dict[str, np.ndarray]
    """Every array of ``robot_trajectory.npz``."""

    @property
    def num_frames(self) -> int:
        return int(self.arrays["q"].shape[0])

    @property
    def timestamp(self) -> np.ndarray:
        return np.asarray(self.arrays["timestamp"], dtype=np.float64)


def load_run(run_dir: str | Path) -> RunFiles:
    """Read a run directory written by ``retarget run``; raise :class:`VizError` naming what is
    missing or malformed."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise VizError(
            f"run directory {str(run_dir)!r} does not exist (make one with retarget run)"
        )
    missing = [f for f in RUN_FILES if not (run_dir / f).is_file()]
    if missing:
        raise VizError(
            f"run directory {str(run_dir)!r} has no {' or '.join(missing)} "
            f"(a run directory holds {', '.join(RUN_FILES)}; make one with retarget run)"
        )
    try:
        metrics = json.loads((run_dir / "metrics.json").read_text())
    except (OSError, ValueError) as e:
        raise VizError(
            f"{run_dir / 'metrics.json'}: cannot read it as JSON ({e}); rerun retarget run to "
            "write it again"
        ) from e
    if not isinstance(metrics, dict):
        raise VizError(
            f"{run_dir / 'metrics.json'}: expected a JSON object, got {type(metrics).__name__} "
            "(rerun retarget run to write it again)"
        )
    absent = [k for k in _METRICS_KEYS if k not in metrics]
    if absent:
        raise VizError(
            f"{run_dir / 'metrics.json'}: missing field(s) {', '.join(absent)} (not written by "
            "retarget run? rerun it to write the directory again)"
        )
    try:
        with np.load(run_dir / "robot_trajectory.npz", allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:  # truncated or not a zip
        raise VizError(
            f"{run_dir / 'robot_trajectory.npz'}: cannot read it ({e}); the file is truncated "
            "or not a run's output: rerun retarget run to write it again"
        ) from e
    absent = [k for k in _NPZ_KEYS if k not in arrays]
    if absent:
        raise VizError(
            f"{run_dir / 'robot_trajectory.npz'}: missing array(s) {', '.join(absent)} (not "
            "written by retarget run? rerun it to write the directory again)"
        )
    T = arrays["q"].shape[0] if arrays["q"].ndim else None
    for k in _NPZ_KEYS:
        if k in ("joint_names", "force_parts"):
            continue
        if T is None or arrays[k].ndim == 0:
            raise VizError(
                f"{run_dir / 'robot_trajectory.npz'}: {k} is a scalar, not per-frame values "
                "(rerun retarget run to write it again)"
            )
        if arrays[k].shape[0] != T:
            raise VizError(
                f"{run_dir / 'robot_trajectory.npz'}: {k} has {arrays[k].shape[0]} frames, "
                f"q has {T}"
            )
    return RunFiles(run_dir=run_dir, metrics=metrics, arrays=arrays)


def load_human(
    dataset: str | Path | None, pair: str | None, *, uuid: str | None = None, index: int = 0
) -> Trajectory:
    """The human demonstration of ``pair`` in ``dataset`` (``None`` or ``'built-in'``: the
    built-in demonstrations), by ``uuid`` when given, else the ``index``-th of the pair; with a
    dataset and no pair, the row ``index``."""
    builtin = dataset is None or str(dataset) == "built-in"
    if builtin:
        if pair is None:
            raise VizError("the built-in demonstrations are chosen by pair: give --pair")
        p = Pair.parse(pair)
        path = builtin_demonstration_path(p)
    else:
        path = Path(dataset)
        use_dataset_objects(path)
    ds = open_dataset(path)
    if not builtin and (uuid is not None or pair is None):
        sel = select_rows(ds)
        if uuid is not None:
            if uuid not in sel.uuids:
                raise VizError(
                    f"dataset {str(path)!r} has no demonstration {uuid!r} (the run was made "
                    "from a different dataset?)"
                )
            return ds.take([int(sel.positions[sel.uuids.index(uuid)])])[0]
        if not 0 <= index < len(sel.positions):
            raise VizError(f"index {index} out of range: {path} has {len(sel.positions)} rows")
        return ds.take([int(sel.positions[index])])[0]
    p = Pair.parse(pair)
    sel = select_rows(ds, objects=[p.object.id], manipulation_types=[p.manipulation_type.name])
    if uuid is not None:
        if uuid not in sel.uuids:
            raise VizError(
                f"dataset {str(path)!r} has no demonstration {uuid!r} of {p} (the run was made "
                "from a different dataset?)"
            )
        pos = sel.positions[sel.uuids.index(uuid)]
    else:
        n = len(sel.positions)
        if not 0 <= index < n:
            raise VizError(f"index {index} out of range: {path} has {n} demonstration(s) of {p}")
        pos = sel.positions[index]
    return ds.take([int(pos)])[0]


def load_human_for_run(run: RunFiles) -> Trajectory:
    """The demonstration a run was made from (``metrics.json``: dataset, pair, uuid), executed
    as slowly as the run executed it (``time_scale``, :func:`retarget.time_scale.time_scaled`)."""
    m = run.metrics
    traj = time_scaled(
        load_human(m["dataset"], m["pair"], uuid=m["uuid"]), m.get("time_scale", 1.0)
    )
    if traj.num_frames != run.num_frames:
        raise VizError(
            f"demonstration {m['uuid']} has {traj.num_frames} frames, the run in "
            f"{run.run_dir} has {run.num_frames}"
        )
    return traj


# ---------------------------------------------------------------------------- scene data


@dataclass
class SceneData:
    """Everything drawn, per data frame (world frame, z up, metres)."""

    hand_name: str
    object_id: str
    pair: str
    fps: float
    """Data frame rate [Hz]."""
    timestamp: np.ndarray
    """(T,) [s]."""
    robot_qpos: np.ndarray
    """(T, hand_nq) robot hand joints shown (MuJoCo ``qpos`` order, floating wrist first)."""
    robot_source: Literal["sim", "kinematic"]
    """``sim``: the re-simulated hand; ``kinematic``: the retargeted solution."""
    object_pos: np.ndarray
    """(T, 3) [m] object drawn with the robot (simulated when ``robot_source`` is ``sim``)."""
    object_rot_aa: np.ndarray
    """(T, 3) [rad]."""
    ref_object_pos: np.ndarray
    """(T, 3) [m] the human's object (the reference the simulation must follow)."""
    ref_object_rot_aa: np.ndarray
    human_keypoints: np.ndarray | None
    """(T, 21, 3) [m] MANO21 keypoints of the human hand."""
    human_contacts: ContactFrames | None
    robot_contacts: ContactFrames | None
    metrics: dict
    table: Table = DEFAULT_TABLE
    """The demonstration's table (drawn as its box)."""

    @property
    def num_frames(self) -> int:
        return self.timestamp.shape[0]

    def check_frames(self, frames) -> np.ndarray:
        """``frames`` as an int array; :class:`VizError` for any outside ``0 … T-1``."""
        out = np.asarray(list(frames), dtype=np.int64)
        T = self.num_frames
        bad = out[(out < 0) | (out >= T)]
        if bad.size:
            raise VizError(
                f"frame {int(bad[0])} out of range: {self.pair} on {self.hand_name} has "
                f"{T} frames (0–{T - 1})"
            )
        return out


def scene_data(
    run: RunFiles,
    human: Trajectory | None,
    *,
    hand=None,
    robot_source: Literal["sim", "kinematic"] = "sim",
    sim: RobotSimRecord | None = None,
) -> SceneData:
    """Combine a run, its human demonstration and (for ``robot_source='sim'``) a recorded
    re-simulation (made here when ``sim`` is None) into what the renderers draw."""
    if robot_source not in ("sim", "kinematic"):
        raise VizError(f"robot_source must be 'sim' or 'kinematic', got {robot_source!r}")
    m = run.metrics
    object_id = (m.get("object") or {}).get("id") or m["pair"].split("/", 1)[0]
    if hand is None:
        hand = get_hand(m["hand"])
    a = run.arrays
    T = run.num_frames
    if human is not None and human.num_frames != T:
        raise VizError(f"the demonstration has {human.num_frames} frames, the run has {T}")
    robot_contacts = None
    if robot_source == "sim":
        if sim is None:
            if human is None:
                raise VizError("showing the re-simulated hand needs the human demonstration")
            sim = record_resimulation(
                hand, object_geometry(object_id), a["q_command"], human, metrics=m
            )
        qpos = sim.qpos
        robot_contacts = sim.contacts
        obj_pos, obj_rot = a["object_pos_sim"], a["object_rot_sim"]
    else:
        qpos = a["q"]
        obj_pos = human.object.pos if human is not None else a["object_pos_sim"]
        obj_rot = human.object.rot_aa if human is not None else a["object_rot_sim"]
    if human is not None:
        ref_pos, ref_rot = human.object.pos, human.object.rot_aa
        kp = human.hand.joint_pos
        hc = human_contacts(human, object_geometry(object_id))
    else:
        ref_pos, ref_rot, kp, hc = obj_pos, obj_rot, None, None
    return SceneData(
        hand_name=hand.name,
        object_id=object_id,
        pair=str(m["pair"]),
        fps=float(m["fps"]),
        timestamp=run.timestamp,
        robot_qpos=np.asarray(qpos, dtype=np.float64),
        robot_source=robot_source,
        object_pos=np.asarray(obj_pos, dtype=np.float64),
        object_rot_aa=np.asarray(obj_rot, dtype=np.float64),
        ref_object_pos=np.asarray(ref_pos, dtype=np.float64),
        ref_object_rot_aa=np.asarray(ref_rot, dtype=np.float64),
        human_keypoints=None if kp is None else np.asarray(kp, dtype=np.float64),
        human_contacts=hc,
        robot_contacts=robot_contacts,
        metrics=m,
        table=table_of(human) if human is not None else DEFAULT_TABLE,
    )
