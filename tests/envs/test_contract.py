"""The environment contract of ``envs/__init__.py``, checked on every registered id (what the agents rely on)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs

ENV_IDS = sorted(envs.ENV_IDS.values())
NUM_STEPS = 8


@pytest.fixture(params=ENV_IDS)
def env(request):
    # The "module:id" form imports the package first, as a third-party CLI would.
    environment = gym.make("envs:" + request.param)
    yield environment.unwrapped
    environment.close()


def test_resolve_env_id_maps_short_names():
    for short, env_id in envs.ENV_IDS.items():
        assert envs.resolve_env_id(short) == env_id
        assert envs.resolve_env_id(short.upper()) == env_id
    assert envs.resolve_env_id("CartPole-v1") == "CartPole-v1"


def test_spaces_and_attributes_are_consistent(env):
    obs_space = env.observation_space
    assert isinstance(obs_space, gym.spaces.Dict)
    assert {"observation", "achieved_goal", "desired_goal"} <= set(obs_space.spaces)
    (state_dim,) = obs_space["observation"].shape
    (goal_dim,) = obs_space["achieved_goal"].shape
    assert obs_space["desired_goal"].shape == (goal_dim,)
    assert isinstance(env.action_space, gym.spaces.Box) and np.all(np.isfinite(env.action_space.low))

    goal_indices = np.asarray(env.goal_indices)
    target_indices = np.asarray(env.target_indices)
    assert goal_indices.dtype.kind == "i" and goal_indices.shape == (goal_dim,)
    assert np.all((goal_indices >= 0) & (goal_indices < state_dim))
    assert target_indices.dtype.kind == "i" and target_indices.ndim == 1
    assert np.all((target_indices >= 0) & (target_indices < state_dim))
    assert not set(target_indices.tolist()) & set(goal_indices.tolist())
    assert env.goal_period is None or (isinstance(env.goal_period, float) and env.goal_period > 0)
    assert (env.state_low is None) == (env.state_high is None)
    if env.state_low is not None:
        assert np.shape(env.state_low) == (state_dim,) and np.shape(env.state_high) == (state_dim,)
        assert np.all(np.asarray(env.state_low) < np.asarray(env.state_high))


def test_rollout_follows_the_contract(env):
    obs, _ = env.reset(seed=0)
    env.action_space.seed(0)
    goal_indices = np.asarray(env.goal_indices)
    states, achieved, desired, rewards, infos = [obs["observation"]], [], [], [], []
    for _ in range(NUM_STEPS):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert obs in env.observation_space
        np.testing.assert_array_equal(obs["achieved_goal"], obs["observation"][goal_indices])
        assert "is_success" in info
        states.append(obs["observation"])
        achieved.append(obs["achieved_goal"])
        desired.append(obs["desired_goal"])
        rewards.append(reward)
        infos.append(info)
        if terminated or truncated:
            break

    batched = env.compute_reward(np.stack(achieved), np.stack(desired), np.array(infos))
    assert np.shape(batched) == (len(rewards),)
    np.testing.assert_allclose(batched, rewards, rtol=1e-6, atol=1e-6)
    single = env.compute_reward(achieved[0], desired[0], infos[0])
    assert float(single) == pytest.approx(rewards[0], rel=1e-6, abs=1e-6)

    states = np.stack(states)  # [T+1, D]
    actions = np.asarray(env.inverse_dynamics(states[:-1], states[1:]))
    assert actions.shape == (len(states) - 1, *env.action_space.shape)
    assert np.all(np.isfinite(actions))
    assert np.all(actions >= env.action_space.low - 1e-6) and np.all(actions <= env.action_space.high + 1e-6)
