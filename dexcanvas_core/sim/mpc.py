"""The trackers that choose each frame's residual action in a :class:`~dexcanvas_core.sim.
tracker.TrackingEnv` (the interface :class:`ResidualTracker`: the zero-residual
:class:`OpenLoop` and the predictive-sampling :class:`SamplingMPC`), and :func:`track`, the
loop that runs one over a whole demonstration.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from dexcanvas_core.errors import ValidationError
from dexcanvas_core.sim.tracker import TrackingEnv, TrackLog


class ResidualTracker(Protocol):
    """Chooses the residual action of each frame (see the module docstring)."""

    def reset(self, env: TrackingEnv) -> None: ...

    def act(self, env: TrackingEnv) -> np.ndarray: ...


class OpenLoop:
    """Zero residual: the reference plus the grip bias, replayed open loop."""

    def reset(self, env: TrackingEnv) -> None:
        pass

    def act(self, env: TrackingEnv) -> np.ndarray:
        return np.zeros(env.action_dim)


@dataclass(frozen=True)
class MPCConfig:
    """Sampling MPC settings (DESIGN.md, "Tracking human demonstrations in physics")."""

    samples: int = 16
    horizon_s: float = 0.2
    replan_s: float = 0.05
    knots: int = 3
    noise: float = 0.02
    """Standard deviation of the sampled actions (residual units per frame)."""
    noise_wrist_rot: float = 0.02
    noise_finger: float = 0.03
    elite_frac: float = 0.25
    min_gain: float = 0.01
    """A new plan replaces the current one only if some sample's return beats it by more than
    this per planned frame (otherwise sampling noise would random-walk the residual)."""
    temperature: float = 0.05
    """Softmax temperature [reward per planned frame]: samples whose returns differ by less
    than this per frame are averaged rather than chosen between (sampling noise)."""
    seed: int = 0


class SamplingMPC:
    """Predictive sampling over residual action knots, scored by rollouts of the real scene.

    Every ``replan_s``: perturb the current plan's knots with Gaussian noise (sample 0 keeps
    the plan unchanged, sample 1 returns to the reference), roll all samples out for
    ``horizon_s`` with ``mujoco.rollout`` from the exact current physics state, and, if some
    sample beats the current plan by more than ``min_gain`` per frame, replace the plan by the
    softmax-weighted mean of the best ``elite_frac`` samples. Deterministic for a given seed.
    """

    def __init__(self, cfg: MPCConfig | None = None):
        self.cfg = MPCConfig() if cfg is None else cfg
        if self.cfg.samples < 2 or self.cfg.knots < 1:
            raise ValidationError("MPC needs at least 2 samples and 1 knot", field="mpc")
        self.rollout_steps = 0

    def reset(self, env: TrackingEnv) -> None:
        c = self.cfg
        self.H = max(2, round(c.horizon_s * env.ref.fps))
        self.replan = max(1, round(c.replan_s * env.ref.fps))
        self.plan = np.zeros((self.H, env.action_dim))
        self.plan_t = env.t
        self.rng = np.random.default_rng(c.seed)
        self.sigma = np.array(
            [c.noise] * 3 + [c.noise_wrist_rot] * 3 + [c.noise_finger] * (env.action_dim - 6)
        )
        knot_t = np.linspace(0, self.H - 1, c.knots) if c.knots > 1 else np.zeros(1)
        # (H, knots) linear interpolation weights
        self.interp = np.stack(
            [np.interp(np.arange(self.H), knot_t, np.eye(c.knots)[k]) for k in range(c.knots)],
            axis=1,
        )
        self.rollout_steps = 0

    def act(self, env: TrackingEnv) -> np.ndarray:
        k = env.t - self.plan_t
        if k >= self.replan or env.t == self.plan_t:
            self._replan(env, shift=k)
            k = 0
        return self.plan[k]

    def _replan(self, env: TrackingEnv, shift: int) -> None:
        c = self.cfg
        nominal = np.zeros_like(self.plan)
        if shift < self.H:
            nominal[: self.H - shift] = self.plan[shift:]
        eps = self.rng.standard_normal((c.samples, c.knots, env.action_dim)) * self.sigma
        eps[:2] = 0.0
        actions = nominal[None] + np.einsum("hk,nka->nha", self.interp, eps)
        # sample 1: return to the reference at once (u = 0 from the next frame on)
        actions[1] = 0.0
        actions[1, 0] = -env.cfg.tau * env.u
        poses, tips = env.rollout_object_poses(actions)
        self.rollout_steps += actions.shape[0] * actions.shape[1] * env.scene.substeps
        ret = env.rewards(poses, tips, actions).sum(axis=1)
        self.last_returns = ret
        if ret.max() - ret[0] <= c.min_gain * self.H:
            self.plan = actions[0]  # nothing is clearly better: keep the plan (no drift)
        else:
            n_elite = max(1, round(c.elite_frac * c.samples))
            elite = np.argsort(-ret)[:n_elite]
            w = np.exp((ret[elite] - ret[elite].max()) / (c.temperature * self.H))
            w /= w.sum()
            self.plan = np.einsum("n,nha->ha", w, actions[elite])
        self.plan_t = env.t


def track(env: TrackingEnv, tracker: ResidualTracker, progress=None) -> TrackLog:
    """Run ``tracker`` on ``env`` from its reset state until the end or the first failure."""
    env.reset()
    tracker.reset(env)
    while not env.done:
        env.step(tracker.act(env))
        if progress is not None:
            progress(1)
    return env.log
