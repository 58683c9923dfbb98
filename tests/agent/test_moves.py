"""The one running statistics object of the real moves (ebm_agent.moves)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

import envs  # noqa: F401  (registers the envs)
from ebm_agent import EBMPlannerAgent
from ebm_agent.datasets import collect_random_transitions
from ebm_agent.moves import MoveStatistics, state_periods


def test_statistics_accumulate_over_updates_as_over_one_batch() -> None:
    rng = np.random.default_rng(0)
    states = rng.uniform(-1, 1, (300, 3)).astype(np.float32)
    next_states = states + rng.normal(0.0, [0.01, 0.1, 1.0], (300, 3)).astype(np.float32)
    whole = MoveStatistics().update(states, next_states)
    parts = MoveStatistics().update(states[:100], next_states[:100]).update(states[100:], next_states[100:])
    moves = (next_states - states).astype(np.float64)
    assert whole.count == parts.count == 300
    np.testing.assert_allclose(parts.mean, moves.mean(0), atol=1e-12)
    np.testing.assert_allclose(parts.std, moves.std(0) + 1e-6, rtol=1e-9)
    np.testing.assert_array_equal(parts.largest, np.abs(next_states - states).max(0))
    np.testing.assert_array_equal(whole.largest, parts.largest)


def test_periodic_dims_move_the_short_way_round() -> None:
    periods = np.array([2.0, 0.0], np.float32)  # dim 0 an angle in [-1, 1), dim 1 not periodic
    states = np.array([[0.99, 0.5], [-0.99, -0.5]], np.float32)
    next_states = np.array([[-0.99, 0.9], [0.99, -0.9]], np.float32)
    stats = MoveStatistics(periods).update(states, next_states)
    np.testing.assert_allclose(stats.largest, [0.02, 0.4], atol=1e-5)  # not 1.98 on the angle
    np.testing.assert_allclose(MoveStatistics().update(states, next_states).largest, [1.98, 0.4], atol=1e-5)


def test_bad_input_and_empty_statistics_say_what_to_do() -> None:
    stats = MoveStatistics(np.zeros(2, np.float32))
    with pytest.raises(RuntimeError, match="update"):
        _ = stats.largest
    with pytest.raises(RuntimeError, match="update"):
        _ = stats.std
    with pytest.raises(ValueError, match="alike"):
        stats.update(np.zeros((3, 2)), np.zeros((4, 2)))
    with pytest.raises(ValueError, match="periods has 2 dims"):
        stats.update(np.zeros((3, 4)), np.zeros((3, 4)))
    assert stats.update(np.zeros((0, 2)), np.zeros((0, 2))).count == 0


def test_state_periods_follow_the_goal_spec() -> None:
    torch.set_num_threads(1)
    reacher = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Reacher-v0"), seed=0, device="cpu")
    periods = state_periods(reacher.goal_spec, reacher.goal_spec.state_dim)
    assert periods is not None and set(np.flatnonzero(periods)) == set(reacher.goal_spec.goal_indices)
    maze = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Maze-v0"), seed=0, device="cpu")
    assert state_periods(maze.goal_spec, 2) is None


def test_the_agent_records_every_transition_it_learns_from_with_reacher_angles_wrapped() -> None:
    torch.set_num_threads(1)
    env = gym.make("ebm/Reacher-v0")
    agent = EBMPlannerAgent("MultiInputPolicy", env, seed=0, device="cpu")
    with pytest.raises(RuntimeError, match="learn"):
        _ = agent.real_moves
    data = collect_random_transitions(gym.make("ebm/Reacher-v0"), 2000, seed=0)
    agent.learn_offline(data, epochs=0, log_interval=0)
    assert agent.real_moves.count == 2000
    dims = list(agent.goal_spec.goal_indices)
    raw = np.abs(data.next_states - data.states).max(axis=0)[dims]
    wrapped = agent.real_moves.largest[dims]
    assert np.all(raw > 1.9), "the random data crosses the angles' wrap at +-1 (unwrapped, a move of almost 2)"
    assert np.all(wrapped < 0.25), f"wrapped, an angle's largest real move is small, got {wrapped}"
