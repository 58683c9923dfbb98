"""The exploration measures of ebm_agent.exploration: grid occupancy on scripted paths, the visited-states callback
against the random agent's own record, the energy-map snapshots of an untrained model."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.env_util import make_vec_env

import envs  # noqa: F401
from baselines.random_agent import RandomAgent
from ebm_agent import EBMPlannerAgent, MPPIConfig
from ebm_agent.exploration import (
    EnergyMapCallback,
    VisitedStatesCallback,
    count_occupied_cells,
    grid_counts,
    grid_coverage,
    linear_checkpoints,
    log_checkpoints,
)

SMALL_PLANNER = MPPIConfig(iterations=2, num_samples=8)


def test_grid_counts_and_coverage_on_a_scripted_maze_path():
    row = np.stack([np.linspace(-0.95, 0.95, 20), np.full(20, -0.95)], axis=1)  # the centre of each bottom-row cell
    assert grid_coverage(np.concatenate([row, row])) == pytest.approx(20 / 400)
    counts = grid_counts(np.array([[0.95, -0.95], [0.95, -0.95], [-0.95, 0.95]]))
    assert counts.shape == (20, 20) and counts.sum() == 3
    assert counts[0, 19] == 2 and counts[19, 0] == 1  # row index is y, column index is x


def test_count_occupied_cells_refuses_bad_grids():
    with pytest.raises(ValueError, match="states must be"):
        count_occupied_cells(np.zeros(3), 4, -1.0, 1.0)
    with pytest.raises(ValueError, match="bins"):
        count_occupied_cells(np.zeros((2, 2)), 0, -1.0, 1.0)
    with pytest.raises(ValueError, match="high must exceed low"):
        count_occupied_cells(np.zeros((2, 2)), 4, 1.0, 1.0)
    assert count_occupied_cells(np.array([[1.0, 1.0], [0.99, 0.99]]), 2, -1.0, 1.0) == 1  # the upper face is inside


def test_checkpoints_are_sorted_distinct_and_end_at_the_budget():
    assert linear_checkpoints(100, 4) == [25, 50, 75, 100]
    assert linear_checkpoints(3, 10) == [1, 2, 3]
    points = log_checkpoints(10_000, 5)
    assert points[0] == 10 and points[-1] == 10_000 and points == sorted(set(points))


def test_visited_states_callback_matches_the_random_agent_record_across_episode_ends():
    env = make_vec_env("ebm/Particle-v0", n_envs=2, seed=0, env_kwargs={"max_episode_steps": 7})
    agent = RandomAgent("MultiInputPolicy", env, seed=0)
    measure = lambda states: count_occupied_cells(states, 20, -1.0, 1.0)  # noqa: E731
    callback = VisitedStatesCallback([10, 20, 30], measure)
    agent.learn(40, callback=callback)
    assert agent._episode_num >= 4  # episodes ended, so terminal observations were recorded
    np.testing.assert_array_equal(callback.visited_states, agent.visited_states)
    np.testing.assert_array_equal(callback.visited_timesteps, agent.visited_timesteps)
    assert callback.curve_timesteps == [10, 20, 30, 40]
    assert callback.curve_values == [agent.occupancy(20, -1.0, 1.0, until_timestep=t) for t in (10, 20, 30, 40)]


def test_energy_map_callback_snapshots_the_untrained_model_at_zero():
    agent = EBMPlannerAgent(
        "MultiInputPolicy", gym.make("ebm/Particle-v0"), seed=0, image_log_interval=0, planner_config=SMALL_PLANNER
    )
    callback = EnergyMapCallback([0, 8], resolution=8, bins=4)
    agent.learn(16, callback=callback)
    assert [s.timestep for s in callback.snapshots] == [0, 8]
    assert callback.snapshots[0].energies.shape == (8, 8) and callback.snapshots[0].cell_energies.shape == (4, 4)
    assert callback.snapshots[0].visit_counts.sum() == 1  # only the first observation before training
