"""Data loaders: a torch ``Dataset`` over DexCanvas trajectories, batching with padding and
attention masks, and an on-device trajectory buffer for parallel RL environments.

>>> ds = DexCanvasDataset(path, manipulation_types=["tripod"], objects=["cube2"])
>>> for batch in make_dataloader(ds, batch_size=8, shuffle=True, seed=0):
...     batch["finger_pose"]      # (B, T, 45), zero-padded
...     batch["attention_mask"]   # (B, T) bool
>>> buf = RLTrajectoryBuffer(ds, num_envs=4096, device="cuda", seed=0)
>>> obs = buf.get_observations(); done = buf.advance_timesteps(); buf.reset_envs(done)
"""

from dexcanvas_core.loaders.collate import collate_trajectories, make_dataloader
from dexcanvas_core.loaders.dataset import (
    META_KEYS,
    OPTIONAL_KEYS,
    REQUIRED_KEYS,
    DexCanvasDataset,
    trajectory_to_sample,
)
from dexcanvas_core.loaders.rl_buffer import DEFAULT_FIELDS, RLTrajectoryBuffer
from dexcanvas_core.loaders.selection import Selection, select_rows

__all__ = [
    "DEFAULT_FIELDS",
    "META_KEYS",
    "OPTIONAL_KEYS",
    "REQUIRED_KEYS",
    "DexCanvasDataset",
    "RLTrajectoryBuffer",
    "Selection",
    "collate_trajectories",
    "make_dataloader",
    "select_rows",
    "trajectory_to_sample",
]
