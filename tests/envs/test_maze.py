"""Tests of the maze environment: wall layout, move rejection, no out-of-box loophole, the lattice optimum."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import envs  # noqa: F401  (registers the ids)
from envs.maze import MAZE_GOAL, MAZE_START, MazeEnv, maze_optimal_path, maze_optimal_score, maze_valid

MAZE_ID = "ebm/Maze-v0"


def make_unwrapped(**kwargs) -> MazeEnv:
    env = gym.make(MAZE_ID, **kwargs).unwrapped
    assert isinstance(env, MazeEnv)
    return env


@pytest.mark.parametrize("kwargs", [{}, {"start": None, "goal": None}])
def test_env_checkers_pass(kwargs):
    gym_check_env(gym.make(MAZE_ID, render_mode="rgb_array", **kwargs).unwrapped)
    sb3_check_env(gym.make(MAZE_ID, **kwargs).unwrapped, warn=True)


@pytest.mark.parametrize(
    ("point", "expected"),
    [
        ((-0.75, -0.9), True),  # column 0 [-1, -0.5): free everywhere
        ((-0.75, 0.9), True),
        ((-0.5, 0.0), False),  # column 1 [-0.5, 0): x = -0.5 already belongs to it
        ((-0.25, 0.25), False),  # free only for y > 0.25, strictly
        ((-0.25, 0.26), True),
        ((-0.01, 0.9), True),
        ((0.0, -0.9), True),  # column 2 [0, 0.5): free everywhere
        ((0.49, 0.9), True),
        ((0.5, 0.0), False),  # column 3 [0.5, 1): free only for y < -0.25, strictly
        ((0.75, -0.25), False),
        ((0.75, -0.26), True),
        ((0.7, -0.8), True),  # the goal
        ((-0.85, -0.85), True),  # the start
        ((0.98, -0.98), True),  # border: |coord| >= 0.99 is a wall
        ((0.99, -0.5), False),
        ((-0.3, 0.99), False),
        ((-0.995, 0.0), False),
        ((0.2, -1.0), False),
        ((np.nan, 0.0), False),
    ],
)
def test_maze_valid_at_hand_picked_points(point, expected):
    assert bool(maze_valid(np.array(point))) is expected


def test_maze_valid_is_vectorised_and_checks_its_input():
    points = np.array([[[-0.75, 0.0], [-0.25, 0.0]], [[0.25, 0.0], [0.75, 0.0]]])  # [2, 2, 2]
    np.testing.assert_array_equal(maze_valid(points), [[True, False], [True, False]])
    assert maze_valid(np.zeros((0, 2))).shape == (0,)
    with pytest.raises(ValueError, match="last axis"):
        maze_valid(np.zeros((4, 3)))


def test_moves_into_walls_are_rejected_and_moves_along_them_accepted():
    env = make_unwrapped()
    env.reset(seed=0, options={"start": (-0.52, 0.0)})
    obs, _, _, _, info = env.step(np.array([1.0, 0.0], dtype=np.float32))  # -> (-0.47, 0.0): column 1 below 0.25
    assert info["rejected"] is True
    np.testing.assert_allclose(obs["observation"], [-0.52, 0.0], atol=1e-7)
    env.reset(seed=0, options={"start": (-0.52, 0.24)})
    obs, _, _, _, info = env.step(np.array([1.0, 1.0], dtype=np.float32))  # -> (-0.47, 0.29): end point free
    assert info["rejected"] is False
    np.testing.assert_allclose(obs["observation"], [-0.47, 0.29], atol=1e-7)
    env.reset(seed=0, options={"start": (0.45, -0.3)})
    obs, _, _, _, info = env.step(np.array([1.0, 0.0], dtype=np.float32))  # into column 3 below -0.25
    assert info["rejected"] is False
    np.testing.assert_allclose(obs["observation"], [0.5, -0.3], atol=1e-7)


def test_leaving_the_box_is_rejected_and_does_not_end_the_episode():
    env = make_unwrapped()
    env.reset(seed=0, options={"start": (-0.96, -0.96)})
    for _ in range(3):
        obs, reward, terminated, truncated, info = env.step(np.array([-1.0, -1.0], dtype=np.float32))
        assert info["rejected"] is True and not terminated and not truncated  # no out-of-bounds loophole
        np.testing.assert_allclose(obs["observation"], [-0.96, -0.96], atol=1e-7)
        assert reward == pytest.approx(-(0.96 + 0.7 + 0.96 - 0.8), abs=1e-6)


def test_invalid_start_or_goal_raises():
    with pytest.raises(ValueError, match="maze wall"):
        MazeEnv(start=(-0.25, 0.0))
    with pytest.raises(ValueError, match="maze wall"):
        MazeEnv(goal=(0.75, 0.5))
    env = make_unwrapped()
    with pytest.raises(ValueError, match="maze wall"):
        env.reset(options={"start": (0.995, 0.0)})


def test_random_start_and_goal_are_valid_and_seeded():
    env = make_unwrapped(start=None, goal=None)
    firsts = []
    for seed in range(10):
        obs, _ = env.reset(seed=seed)
        assert maze_valid(obs["observation"]) and maze_valid(obs["desired_goal"])
        firsts.append(obs["observation"])
    obs, _ = env.reset(seed=0)
    np.testing.assert_array_equal(obs["observation"], firsts[0])
    assert not np.allclose(firsts[0], firsts[1])


def test_random_walk_stays_valid_and_rewards_add_up():
    env = make_unwrapped(start=None, goal=None)
    obs, _ = env.reset(seed=5)
    env.action_space.seed(5)
    rewards, distances, achieved, desired = [], [], [], []
    for _ in range(200):
        obs, reward, _, _, _ = env.step(env.action_space.sample())
        assert maze_valid(obs["observation"])
        rewards.append(reward)
        distances.append(float(np.abs(obs["achieved_goal"].astype(np.float64) - obs["desired_goal"]).sum()))
        achieved.append(obs["achieved_goal"])
        desired.append(obs["desired_goal"])
    assert sum(rewards) == pytest.approx(-sum(distances), abs=1e-9)
    np.testing.assert_array_equal(env.compute_reward(np.stack(achieved), np.stack(desired), None), rewards)


def test_lattice_optimum_and_its_replay_through_the_env():
    # The strict walls give -73.67 in 54 steps; the -71.9 (52 steps) of the original analysis counts y = 0.25 as free.
    score = maze_optimal_score()
    assert score == pytest.approx(-73.67, abs=1e-6)
    path = maze_optimal_path()  # [55, 2]
    assert path.shape == (55, 2)
    np.testing.assert_allclose(path[0], MAZE_START)
    np.testing.assert_allclose(path[-1], MAZE_GOAL)
    assert np.abs(np.diff(path, axis=0)).max() <= 0.05 + 1e-9
    env = make_unwrapped()
    obs, _ = env.reset(seed=0)
    total, terminated, info, steps = 0.0, False, {}, 0
    for waypoint in path[1:]:
        action = env.inverse_dynamics(obs["observation"], waypoint)
        obs, reward, terminated, _, info = env.step(action)
        np.testing.assert_allclose(obs["observation"], waypoint, rtol=0, atol=1e-6)
        total += reward
        steps += 1
        if terminated:
            break
    # The last lattice step may be skipped: one lattice cell from the goal, L1 = 0.01 rounds below the threshold
    # in float32, and that skipped step would have earned 0 anyway.
    assert terminated and info["is_success"] == 1.0 and steps >= len(path) - 2
    assert total == pytest.approx(score, abs=1e-4)


def test_lattice_optimum_on_an_open_column_matches_straight_line():
    # Inside column 2 there are no walls: the particle's optimum from (0, 0) to (0.25, 0.25) is 5 diagonal steps.
    assert maze_optimal_score(start=(0.0, 0.0), goal=(0.25, 0.25)) == pytest.approx(-(0.4 + 0.3 + 0.2 + 0.1))
    with pytest.raises(ValueError, match="spacing"):
        maze_optimal_score(spacing=0.03)
    with pytest.raises(ValueError, match="not a valid maze point"):
        maze_optimal_score(start=(-0.25, 0.0))


def test_inverse_dynamics_round_trip_on_reachable_pairs():
    env = make_unwrapped()
    env.reset(seed=0)
    rng = np.random.default_rng(1)
    states = rng.uniform(-0.98, 0.98, size=(2000, 2)).astype(np.float32)
    states = states[maze_valid(states)][:200]
    next_states = env.forward_dynamics(states, rng.uniform(-1, 1, size=states.shape)).astype(np.float32)
    actions = env.inverse_dynamics(states, next_states)
    np.testing.assert_allclose(env.forward_dynamics(states, actions), next_states, rtol=0, atol=1e-6)


def test_render_draws_walls():
    env = make_unwrapped(render_mode="rgb_array", render_size=64)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (64, 64, 3) and frame.dtype == np.uint8
    np.testing.assert_array_equal(frame[48, 24], [70, 70, 80])  # world (-0.23, -0.52): column 1 wall
    np.testing.assert_array_equal(frame[48, 8], [255, 255, 255])  # world (-0.73, -0.52): column 0 free
