"""Export to a robomimic-style HDF5 file (one demonstration, ``data/demo_0``).

The layout robomimic's ``robomimic.utils.dataset.SequenceDataset`` and
``robomimic.utils.file_utils.get_env_metadata_from_dataset`` read (robomimic docs, "Dataset
Structure" / "datasets/overview"):

- ``data`` attrs ``total`` (frames over all demos) and ``env_args`` (JSON: ``env_name``,
  ``type``, ``env_kwargs``);
- ``data/demo_i`` attr ``num_samples`` (its frames), datasets ``actions`` (N, A), ``rewards``
  (N,), ``dones`` (N,), ``states`` (N, S), groups ``obs`` and ``next_obs`` (each key (N, …));
- ``mask/<split>``: the demo names of a split (optional; here ``train`` = every demo).

Here: ``actions`` = ``q_command`` (the servo targets, radians/metres per joint),
``obs/joint_pos`` = ``q_sim``, ``obs/joint_vel`` its finite difference [unit/s],
``obs/object_pos`` [m], ``obs/object_quat`` (w x y z), ``obs/fingertip_pos`` (N, F, 3) [m] at the
retargeted ``q``, ``obs/finger_force`` (N, parts, 3) [N]; ``states`` = the MuJoCo export scene's
``qpos`` (hand + object free joint, :mod:`retarget.export.mujoco`); ``rewards`` 1 on the last
frame of a successful run, else 0; ``dones`` 1 on the last frame.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from dexcanvas_core.rotations import aa_to_quat_wxyz
from retarget.export.source import ExportError, ExportSource

ENV_TYPE_GYM = 2
"""robomimic's ``EnvType.GYM_TYPE`` (``robomimic.envs.env_base.EnvType``: 1 robosuite, 2 gym,
3 iGibson): the closest kind for an environment robomimic does not know."""


def observations(src: ExportSource) -> dict[str, np.ndarray]:
    """The per-frame observations written under ``obs`` (module docstring)."""
    dt = np.gradient(src.timestamp) if src.num_frames > 1 else np.ones(1)
    vel = (
        np.gradient(src.q_sim, axis=0) / dt[:, None]
        if src.num_frames > 1
        else np.zeros_like(src.q_sim)
    )
    return {
        "joint_pos": src.q_sim,
        "joint_vel": vel,
        "object_pos": src.object_pos,
        "object_quat": aa_to_quat_wxyz(src.object_rot_aa),
        "fingertip_pos": src.tip_pos,
        "finger_force": src.finger_force,
    }


def env_args(src: ExportSource) -> dict:
    """``data.attrs["env_args"]`` (before JSON): what made the demonstration."""
    return {
        "env_name": f"DexCanvasRetarget-{src.hand}",
        "type": ENV_TYPE_GYM,
        "env_kwargs": {
            "hand": src.hand,
            "pair": src.pair,
            "object": src.object_id,
            "uuid": src.metrics.get("uuid"),
            "dataset": str(src.metrics.get("dataset")),
            "fps": src.fps,
            "joint_names": src.joint_names,
            "tip_sites": src.tip_sites,
            "force_parts": src.force_parts,
        },
    }


def write_robomimic(src: ExportSource, path: Path) -> None:
    """Write ``src`` as ``data/demo_0`` of a new HDF5 file ``path`` (module docstring)."""
    try:
        import h5py  # optional (the export extra): only this format needs it
    except ImportError as e:
        raise ExportError(
            "--format robomimic needs h5py: pip install 'dexcanvas-retarget[export]'"
        ) from e
    T = src.num_frames
    obs = observations(src)
    # next_obs: frame t+1's observation (the last frame repeats), as robomimic's converters do.
    nxt = {k: np.concatenate([v[1:], v[-1:]], axis=0) for k, v in obs.items()}
    states = np.concatenate([src.q_sim, src.object_pos, aa_to_quat_wxyz(src.object_rot_aa)], axis=1)
    rewards = np.zeros(T)
    dones = np.zeros(T, dtype=np.int64)
    dones[-1] = 1
    if src.success:
        rewards[-1] = 1.0
    with h5py.File(path, "w") as f:
        data = f.create_group("data")
        data.attrs["total"] = T
        data.attrs["env_args"] = json.dumps(env_args(src))
        demo = data.create_group("demo_0")
        demo.attrs["num_samples"] = T
        demo.attrs["model_file"] = ""  # robosuite's MJCF slot; the scene is the MuJoCo export
        demo.create_dataset("actions", data=src.q_command)
        demo.create_dataset("rewards", data=rewards)
        demo.create_dataset("dones", data=dones)
        demo.create_dataset("states", data=states)
        for group, values in (("obs", obs), ("next_obs", nxt)):
            g = demo.create_group(group)
            for k, v in values.items():
                g.create_dataset(k, data=v)
        f.create_group("mask").create_dataset("train", data=np.array([b"demo_0"]))
