"""The model-quality probe (issue #34): the AUROC helper, chance levels of a flat energy, a learned energy, the callback."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3.common.logger import KVWriter, Logger

import envs  # noqa: F401
from ebm_agent import EBMPlannerAgent, collect_random_transitions
from ebm_agent.callbacks import ModelProbeCallback
from ebm_agent.probe import auroc, can_label_feasibility, feasibility_auroc, label_moves, next_state_rank
from envs.maze import maze_valid


def flat_energy(states: torch.Tensor, next_states: torch.Tensor) -> torch.Tensor:
    return torch.zeros(states.shape[:-1])


def wall_oracle(states: torch.Tensor, next_states: torch.Tensor) -> torch.Tensor:
    """1 where s' is not a free maze point, else 0: the energy of a model that knows the walls exactly."""
    return torch.as_tensor(1.0 - maze_valid(next_states.numpy()).astype(np.float32))


def brute_force_auroc(scores: np.ndarray, labels: np.ndarray) -> float:
    positives, negatives = scores[labels], scores[~labels]
    wins = (positives[:, None] > negatives[None, :]).sum() + 0.5 * (positives[:, None] == negatives[None, :]).sum()
    return float(wins / (len(positives) * len(negatives)))


@pytest.mark.parametrize(
    ("scores", "labels", "expected"),
    [
        ([0.1, 0.4, 0.35, 0.8], [0, 0, 1, 1], 0.75),
        ([1.0, 2.0, 3.0], [0, 1, 1], 1.0),
        ([3.0, 2.0, 1.0], [0, 1, 1], 0.0),
        ([5.0, 5.0, 5.0, 5.0], [0, 1, 0, 1], 0.5),  # all tied
        ([0.0, 1.0, 1.0, 2.0], [0, 0, 1, 1], 0.875),  # one positive-negative tie counts one half
    ],
)
def test_auroc_known_cases(scores, labels, expected):
    assert auroc(np.array(scores), np.array(labels)) == pytest.approx(expected)


def test_auroc_matches_pairwise_counting_with_many_ties():
    rng = np.random.default_rng(0)
    scores = rng.integers(0, 5, size=300).astype(float)  # heavy ties
    labels = rng.random(300) < 0.3
    assert auroc(scores, labels) == pytest.approx(brute_force_auroc(scores, labels))


def test_auroc_is_nan_with_a_single_class():
    assert np.isnan(auroc(np.array([1.0, 2.0]), np.array([True, True])))


def test_moves_are_labelled_by_the_env():
    env = gym.make("ebm/Maze-v0")
    states = np.array([[-0.85, -0.85], [-0.52, -0.8], [-0.7, -0.97], [-0.3, 0.5]], dtype=np.float32)
    next_states = np.array([[-0.8, -0.8], [-0.47, -0.8], [-0.7, -1.0], [-0.25, 0.5]], dtype=np.float32)
    # free move, into the first wall, out of the box, free move above the wall
    assert label_moves(env, states, next_states).tolist() == [True, False, False, True]
    assert can_label_feasibility(env)
    assert can_label_feasibility(gym.make("ebm/Particle-v0", obstacle=(-0.2, -0.2, 0.2, 0.2)))
    assert not can_label_feasibility(gym.make("ebm/Reacher-v0"))


def test_flat_energy_scores_chance_and_the_wall_oracle_scores_one():
    env = gym.make("ebm/Maze-v0")
    flat = feasibility_auroc(flat_energy, env, n_moves=2000, seed=0)
    assert flat.auroc == 0.5 and flat.num_infeasible > 20 and flat.num_feasible > 1000
    assert feasibility_auroc(wall_oracle, env, n_moves=2000, seed=0).auroc == 1.0
    # Same seed, same states and moves: the probe is deterministic.
    again = feasibility_auroc(flat_energy, env, n_moves=2000, seed=0)
    assert (again.num_feasible, again.num_infeasible) == (flat.num_feasible, flat.num_infeasible)
    held_out = collect_random_transitions(gym.make("ebm/Maze-v0"), 300, seed=1)
    rank = next_state_rank(flat_energy, held_out, n_candidates=64, seed=0)
    assert rank.top1 == pytest.approx(1 / 65) and rank.chance == pytest.approx(1 / 65)
    assert rank.mean_rank == pytest.approx(0.5)


def test_probe_of_a_short_pretraining_clears_what_a_flat_energy_cannot():
    """Tiny maze dataset (3,000 random transitions from the corner by the start, 30-step episodes), 10 epochs.

    The AUROC is taken near the data, where the infeasible moves leave the box; a flat energy gets exactly 0.5. The
    next-state mean rank (0.5 for a flat energy) checks that pretraining taught the energy how far a step goes.
    """
    env = gym.make("ebm/Maze-v0", start=(-0.93, -0.93), max_episode_steps=30)
    data = collect_random_transitions(env, 3000, seed=0)
    held_out = collect_random_transitions(env, 500, seed=1)
    agent = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Maze-v0"), seed=0, image_log_interval=0, device="cpu")
    untrained_rank = next_state_rank(agent, held_out, n_candidates=64, scale=2.0, seed=0).mean_rank
    agent.learn_offline(data, epochs=10, log_interval=0)
    feasibility = feasibility_auroc(agent, env, n_moves=1000, near=data.states, seed=0)
    flat = feasibility_auroc(flat_energy, env, n_moves=1000, near=data.states, seed=0)
    assert flat.auroc == 0.5
    assert feasibility.auroc > 0.65, feasibility
    rank = next_state_rank(agent, held_out, n_candidates=64, scale=2.0, seed=0)
    assert rank.mean_rank < 0.35 < untrained_rank, (rank, untrained_rank)


class _Recorder(KVWriter):
    def __init__(self) -> None:
        self.records: list[dict[str, Any]] = []

    def write(self, key_values: dict[str, Any], key_excluded: dict[str, Any], step: int = 0) -> None:
        self.records.append(dict(key_values))


def test_callback_logs_the_probe_keys_during_learn_and_changes_nothing():
    def trained(callback: ModelProbeCallback | None) -> EBMPlannerAgent:
        agent = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Maze-v0"), seed=0, image_log_interval=0, device="cpu")
        recorder = _Recorder()
        agent.set_logger(Logger(folder=None, output_formats=[recorder]))
        agent.learn(total_timesteps=40, callback=callback)
        agent.recorded = recorder.records  # type: ignore[attr-defined]
        return agent

    callback = ModelProbeCallback(gym.make("ebm/Maze-v0"), every=20, n_moves=300, n_transitions=100)
    probed, plain = trained(callback), trained(None)
    logged = {key for record in probed.recorded for key in record}  # type: ignore[attr-defined]
    expected = {"probe/next_state_rank", "probe/next_state_mean_rank", "probe/feasibility_auroc"}
    assert expected | {"probe/feasibility_auroc_uniform"} <= logged
    assert callback.num_probes == 2 and callback.last_feasibility is not None
    for probed_weight, plain_weight in zip(probed.energy_model.parameters(), plain.energy_model.parameters(), strict=True):
        assert torch.equal(probed_weight, plain_weight)


class _WallAtZero(torch.nn.Module):
    """E = 1 for a move that crosses x = 0, else 0 (a stand-in energy that knows one wall)."""

    def __init__(self) -> None:
        super().__init__()
        self.unused = torch.nn.Parameter(torch.zeros(()))  # a parameter, for the device

    def forward(self, states: torch.Tensor, next_states: torch.Tensor) -> torch.Tensor:
        return (torch.sign(states[..., 0]) != torch.sign(next_states[..., 0])).float()  # [...]


def test_the_move_energy_map_is_high_beside_a_wall_the_energy_knows_and_low_in_the_open():
    from ebm_agent.visualize import energy_maps_figure, move_energy_map

    low, high, step = np.array([-1.0, -1.0]), np.array([1.0, 1.0]), np.array([0.05, 0.05])
    values = move_energy_map(_WallAtZero(), low, high, step, resolution=41)  # cells 0.05 apart, x = 0 in column 20
    assert values.shape == (41, 41)
    assert np.all(values[:, 19:22] == 1.0)  # beside the wall some move crosses it
    assert np.all(values[:, :18] == 0.0) and np.all(values[:, 23:] == 0.0)  # in the open none does
    figure = energy_maps_figure(_WallAtZero(), low, high, step, resolution=16)
    assert len(figure.axes) == 4  # two panels and their colour bars
    import matplotlib.pyplot as plt

    plt.close(figure)


def test_the_probe_cli_draws_the_maps_of_a_saved_agent(tmp_path):
    from ebm_agent.probe import main

    env = gym.make("ebm/Maze-v0")
    agent = EBMPlannerAgent("MultiInputPolicy", env, seed=0)
    agent.save(tmp_path / "model.zip")
    path = tmp_path / "maps.png"
    main([str(tmp_path / "model.zip"), "ebm/Maze-v0", "--moves", "50", "--transitions", "50", "--map", str(path)])
    assert path.stat().st_size > 1000
    reacher = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Reacher-v0"), seed=0)
    reacher.save(tmp_path / "reacher.zip")
    with pytest.raises(ValueError, match="2-D state spaces"):
        main([str(tmp_path / "reacher.zip"), "ebm/Reacher-v0", "--moves", "10", "--transitions", "10", "--map", str(path)])
