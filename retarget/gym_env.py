"""A Gymnasium environment for robot learning: the retargeted demonstration as a tracking task.

:class:`RobotTrackingEnv` wraps the physics refinement's tracker
(:func:`retarget.refine_scene.tracking_env`, a :class:`dexcanvas_core.sim.tracker.TrackingEnv`
for the robot hand) in the ``gymnasium.Env`` interface. The reference is the retargeted servo
commands plus the human object motion; a policy chooses the DexCanvas paper's *residual*
action each data frame:

    ctrl_t = ref_t + M_t · u_t,      u_t = clip(τ · u_{t-1} + a_t, -1, 1)

with ``a_t ∈ [-1, 1]^(6 + F)``: wrist x, y, z (× 3 cm), wrist rotation x, y, z (× 0.15 rad),
then one action per robot fingertip (scales that finger's force/squeeze offset and, on
contact frames, moves its tip towards the object; ``RefineConfig``). ``a = 0`` everywhere
replays the retarget open loop, exactly as ``refine(..., RefineConfig(tracker="open_loop"))``.

The reward is the tracker's planning reward for the frame reached (``TrackingEnv.rewards``):
``exp(-60·e_pos) + 0.3·exp(-10·e_rot) + 2·mean_f w_f exp(-100·‖tip_f − tip_f^ref‖) − ‖a‖² −
0.3·‖u‖²`` (object errors [m, rad], fingertips in the object frame weighted by the human's
contact), ``-1`` once the object is lost. ``terminated``: the object is more than 5 cm from
its reference (the tracker's failure); ``truncated``: the end of the demonstration. Physics and
reset are deterministic (no randomness is drawn), so a seed only seeds ``np_random``.

Registered as ``DexCanvasTracking-v0`` when this module is imported;
``gymnasium.make("retarget.gym_env:DexCanvasTracking-v0", hand="allegro")`` imports it first.

>>> env = RobotTrackingEnv("cube2/tripod", "allegro", start=0, max_frames=20)
>>> obs, info = env.reset(seed=0)
>>> env.action_space.shape, obs.shape == env.observation_space.shape, info["frame"]
((10,), True, 0)
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from dexcanvas_core.checks import check_bool, check_int
from dexcanvas_core.trajectory import Trajectory
from retarget.config import RetargetConfig
from retarget.errors import RetargetError
from retarget.loading import load_subject
from retarget.pipeline import refine_config, retarget_demonstration
from retarget.refine import RefineConfig
from retarget.refine_scene import tracking_env

ENV_ID = "DexCanvasTracking-v0"

_OBS_KEYS = (
    "hand_qpos", "hand_qvel", "object_pos", "object_quat", "object_vel", "ref_ctrl_next",
    "ref_object_pos_next", "ref_object_quat_next", "residual",
)  # fmt: skip
"""The tracker's ``observation()`` entries, in the order they are concatenated."""


@dataclass(frozen=True)
class TrackingTask:
    """A retargeted demonstration ready to be tracked: what :func:`tracking_task` caches."""

    human: Trajectory
    """The human demonstration (the slice tracked)."""
    robot: Any
    """Its ``RobotTrajectory`` on ``hand`` (after force calibration when ``forces``)."""
    hand: Any
    geometry: Any
    tip_sites: tuple[str, ...]
    refine: RefineConfig
    """The scene and residual settings (``pipeline.refine_config(forces)``)."""


_TASKS: dict[tuple, TrackingTask] = {}


def tracking_task(
    pair: str | None = "cube2/tripod",
    hand: str = "allegro",
    forces: bool = False,
    dataset: str | Path | None = None,
    index: int = 0,
    start: int = 0,
    max_frames: int | None = None,
) -> TrackingTask:
    """The demonstration (``pair`` or ``dataset`` row ``index``, :func:`retarget.loading.
    load_subject`), frames ``start`` to ``start + max_frames`` (``None``: to the end),
    retargeted onto ``hand`` (:func:`retarget.pipeline.retarget_demonstration`, force
    matched when ``forces``). Computed once per process for each distinct argument set, so
    the copies of a vector environment share it."""
    key = (pair, hand, forces, None if dataset is None else str(dataset), index, start, max_frames)
    if key not in _TASKS:
        traj, subject, _ = load_subject(pair, dataset, index)
        stop = traj.num_frames if max_frames is None else min(traj.num_frames, start + max_frames)
        if not 0 <= start < stop - 1:
            raise RetargetError(
                f"start={start}, max_frames={max_frames}: the demonstration has "
                f"{traj.num_frames} frames; a task needs at least 2"
            )
        traj = traj.slice(start, stop) if (start, stop) != (0, traj.num_frames) else traj
        config = RetargetConfig.from_overrides({"force_matching": True}) if forces else None
        res = retarget_demonstration(traj, subject, hand, config)
        _TASKS[key] = TrackingTask(
            human=res.trajectory, robot=res.robot, hand=res.hand, geometry=res.geometry,
            tip_sites=tuple(res.retargeter.tip_sites), refine=refine_config(forces),
        )  # fmt: skip
    return _TASKS[key]


class RobotTrackingEnv(gymnasium.Env):
    """The retargeted demonstration as a residual tracking task for the robot hand (module
    doc). Arguments as :func:`tracking_task` (``start``, ``max_frames``: the frames tracked).

    Spaces: ``action_space`` ``Box(-1, 1, (6 + F,))`` (float32: wrist x, y, z, rx, ry, rz,
    then one per fingertip site, :attr:`action_names`); ``observation_space`` an unbounded
    float32 ``Box`` concatenating :attr:`observation_names` (hand joint positions [m, rad]
    and velocities, object position [m], quaternion (w, x, y, z) and velocity, the next
    frame's reference servo commands and object pose, the residual ``u``, the fingertips in
    the object frame [m] now and in the next reference frame, and the episode's progress in
    [0, 1]).

    ``info``: ``frame`` (the data frame reached), ``object_pos_err_m``,
    ``object_rot_err_rad``, ``failed_at`` (the frame the object was lost, or ``None``) and,
    at the end of an episode, ``success`` (never lost).
    """

    metadata = {"render_modes": []}  # noqa: RUF012 (gymnasium's class attribute)

    def __init__(
        self,
        pair: str | None = "cube2/tripod",
        hand: str = "allegro",
        forces: bool = False,
        dataset: str | Path | None = None,
        index: int = 0,
        start: int = 0,
        max_frames: int | None = None,
    ):
        check_bool("forces", forces, error=RetargetError)
        check_int("index", index, min=0, error=RetargetError)
        check_int("start", start, min=0, error=RetargetError)
        if max_frames is not None:
            check_int("max_frames", max_frames, min=2, error=RetargetError)
        self.task = tracking_task(pair, hand, forces, dataset, index, start, max_frames)
        t = self.task
        self.tracker, _, _ = tracking_env(
            t.hand, t.geometry, t.human, t.robot, list(t.tip_sites), t.refine
        )
        env = self.tracker
        self.num_frames = env.ref.num_frames
        self.action_names = (
            "wrist_x", "wrist_y", "wrist_z", "wrist_rx", "wrist_ry", "wrist_rz",
            *(f"{s.removesuffix('_tip_site')}_finger" for s in t.tip_sites),
        )  # fmt: skip
        self.action_space = spaces.Box(-1.0, 1.0, (env.action_dim,), dtype=np.float32)
        sizes = {k: v.size for k, v in env.observation().items()}
        sizes |= {"tips_object": 3 * env.n_tips, "ref_tips_object_next": 3 * env.n_tips}
        sizes["progress"] = 1
        self.observation_names = (*_OBS_KEYS, "tips_object", "ref_tips_object_next", "progress")
        self._sizes = [sizes[k] for k in self.observation_names]
        n = sum(self._sizes)
        self.observation_space = spaces.Box(-np.inf, np.inf, (n,), dtype=np.float32)

    # -- gymnasium API ----------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Back to frame 0 of the demonstration (the tracker's settled start); ``seed`` seeds
        ``np_random`` (the episode itself draws nothing). ``(observation, info)``."""
        super().reset(seed=seed)
        self.tracker.reset()
        return self._observation(), self._info()

    def step(self, action):
        """One data frame with residual action ``action`` (clipped to the action space):
        ``(observation, reward, terminated, truncated, info)``."""
        env = self.tracker
        a = np.clip(np.asarray(action, dtype=np.float64).reshape(env.action_dim), -1.0, 1.0)
        t_prev, u_prev = env.t, env.u.copy()
        env.step(a)
        reward = self._reward(t_prev, u_prev, a)
        terminated = env.failed_at is not None
        truncated = not terminated and env.t >= self.num_frames - 1
        info = self._info()
        if terminated or truncated:
            info["success"] = not terminated and not env.warnings.blew_up
        return self._observation(), reward, terminated, truncated, info

    # -- internals --------------------------------------------------------------------------

    def _tips_object(self) -> np.ndarray:
        """(F, 3) [m] the fingertip sites in the object frame (the scene's sensors)."""
        env = self.tracker
        a = env.tip_sensor_adr
        return env.scene.data.sensordata[a : a + 3 * env.n_tips].reshape(env.n_tips, 3).copy()

    def _reward(self, t_prev: int, u_prev: np.ndarray, a: np.ndarray) -> float:
        """The tracker's planning reward (``TrackingEnv.rewards``) of the frame just reached,
        evaluated as a one-frame plan from the state before the step (``t_prev``,
        ``u_prev``) so the formula is the tracker's own."""
        env = self.tracker
        t, u = env.t, env.u
        p, q = env.log.object_pos[-1], env.log.object_quat[-1]
        pose = np.concatenate([p, q])[None, None]
        env.t, env.u = t_prev, u_prev
        try:
            r = env.rewards(pose, self._tips_object()[None, None], a[None, None])
        finally:
            env.t, env.u = t, u
        return float(r[0, 0])

    def _observation(self) -> np.ndarray:
        env = self.tracker
        obs = env.observation()
        t1 = min(env.t + 1, self.num_frames - 1)
        obs["tips_object"] = self._tips_object()
        obs["ref_tips_object_next"] = env.ref.tips_object[t1]
        obs["progress"] = np.array([env.t / (self.num_frames - 1)])
        flat = np.concatenate([np.ravel(obs[k]) for k in self.observation_names])
        return flat.astype(np.float32)

    def _info(self) -> dict:
        env = self.tracker
        return {
            "frame": env.t,
            "object_pos_err_m": env.log.pos_err[-1],
            "object_rot_err_rad": env.log.rot_err[-1],
            "failed_at": env.failed_at,
        }


if ENV_ID not in gymnasium.registry:  # (a reload of this module registers nothing new)
    gymnasium.register(id=ENV_ID, entry_point="retarget.gym_env:RobotTrackingEnv")
