"""Export to the LeRobot dataset v3.0 layout, written with pyarrow (one episode).

The layout of ``lerobot.datasets.utils`` (``INFO_PATH``, ``STATS_PATH``, ``DEFAULT_TASKS_PATH``,
``DEFAULT_EPISODES_PATH``, ``DEFAULT_DATA_PATH``, ``DEFAULT_FEATURES``)::

    meta/info.json                             codebase_version "v3.0", fps, features, paths
    meta/stats.json                            per feature: min, max, mean, std, count
    meta/tasks.parquet                         task_index, indexed by the task string
    meta/episodes/chunk-000/file-000.parquet   one row per episode: episode_index, tasks,
                                               length, data/chunk_index, data/file_index,
                                               dataset_from_index, dataset_to_index,
                                               meta/episodes/chunk_index, …/file_index
    data/chunk-000/file-000.parquet            one row per frame

Features: ``observation.state`` = ``q_sim`` (the re-simulated joints), ``action`` =
``q_command`` (float32, names = the joint names), ``observation.environment_state`` = the
object's position [m] and quaternion (w x y z), and LeRobot's own ``timestamp`` (float32 [s]),
``frame_index``, ``episode_index``, ``index``, ``task_index`` (int64). No video.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from dexcanvas_core.rotations import aa_to_quat_wxyz
from retarget.export.source import ExportSource

CODEBASE_VERSION = "v3.0"
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
EPISODES_PATH = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
TASKS_PATH = "meta/tasks.parquet"
INFO_PATH = "meta/info.json"
STATS_PATH = "meta/stats.json"
OBJECT_STATE_NAMES = ["x", "y", "z", "qw", "qx", "qy", "qz"]


def task_of(src: ExportSource) -> str:
    """The episode's task text, e.g. ``"tripod cube2 (panda hand)"``."""
    obj, _, kind = src.pair.partition("/")
    return f"{kind or 'manipulate'} {obj} ({src.hand} hand)"


def frame_columns(src: ExportSource) -> dict[str, np.ndarray]:
    """The data file's columns (one value or vector per frame), in LeRobot's dtypes."""
    T = src.num_frames
    env = np.concatenate([src.object_pos, aa_to_quat_wxyz(src.object_rot_aa)], axis=1)
    return {
        "observation.state": src.q_sim.astype(np.float32),
        "observation.environment_state": env.astype(np.float32),
        "action": src.q_command.astype(np.float32),
        "timestamp": src.timestamp.astype(np.float32),
        "frame_index": np.arange(T, dtype=np.int64),
        "episode_index": np.zeros(T, dtype=np.int64),
        "index": np.arange(T, dtype=np.int64),
        "task_index": np.zeros(T, dtype=np.int64),
    }


def features(src: ExportSource) -> dict[str, dict]:
    """``info.json``'s ``features``: dtype, shape and names of each column."""
    nq = len(src.joint_names)
    out = {
        "observation.state": {"dtype": "float32", "shape": [nq], "names": src.joint_names},
        "observation.environment_state": {
            "dtype": "float32",
            "shape": [len(OBJECT_STATE_NAMES)],
            "names": OBJECT_STATE_NAMES,
        },
        "action": {"dtype": "float32", "shape": [nq], "names": src.joint_names},
        "timestamp": {"dtype": "float32", "shape": [1], "names": None},
    }
    for k in ("frame_index", "episode_index", "index", "task_index"):
        out[k] = {"dtype": "int64", "shape": [1], "names": None}
    return out


def _column(v: np.ndarray) -> pa.Array:
    if v.ndim == 1:
        return pa.array(v)
    return pa.FixedSizeListArray.from_arrays(pa.array(v.ravel()), v.shape[1])


def _stats(v: np.ndarray) -> dict[str, list]:
    v2 = v.reshape(len(v), -1).astype(np.float64)
    return {
        "min": v2.min(axis=0).tolist(),
        "max": v2.max(axis=0).tolist(),
        "mean": v2.mean(axis=0).tolist(),
        "std": v2.std(axis=0).tolist(),
        "count": [len(v)],
    }


def _tasks_table(task: str) -> pa.Table:
    """``tasks.parquet`` as ``pandas.DataFrame({"task_index": [0]}, index=[task])`` writes it
    (LeRobot reads it with ``pandas.read_parquet`` and looks tasks up by the index)."""
    pandas_meta = {
        "index_columns": ["__index_level_0__"],
        "column_indexes": [],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64",
             "numpy_type": "int64", "metadata": None},
            {"name": None, "field_name": "__index_level_0__", "pandas_type": "unicode",
             "numpy_type": "object", "metadata": None},
        ],
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.2.0",
    }  # fmt: skip
    t = pa.table({"task_index": pa.array([0], pa.int64()), "__index_level_0__": [task]})
    return t.replace_schema_metadata({b"pandas": json.dumps(pandas_meta).encode()})


def write_lerobot(src: ExportSource, root: Path) -> list[str]:
    """Write ``src`` as episode 0 of a new LeRobot v3.0 dataset in directory ``root`` (module
    docstring); return the files written, relative to it."""
    T = src.num_frames
    cols = frame_columns(src)
    feats = features(src)
    task = task_of(src)
    data_rel = DATA_PATH.format(chunk_index=0, file_index=0)
    episodes_rel = EPISODES_PATH.format(chunk_index=0, file_index=0)
    for rel in (data_rel, episodes_rel):
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(pa.table({k: _column(v) for k, v in cols.items()}), root / data_rel)
    stats = {k: _stats(v) for k, v in cols.items()}
    episode = {
        "episode_index": pa.array([0], pa.int64()),
        "tasks": pa.array([[task]], pa.list_(pa.string())),
        "length": pa.array([T], pa.int64()),
        "data/chunk_index": pa.array([0], pa.int64()),
        "data/file_index": pa.array([0], pa.int64()),
        "dataset_from_index": pa.array([0], pa.int64()),
        "dataset_to_index": pa.array([T], pa.int64()),
    }
    for k, s in stats.items():
        for name, val in s.items():
            typ = pa.int64() if name == "count" else pa.float64()
            episode[f"stats/{k}/{name}"] = pa.array([val], pa.list_(typ))
    episode["meta/episodes/chunk_index"] = pa.array([0], pa.int64())
    episode["meta/episodes/file_index"] = pa.array([0], pa.int64())
    pq.write_table(pa.table(episode), root / episodes_rel)
    pq.write_table(_tasks_table(task), root / TASKS_PATH)
    (root / STATS_PATH).write_text(json.dumps(stats, indent=4))
    info = {
        "codebase_version": CODEBASE_VERSION,
        "robot_type": src.hand,
        "total_episodes": 1,
        "total_frames": T,
        "total_tasks": 1,
        "chunks_size": 1000,
        "data_files_size_in_mb": 100,
        "video_files_size_in_mb": 500,
        "fps": int(src.fps) if float(src.fps).is_integer() else src.fps,
        "splits": {"train": "0:1"},
        "data_path": DATA_PATH,
        "video_path": VIDEO_PATH,
        "features": feats,
    }
    (root / INFO_PATH).write_text(json.dumps(info, indent=4))
    return [INFO_PATH, STATS_PATH, TASKS_PATH, episodes_rel, data_rel]
