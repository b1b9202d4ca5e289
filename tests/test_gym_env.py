"""The Gymnasium tracking environment (retarget.gym_env): the Gymnasium checker, seeded
determinism, vector environments, the zero action as the open-loop replay, termination."""

import runpy
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from retarget.errors import RetargetError
from retarget.gym_env import ENV_ID, RobotTrackingEnv, tracking_task
from retarget.refine import RefineConfig, refine

# the grasp and the start of the lift of the built-in cube2/tripod demonstration (50 frames)
SLICE = {"pair": "cube2/tripod", "hand": "allegro", "start": 290, "max_frames": 50}


@pytest.fixture(scope="module")
def env():
    return RobotTrackingEnv(**SLICE)


def rollout(env, actions, seed=0):
    obs, info = env.reset(seed=seed)
    out = {"obs": [obs], "reward": [], "pos_err": [info["object_pos_err_m"]]}
    for a in actions:
        obs, r, terminated, truncated, info = env.step(a)
        out["obs"].append(obs)
        out["reward"].append(r)
        out["pos_err"].append(info["object_pos_err_m"])
        if terminated or truncated:
            break
    return out, terminated, truncated, info


def test_check_env(env):
    check_env(env, skip_render_check=True)
    assert env.action_space.shape == (6 + len(env.task.tip_sites),)
    assert env.observation_space.shape == env.reset(seed=0)[0].shape


def test_seeded_determinism(env):
    actions = np.random.default_rng(3).uniform(-0.3, 0.3, (20, env.action_space.shape[0]))
    a, *_ = rollout(env, actions, seed=7)
    b, *_ = rollout(env, actions, seed=7)
    np.testing.assert_array_equal(np.stack(a["obs"]), np.stack(b["obs"]))
    np.testing.assert_array_equal(a["reward"], b["reward"])


def test_zero_action_is_the_open_loop_replay(env):
    zeros = np.zeros((env.num_frames, env.action_space.shape[0]), dtype=np.float32)
    out, terminated, truncated, info = rollout(env, zeros)
    assert truncated and not terminated and info["success"]
    assert info["frame"] == env.num_frames - 1
    t = env.task
    cfg = RefineConfig(tracker="open_loop", contact_timeconst=t.refine.contact_timeconst)
    ref = refine(t.hand, t.geometry, t.human, t.robot, list(t.tip_sites), cfg)
    np.testing.assert_allclose(out["pos_err"], ref.object_pos_err, atol=1e-9)


def test_losing_the_object_terminates(env):
    n = env.action_space.shape[0]
    open_hand = np.r_[np.zeros(6), -np.ones(n - 6)].astype(np.float32)  # fingers off the cube
    out, terminated, truncated, info = rollout(env, [open_hand] * env.num_frames)
    assert terminated and not truncated and not info["success"]
    assert info["failed_at"] == info["frame"] < env.num_frames - 1
    assert info["object_pos_err_m"] > 0.05
    assert out["reward"][-1] == -1.0


def test_registered_and_vectorised():
    assert ENV_ID in gymnasium.registry
    single = gymnasium.make(f"retarget.gym_env:{ENV_ID}", **SLICE)
    assert single.spec.id == ENV_ID
    envs = gymnasium.make_vec(ENV_ID, num_envs=2, vectorization_mode="sync", **SLICE)
    try:
        obs, _ = envs.reset(seed=0)
        assert obs.shape == (2, *single.observation_space.shape)
        np.testing.assert_array_equal(obs[0], obs[1])  # one demonstration, two copies
        a = np.zeros((2, single.action_space.shape[0]), dtype=np.float32)
        a[1, 6:] = -1.0
        for _ in range(5):
            obs, r, terminated, truncated, _ = envs.step(a)
        assert r.shape == (2,) and not terminated.any() and not truncated.any()
        assert r[0] != r[1]
    finally:
        envs.close()
        single.close()


def test_retargeting_cached_once():
    assert tracking_task(**SLICE) is tracking_task(**SLICE)
    with pytest.raises(RetargetError, match="at least 2"):
        RobotTrackingEnv(**{**SLICE, "start": 10_000})


def test_training_example_runs(capsys):
    example = Path(__file__).parents[1] / "examples" / "train_tracking.py"
    main = runpy.run_path(str(example))["main"]
    main(["--start", "290", "--frames", "40", "--timesteps", "256", "--envs", "1"])
    out = capsys.readouterr().out
    assert "open loop (zero residual)" in out and "PPO" in out
