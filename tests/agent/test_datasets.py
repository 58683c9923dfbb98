"""Offline datasets: random collection without cross-episode pairs, .npz round trip, minibatch order."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from ebm_agent.datasets import TransitionDataset, collect_random_transitions, iterate_minibatches


class _TinyGoalEnv(gym.Env):
    """A particle with a step counter in its state: observation = (x, y, t), goal (0.5, 0.5)."""

    def __init__(self) -> None:
        box = spaces.Box(-np.inf, np.inf, (2,), np.float32)
        self.observation_space = spaces.Dict(
            {"observation": spaces.Box(-np.inf, np.inf, (3,), np.float32), "achieved_goal": box, "desired_goal": box}
        )
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self._state = np.zeros(3, dtype=np.float32)

    def _obs(self) -> dict[str, np.ndarray]:
        goal = np.full(2, 0.5, dtype=np.float32)
        return {"observation": self._state.copy(), "achieved_goal": self._state[:2].copy(), "desired_goal": goal}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict, dict]:
        super().reset(seed=seed)
        self._state = np.array([*self.np_random.uniform(-1, 1, 2), 0.0], dtype=np.float32)
        return self._obs(), {}

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        self._state[:2] = np.clip(self._state[:2] + np.asarray(action) / 20, -1, 1)
        self._state[2] += 1
        terminated = bool(np.abs(self._state[:2] - 0.5).sum() < 0.01)
        return self._obs(), -float(np.abs(self._state[:2] - 0.5).sum()), terminated, False, {}


class _ExploringGoalEnv(_TinyGoalEnv):
    def sample_exploration_action(self) -> np.ndarray:
        return np.full(2, 0.25, dtype=np.float32)


def _make_env(cls: type[gym.Env] = _TinyGoalEnv) -> gym.Env:
    return gym.wrappers.TimeLimit(cls(), max_episode_steps=5)


def test_collect_gives_exactly_n_transitions_without_cross_episode_pairs() -> None:
    dataset = collect_random_transitions(_make_env(), num_transitions=23, seed=0)
    assert len(dataset) == 23
    assert dataset.states.shape == (23, 3) and dataset.actions.shape == (23, 2)
    # Every pair is one step of the same episode: the counter advances by exactly one.
    np.testing.assert_array_equal(dataset.next_states[:, 2], dataset.states[:, 2] + 1)
    np.testing.assert_array_equal(dataset.episode_ids, np.repeat(np.arange(5), 5)[:23])
    # Each episode's last transition (t = 4 -> 5) is kept; the next episode restarts at t = 0.
    assert np.all(dataset.states[dataset.episode_ids != np.roll(dataset.episode_ids, 1), 2] == 0)
    # The moves are the actions' / 20 (no teleport through a reset).
    assert np.all(np.abs(dataset.next_states[:, :2] - dataset.states[:, :2]) <= 0.05 + 1e-6)
    assert dataset.info["num_episodes"] == 5 and dataset.info["policy"] == "random"


def test_collect_is_seeded() -> None:
    first = collect_random_transitions(_make_env(), num_transitions=12, seed=4)
    again = collect_random_transitions(_make_env(), num_transitions=12, seed=4)
    other = collect_random_transitions(_make_env(), num_transitions=12, seed=5)
    np.testing.assert_array_equal(first.states, again.states)
    np.testing.assert_array_equal(first.actions, again.actions)
    assert not np.array_equal(first.actions, other.actions)
    assert not np.array_equal(first.states[0], other.states[0])


def test_collect_uses_the_envs_exploration_action() -> None:
    dataset = collect_random_transitions(_make_env(_ExploringGoalEnv), num_transitions=7, seed=0)
    np.testing.assert_array_equal(dataset.actions, np.full((7, 2), 0.25, dtype=np.float32))


def test_collect_from_an_id_with_a_box_observation() -> None:
    dataset = collect_random_transitions("Pendulum-v1", num_transitions=12, seed=0, max_episode_steps=5)
    assert len(dataset) == 12 and dataset.states.shape == (12, 3) and dataset.actions.shape == (12, 1)
    np.testing.assert_array_equal(dataset.episode_ids, [0] * 5 + [1] * 5 + [2] * 2)
    assert dataset.info["env_id"] == "Pendulum-v1"


def test_collect_rejects_bad_arguments() -> None:
    with pytest.raises(ValueError, match="random"):
        collect_random_transitions(_make_env(), num_transitions=5, policy="directed")
    with pytest.raises(ValueError, match="num_transitions"):
        collect_random_transitions(_make_env(), num_transitions=0)


def test_save_load_round_trip(tmp_path: Path) -> None:
    dataset = collect_random_transitions(_make_env(), num_transitions=9, seed=1)
    written = dataset.save(tmp_path / "sub" / "particle")
    assert written == tmp_path / "sub" / "particle.npz" and written.exists()
    assert [p.name for p in written.parent.iterdir()] == ["particle.npz"]  # no temp file left behind
    loaded = TransitionDataset.load(written)
    for key in ("states", "next_states", "actions", "episode_ids"):
        np.testing.assert_array_equal(getattr(loaded, key), getattr(dataset, key))
    assert loaded.info == dataset.info
    dataset.save(written)  # overwriting an existing file is fine
    assert len(TransitionDataset.load(written)) == 9


def test_load_names_missing_arrays(tmp_path: Path) -> None:
    path = tmp_path / "broken.npz"
    np.savez(path, states=np.zeros((2, 2)), next_states=np.zeros((2, 2)))
    with pytest.raises(ValueError, match=r"\['actions', 'episode_ids'\]"):
        TransitionDataset.load(path)


def test_dataset_validates_shapes() -> None:
    with pytest.raises(ValueError, match="actions"):
        TransitionDataset(np.zeros((4, 2)), np.zeros((4, 2)), np.zeros((3, 2)), np.zeros(4))
    with pytest.raises(ValueError, match="next_states"):
        TransitionDataset(np.zeros((4, 2)), np.zeros((4, 3)), np.zeros((4, 2)), np.zeros(4))


def test_shuffled_minibatches_cover_the_dataset_once() -> None:
    batches = list(iterate_minibatches(10, 4, np.random.default_rng(0)))
    assert [len(b) for b in batches] == [4, 4, 2]
    indices = np.concatenate(batches)
    np.testing.assert_array_equal(np.sort(indices), np.arange(10))
    assert not np.array_equal(indices, np.arange(10))
    assert [len(b) for b in iterate_minibatches(10, 4, np.random.default_rng(0), drop_last=True)] == [4, 4]


def test_sequential_minibatches_are_contiguous_chunks_in_shuffled_order() -> None:
    dataset = TransitionDataset(np.zeros((103, 2)), np.zeros((103, 2)), np.zeros((103, 1)), np.zeros(103))
    batches = list(iterate_minibatches(dataset, 10, np.random.default_rng(0), sequential=True))
    assert len(batches) == 11
    for batch in batches:
        np.testing.assert_array_equal(batch, np.arange(batch[0], batch[0] + len(batch)))
        assert batch[0] % 10 == 0
    np.testing.assert_array_equal(np.sort(np.concatenate(batches)), np.arange(103))
    starts = [int(b[0]) for b in batches]
    assert starts != sorted(starts)  # only the chunk order is shuffled
    again = list(iterate_minibatches(dataset, 10, np.random.default_rng(0), sequential=True))
    assert [int(b[0]) for b in again] == starts
