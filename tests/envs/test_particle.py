"""Tests of the particle environment: checkers, exact dynamics, the paper's optimum, the obstacle, seeding, rendering."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import envs  # noqa: F401  (registers the ids)
from envs.particle import ParticleEnv
from envs.rendering import draw_paths

PARTICLE_ID = "ebm/Particle-v0"
OBSTACLE = (0.1, 0.1, 0.4, 0.4)


def make_unwrapped(**kwargs) -> ParticleEnv:
    env = gym.make(PARTICLE_ID, **kwargs).unwrapped
    assert isinstance(env, ParticleEnv)
    return env


@pytest.mark.parametrize("kwargs", [{}, {"start": (0.0, 0.0)}, {"obstacle": OBSTACLE, "start": None, "goal": None}])
def test_env_checkers_pass(kwargs):
    gym_check_env(gym.make(PARTICLE_ID, render_mode="rgb_array", **kwargs).unwrapped)
    sb3_check_env(gym.make(PARTICLE_ID, **kwargs).unwrapped, warn=True)


def test_spaces_and_contract_attributes():
    env = make_unwrapped()
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    for key in ("observation", "achieved_goal", "desired_goal"):
        assert env.observation_space[key].shape == (2,)
        assert env.observation_space[key].dtype == np.float32
    np.testing.assert_array_equal(env.goal_indices, [0, 1])
    assert env.target_indices.size == 0 and env.target_indices.dtype.kind == "i"
    assert env.goal_period is None
    np.testing.assert_array_equal(env.state_low, [-1, -1])
    np.testing.assert_array_equal(env.state_high, [1, 1])
    assert env.obstacle is None


def test_optimal_diagonal_policy_scores_minus_4_5():
    env = make_unwrapped(start=(0.0, 0.0), goal=(0.5, 0.5))
    obs, _ = env.reset(seed=0)
    np.testing.assert_array_equal(obs["observation"], [0.0, 0.0])
    total, steps, terminated, info = 0.0, 0, False, {}
    while not terminated:
        obs, reward, terminated, truncated, info = env.step(np.ones(2, dtype=np.float32))
        total += reward
        steps += 1
        assert not truncated and steps <= 10
    assert steps == 10
    assert total == pytest.approx(-4.5, abs=1e-6)
    assert info["is_success"] == 1.0


def test_large_actions_are_rescaled_not_clipped():
    env = make_unwrapped(start=(0.0, 0.0))
    env.reset(seed=0)
    obs, *_ = env.step(np.array([4.0, 1.0]))  # L-inf 4 -> (1, 0.25) -> move (0.05, 0.0125)
    np.testing.assert_allclose(obs["observation"], [0.05, 0.0125], atol=1e-7)


def test_state_is_clipped_to_the_box():
    env = make_unwrapped(start=(0.98, -0.99))
    env.reset(seed=0)
    obs, _, _, _, info = env.step(np.array([1.0, -1.0], dtype=np.float32))
    np.testing.assert_array_equal(obs["observation"], [1.0, -1.0])
    assert info["rejected"] is False


def test_inverse_dynamics_round_trip_is_exact():
    env = make_unwrapped(start=None, goal=None)
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    states = rng.uniform(-0.95, 0.95, size=(256, 2)).astype(np.float32)
    next_states = (states + rng.uniform(-0.05, 0.05, size=(256, 2))).astype(np.float32)
    actions = env.inverse_dynamics(states, next_states)
    assert actions.shape == (256, 2) and actions.dtype == np.float32
    assert np.all(np.abs(actions) <= 1.0)
    for state, next_state, action in zip(states, next_states, actions):
        env.reset(options={"start": state})
        obs, *_ = env.step(action)
        np.testing.assert_allclose(obs["observation"], next_state, rtol=0, atol=1e-6)
    # Un-batched input gives an un-batched action; the batched forward model agrees with step.
    assert env.inverse_dynamics(states[0], next_states[0]).shape == (2,)
    np.testing.assert_allclose(env.forward_dynamics(states, actions), next_states, rtol=0, atol=1e-6)


def test_inverse_dynamics_rejects_bad_shapes():
    env = make_unwrapped()
    with pytest.raises(ValueError, match="same shape"):
        env.inverse_dynamics(np.zeros((3, 2)), np.zeros((4, 2)))
    with pytest.raises(ValueError, match="same shape"):
        env.inverse_dynamics(np.zeros(3), np.zeros(3))


def test_reward_accounting_and_compute_reward_batched():
    env = make_unwrapped(start=None, goal=None)
    obs, _ = env.reset(seed=7)
    env.action_space.seed(7)
    achieved, desired, rewards, infos = [], [], [], []
    for _ in range(30):
        obs, reward, terminated, _, info = env.step(env.action_space.sample())
        l1 = float(np.abs(obs["achieved_goal"].astype(np.float64) - obs["desired_goal"]).sum())
        assert reward == pytest.approx(-l1, abs=1e-12)
        assert info["is_success"] == float(l1 < 0.01) == float(terminated)
        achieved.append(obs["achieved_goal"])
        desired.append(obs["desired_goal"])
        rewards.append(reward)
        infos.append(info)
    batched = env.compute_reward(np.stack(achieved), np.stack(desired), np.array(infos))
    assert batched.shape == (30,)
    np.testing.assert_array_equal(batched, rewards)  # exact: the same arithmetic as step
    assert np.sum(rewards) == pytest.approx(-sum(info["distance"] for info in infos))
    assert env.compute_terminated(np.stack(achieved), np.stack(desired), None).shape == (30,)
    assert not env.compute_truncated(np.stack(achieved), np.stack(desired), None).any()
    single = env.compute_reward(achieved[0], desired[0], infos[0])
    assert np.ndim(single) == 0 and single == rewards[0]


def rollout(env: ParticleEnv, seed: int, steps: int = 20) -> np.ndarray:
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    positions = [obs["observation"]]
    for _ in range(steps):
        obs, *_ = env.step(env.action_space.sample())
        positions.append(obs["observation"])
    return np.stack(positions)


def test_same_seed_same_trajectory_different_seed_differs():
    env = make_unwrapped(start=None, goal=None)
    first, again, other = rollout(env, 11), rollout(env, 11), rollout(env, 12)
    np.testing.assert_array_equal(first, again)
    assert not np.allclose(first[0], other[0])  # the random start differs
    assert not np.allclose(first, other)


def test_reset_options_override_start_and_goal_and_reject_unknown():
    env = make_unwrapped()
    obs, _ = env.reset(seed=0, options={"start": (0.2, -0.3), "goal": (-0.5, 0.25)})
    np.testing.assert_allclose(obs["observation"], [0.2, -0.3], atol=1e-7)
    np.testing.assert_allclose(obs["desired_goal"], [-0.5, 0.25], atol=1e-7)
    with pytest.raises(ValueError, match="unknown reset options"):
        env.reset(options={"target": (0, 0)})


def test_obstacle_rejects_moves_that_touch_it_and_allows_moves_past_it():
    env = make_unwrapped(start=(0.0, 0.0), goal=(0.5, 0.5), obstacle=OBSTACLE)
    np.testing.assert_array_equal(env.obstacle, OBSTACLE)
    env.reset(seed=0, options={"start": (0.08, 0.2)})
    obs, _, _, _, info = env.step(np.array([1.0, 0.0], dtype=np.float32))  # x 0.08 -> 0.13 enters the box
    np.testing.assert_allclose(obs["observation"], [0.08, 0.2], atol=1e-7)
    assert info["rejected"] is True
    env.reset(seed=0, options={"start": (0.06, 0.2)})
    obs, _, _, _, info = env.step(np.array([0.8, 0.0], dtype=np.float32))  # 0.06 -> 0.10: touching counts
    assert info["rejected"] is True
    env.reset(seed=0, options={"start": (0.0, 0.2)})
    obs, _, _, _, info = env.step(np.array([1.0, 0.0], dtype=np.float32))  # 0.0 -> 0.05 stays clear
    np.testing.assert_allclose(obs["observation"], [0.05, 0.2], atol=1e-7)
    assert info["rejected"] is False
    env.reset(seed=0, options={"start": (0.08, 0.42)})
    obs, _, _, _, info = env.step(np.array([1.0, 1.0], dtype=np.float32))  # passes above the box's top edge
    np.testing.assert_allclose(obs["observation"], [0.13, 0.47], atol=1e-7)
    assert info["rejected"] is False
    # A diagonal move whose segment box clips the corner is rejected even though both end points are outside.
    env.reset(seed=0, options={"start": (0.07, 0.43)})
    obs, _, _, _, info = env.step(np.array([1.0, -1.0], dtype=np.float32))  # -> (0.12, 0.38), inside
    assert info["rejected"] is True


def test_obstacle_touching_exactly_at_the_edge_is_a_collision():
    # Dyadic numbers: 7/32 + (0.625 / 20 = 1/32) lands exactly on xmin = 0.25, with no rounding anywhere.
    env = make_unwrapped(start=(0.0, 0.0), goal=(0.9, 0.9), obstacle=(0.25, -0.5, 0.5, 0.0))
    env.reset(seed=0, options={"start": (0.21875, -0.25)})
    obs, _, _, _, info = env.step(np.array([0.625, 0.0], dtype=np.float32))
    assert info["rejected"] is True
    np.testing.assert_array_equal(obs["observation"], [0.21875, -0.25])
    env.reset(seed=0, options={"start": (0.1875, -0.25)})
    obs, _, _, _, info = env.step(np.array([0.625, 0.0], dtype=np.float32))  # ends at 0.21875, short of the box
    assert info["rejected"] is False
    np.testing.assert_array_equal(obs["observation"], [0.21875, -0.25])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"obstacle": (0.4, 0.1, 0.1, 0.4)}, "degenerate"),
        ({"obstacle": (0.1, 0.3, 0.4, 0.3)}, "degenerate"),
        ({"obstacle": (0.1, 0.1, 0.5, 0.5)}, "goal"),  # the original default box touches the goal corner
        ({"obstacle": (-0.1, -0.1, 0.1, 0.1), "start": (0.0, 0.0)}, "start"),
        ({"obstacle": (1.2, 1.2, 1.5, 1.5)}, "outside"),
        ({"obstacle": (-2.0, -2.0, 2.0, 2.0), "start": None, "goal": None}, "whole state box"),
        ({"obstacle": (0.1, 0.1, 0.4)}, "finite box"),
    ],
)
def test_invalid_obstacles_raise_with_the_box_in_the_message(kwargs, message):
    with pytest.raises(ValueError, match=message) as error:
        ParticleEnv(**kwargs)
    box = kwargs["obstacle"]
    if len(box) == 4:
        assert "(" + ", ".join(f"{v:g}" for v in box) + ")" in str(error.value)


def test_random_start_and_goal_avoid_the_obstacle():
    env = make_unwrapped(start=None, goal=None, obstacle=(-0.9, -0.9, 0.9, 0.9))  # only a thin border is free
    for seed in range(20):
        obs, _ = env.reset(seed=seed)
        for key in ("observation", "desired_goal"):
            assert np.abs(obs[key]).max() > 0.9


@pytest.mark.parametrize("bad", [{"start": (2.0, 0.0)}, {"goal": (0.0, np.nan)}, {"success_threshold": 0.0}])
def test_bad_constructor_arguments_raise(bad):
    with pytest.raises(ValueError):
        ParticleEnv(**bad)


def test_bad_actions_raise():
    env = make_unwrapped()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan, 0.0]))


def test_render_shape_dtype_and_content():
    env = make_unwrapped(start=(-0.5, -0.5), goal=(0.5, 0.5), obstacle=OBSTACLE, render_mode="rgb_array", render_size=64)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (64, 64, 3) and frame.dtype == np.uint8
    np.testing.assert_array_equal(frame[24, 40], [70, 70, 80])  # world (0.25, 0.25) lies in the obstacle
    np.testing.assert_array_equal(frame[5, 5], [255, 255, 255])  # world (-0.83, 0.83) is free
    background = env.render_background()
    assert not np.array_equal(frame, background)  # goal and particle drawn on top
    with_plans = draw_paths(frame, np.array([[[-0.5, -0.5], [0.5, 0.5]]]), color=(255, 0, 0))
    assert with_plans.shape == frame.shape and (with_plans != frame).any()
    assert make_unwrapped().render() is None
