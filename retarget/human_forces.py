"""The human's contact forces for force matching: the force pipeline
(:mod:`dexcanvas_core.sim.pipeline`) run on a demonstration that has none, and the human replay
(the same simulation at another MPC seed: the ceiling of the robot's force correlation)."""

from __future__ import annotations

from dataclasses import dataclass

from dexcanvas_core.sim.mpc import MPCConfig
from dexcanvas_core.sim.pipeline import SimConfig, simulate
from dexcanvas_core.trajectory import Trajectory
from retarget.errors import RetargetError

HUMAN_REPLAY_SEED = 1
"""MPC seed of the human replay (``RunConfig.human_replay``, the force-preservation benchmark's
``--human-replay``); the force pipeline's first simulation runs at ``MPCConfig``'s default, 0."""


def human_sim_config(
    object_id: str, tracker: str = "mpc", mpc_seed: int | None = None
) -> SimConfig:
    """The force pipeline's ``SimConfig`` for one human simulation with ``object_id``: the
    defaults, or the sampling MPC at ``mpc_seed`` (the human replay)."""
    if mpc_seed is None:
        return SimConfig(tracker=tracker, object_id=object_id)
    return SimConfig(tracker=tracker, object_id=object_id, mpc=MPCConfig(seed=mpc_seed))


def simulate_human(traj: Trajectory, object_id: str, progress=None, label: str = "human forces",
                   mpc_seed: int | None = None):  # fmt: skip
    """The force pipeline on ``traj`` with ``object_id`` (at ``mpc_seed``, else the defaults):
    ``(SimResult, metrics without the config)``; ``progress``: a :class:`Progress` for its
    bar."""
    task = progress.task(label, traj.num_frames) if progress is not None else None
    done = [0]

    def step(n):
        done[0] += n
        if task is not None:
            task(done[0], traj.num_frames)

    res = simulate(traj, human_sim_config(object_id, mpc_seed=mpc_seed), progress=step)
    return res, {k: v for k, v in res.metrics.items() if k != "config"}


def human_forces(traj: Trajectory, object_id: str, progress=None) -> tuple[Trajectory, dict]:
    """``traj`` annotated with the human's contact forces by the force pipeline, and the
    pipeline's metrics; a ``RetargetError`` naming the failure when it could not reproduce the
    demonstration."""
    res, m = simulate_human(traj, object_id, progress, "human forces (force pipeline)")
    if not res.success:
        raise RetargetError(
            f"the force pipeline could not reproduce this demonstration with {object_id} "
            f"(object error > 5 cm at frame {m['failed_at_frame']}"
            + (f": {m['failure']['reason']}" if m.get("failure") else "")
            + "), so there are no human forces to match; try another --index, or run without "
            "--forces (dexcanvas simulate shows why it failed)"
        )
    return res.trajectory, m


@dataclass
class HumanReplay:
    """The force pipeline run again on a force-annotated demonstration at ``mpc_seed``
    (``RunConfig.human_replay``): the ceiling of the robot's force correlation."""

    trajectory: Trajectory | None
    """The replay's force-annotated trajectory; ``None`` when it lost the object."""
    sim_metrics: dict
    """The force pipeline's metrics of the replay."""
    mpc_seed: int = HUMAN_REPLAY_SEED
