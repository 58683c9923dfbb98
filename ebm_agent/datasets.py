"""Offline transition datasets for pretraining: collection from an env, .npz storage and minibatch order."""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

__all__ = ["TransitionDataset", "collect_random_transitions", "iterate_minibatches"]

_ARRAY_KEYS = ("states", "next_states", "actions", "episode_ids")
COLLECTION_POLICIES = ("random",)


@dataclass
class TransitionDataset:
    """
    Transitions (s, s', a) with the episode each came from; the pretraining data of the paper's Tables 1 and 2.

    :param states: [M, D] states s_t.
    :param next_states: [M, D] next states s_{t+1} (never the first state of another episode).
    :param actions: [M, A] executed actions.
    :param episode_ids: [M] int episode index of each transition (consecutive transitions of an episode are
        stored in order, so contiguous chunks are correlated, as in the "sequential" ablation).
    :param info: JSON-serialisable metadata (env id, seed, policy), saved with the arrays.
    """

    states: np.ndarray
    next_states: np.ndarray
    actions: np.ndarray
    episode_ids: np.ndarray
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.states = np.asarray(self.states, dtype=np.float32)
        self.next_states = np.asarray(self.next_states, dtype=np.float32)
        self.actions = np.asarray(self.actions, dtype=np.float32)
        self.episode_ids = np.asarray(self.episode_ids, dtype=np.int64)
        num = self.states.shape[0] if self.states.ndim else -1
        problems = []
        if self.states.ndim != 2:
            problems.append(f"states must be [M, D], got {self.states.shape}")
        if self.next_states.shape != self.states.shape:
            problems.append(f"next_states must match states {self.states.shape}, got {self.next_states.shape}")
        if self.actions.ndim != 2 or self.actions.shape[0] != num:
            problems.append(f"actions must be [M={num}, A], got {self.actions.shape}")
        if self.episode_ids.shape != (num,):
            problems.append(f"episode_ids must be [M={num}], got {self.episode_ids.shape}")
        if problems:
            raise ValueError("TransitionDataset: " + "; ".join(problems) + ".")

    def __len__(self) -> int:
        return int(self.states.shape[0])

    def save(self, path: str | os.PathLike[str]) -> Path:
        """
        Write the dataset to an ``.npz`` file atomically (temp file in the same folder, then ``os.replace``).

        :param path: destination; ``.npz`` is appended when the name has another suffix or none (as ``np.savez``).
        :return: the path written.
        """
        target = Path(path)
        if target.suffix != ".npz":
            target = target.with_name(target.name + ".npz")
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as handle:
                np.savez(
                    handle,
                    states=self.states,
                    next_states=self.next_states,
                    actions=self.actions,
                    episode_ids=self.episode_ids,
                    info=np.array(json.dumps(self.info)),
                )
            os.replace(tmp_name, target)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp_name)
            raise
        return target

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> TransitionDataset:
        """
        Read a dataset written by :meth:`save` (no pickle).

        :param path: the ``.npz`` file.
        :return: the dataset.
        :raises ValueError: when the file lacks one of the arrays.
        """
        with np.load(path, allow_pickle=False) as data:
            missing = [key for key in _ARRAY_KEYS if key not in data.files]
            if missing:
                raise ValueError(
                    f"TransitionDataset.load: {os.fspath(path)!r} lacks arrays {missing} (has {data.files}); "
                    "write datasets with TransitionDataset.save or collect_random_transitions."
                )
            info = json.loads(str(data["info"])) if "info" in data.files else {}
            return cls(data["states"], data["next_states"], data["actions"], data["episode_ids"], info=info)


def collect_random_transitions(
    env: gym.Env | str,
    num_transitions: int = 100_000,
    seed: int = 0,
    policy: str = "random",
    **env_kwargs: Any,
) -> TransitionDataset:
    """
    Step one environment with random actions and record exactly ``num_transitions`` transitions.

    The action is the unwrapped env's ``sample_exploration_action()`` when it has one (e.g. small torques for the
    arm, which uniform torques pin at its joint limits), else ``action_space.sample()`` from a space seeded with
    ``seed``. States are the ``"observation"`` entry of a Dict observation (or the observation itself for a Box).
    When an episode ends (terminated or truncated) its last transition is kept and the env is reset into a new
    episode id, so a transition never pairs an episode's last state with the next episode's first.

    :param env: an env or a Gymnasium id for ``gym.make``.
    :param num_transitions: M, the exact number of transitions recorded.
    :param seed: seeds the first ``reset`` and the action space.
    :param policy: only ``"random"`` for now (directed datasets come from an agent's replay buffer).
    :param env_kwargs: passed to ``gym.make`` when ``env`` is an id.
    :return: the dataset; ``info`` records the env id, seed and policy.
    :raises ValueError: for an unknown policy or a non-positive count.
    """
    if policy not in COLLECTION_POLICIES:
        raise ValueError(f"collect_random_transitions: unknown policy {policy!r}; choose one of {list(COLLECTION_POLICIES)}.")
    if isinstance(num_transitions, bool) or not isinstance(num_transitions, int | np.integer) or num_transitions < 1:
        raise ValueError(f"collect_random_transitions: num_transitions must be a positive int, got {num_transitions!r}.")
    if isinstance(env, str):
        env_obj, owns_env = gym.make(env, **env_kwargs), True
    else:
        if env_kwargs:
            raise ValueError("collect_random_transitions: env_kwargs only apply when env is an id string.")
        env_obj, owns_env = env, False
    try:
        return _collect(env_obj, int(num_transitions), seed, policy)
    finally:
        if owns_env:
            env_obj.close()


def _collect(env: gym.Env, num_transitions: int, seed: int, policy: str) -> TransitionDataset:
    explore = getattr(env.unwrapped, "sample_exploration_action", None)
    env.action_space.seed(seed)
    observation, _ = env.reset(seed=seed)
    state = _state_of(observation)
    states = np.empty((num_transitions, state.shape[0]), dtype=np.float32)  # [M, D]
    next_states = np.empty_like(states)
    actions: np.ndarray | None = None
    episode_ids = np.empty(num_transitions, dtype=np.int64)
    episode = 0
    for index in range(num_transitions):
        action = np.asarray(explore() if callable(explore) else env.action_space.sample(), dtype=np.float32)
        observation, _, terminated, truncated, _ = env.step(action)
        next_state = _state_of(observation)
        if actions is None:
            actions = np.empty((num_transitions, action.size), dtype=np.float32)  # [M, A]
        states[index], next_states[index], actions[index] = state, next_state, action.reshape(-1)
        episode_ids[index] = episode
        if terminated or truncated:
            episode += 1
            observation, _ = env.reset()
            next_state = _state_of(observation)
        state = next_state
    assert actions is not None
    env_id = env.spec.id if env.spec is not None else type(env.unwrapped).__name__
    info = {"env_id": env_id, "seed": seed, "policy": policy, "num_episodes": episode + 1}
    return TransitionDataset(states, next_states, actions, episode_ids, info=info)


def _state_of(observation: Any) -> np.ndarray:
    if isinstance(observation, dict):
        if "observation" not in observation:
            raise ValueError(
                f"collect_random_transitions: a Dict observation needs an 'observation' key, got {list(observation)}."
            )
        observation = observation["observation"]
    return np.asarray(observation, dtype=np.float32).reshape(-1)


def iterate_minibatches(
    dataset: TransitionDataset | int,
    batch_size: int,
    rng: np.random.Generator,
    sequential: bool = False,
    drop_last: bool = False,
) -> Iterator[np.ndarray]:
    """
    Index arrays covering the dataset once (one epoch).

    Shuffled: a random permutation cut into batches. Sequential: contiguous chunks ``[i*B, (i+1)*B)`` in storage
    order with only the order of the chunks shuffled, so each batch holds consecutive, correlated transitions
    (the original's pretraining batching, used for the "directed + sequential" ablation of Table 2).

    :param dataset: the dataset (or its length M).
    :param batch_size: B.
    :param rng: generator for the permutation.
    :param sequential: contiguous chunks instead of a shuffle.
    :param drop_last: skip the final batch when it is smaller than B.
    :return: an iterator of int64 index arrays of length B (the last may be shorter).
    """
    size = dataset if isinstance(dataset, int | np.integer) else len(dataset)
    if isinstance(batch_size, bool) or not isinstance(batch_size, int | np.integer) or batch_size < 1:
        raise ValueError(f"iterate_minibatches: batch_size must be a positive int, got {batch_size!r}.")
    starts = np.arange(0, size, batch_size)
    if drop_last:
        starts = starts[starts + batch_size <= size]
    if sequential:
        for start in rng.permutation(starts):
            yield np.arange(start, min(start + batch_size, size), dtype=np.int64)
    else:
        order = rng.permutation(size).astype(np.int64)
        for start in starts:
            yield order[start : start + batch_size]
