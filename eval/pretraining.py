"""The datasets and the offline training of pretrained jobs (the paper's "pretrained" rows, Tables 1 and 2).

Datasets (paper Sec. 4.1-4.2; reference/original_code.md §2, §6):

- ``random``: ``timesteps`` transitions of the training env driven by its exploration actions
  (``ebm_agent.datasets.collect_random_transitions``: the env's ``sample_exploration_action()`` where it has one,
  e.g. the Sawyer's random joint targets, else uniform actions). The paper: "100,000 action-state transitions
  pre-generated from random sampling in each environment".
- ``directed``: the real transitions an EBM agent experiences while it learns online on the same env for
  ``timesteps`` transitions, in the order it experienced them. The paper: "a directed dataset of 100,000 frames
  from an EBM trained on Sawyer Arm task"; the original code saved the first 120,000 entries of the online EBM's
  positive replay buffer. The collecting agent is ``EBMPlannerAgent`` with ``Job.dataset_kwargs`` and the job's
  seed, so the EBM and Action FF jobs of one seed learn from the same dataset.
- ``directed+sequential``: the directed dataset with every transition repeated ``repeat`` (100) times in a row,
  learnt in contiguous minibatches (``learn_offline(sequential=True)``). The paper: "batches sequentially sampled
  from the dataset, with each datapoint repeated 100 times without shuffling to mimic the correlated experiences
  seen during online training". The paper gives no epoch count for it; the default is one pass over the repeated
  data, i.e. every transition is seen 100 times (the shuffled datasets: 10 epochs, 10 times), because the original's
  10 epochs over the repeated data would cost 100x the gradient steps of the other rows.

Datasets are cached under ``<out>/datasets/<env>/`` (a file lock keeps parallel jobs of one seed from collecting the
same directed dataset twice); a cache file is named by a hash of everything that determines its content.

A directed collection is an online run without evaluations: 100,000 Sawyer transitions take about two hours of one
core, so it keeps a checkpoint every ``COLLECT_CHECKPOINT_EVERY`` transitions in ``<cache file>.collect/`` (the agent's
``save_checkpoint``, the env with its recorder, the time spent; ``eval.resume.write_checkpoint_files``). The next job
that needs the dataset goes on from there, and the dataset equals an uninterrupted collection's (tested); the folder
is removed once the dataset is saved. SIGTERM or Ctrl-C during the collection writes a checkpoint at the next step
and stops it (``eval.stop``), so that nothing collected is lost.
"""

from __future__ import annotations

import functools
import hashlib
import json
import shutil
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv

import envs  # noqa: F401  registers the ebm/ ids
from ebm_agent import EBMPlannerAgent
from ebm_agent.datasets import TransitionDataset, collect_random_transitions
from ebm_agent.presets import merge_settings, preset_settings
from eval.jobs import Job, to_plain
from eval.locks import file_lock
from eval.resume import ResumeCheckpoint, read_checkpoint_files, write_checkpoint_files
from eval.stop import raise_if_stopped, stop_at_next_step

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm

OFFLINE_DEFAULTS: dict[str, int] = {"epochs": 10, "batch_size": 256}
"""``learn_offline`` settings of the shuffled datasets: the original's 10 epochs of batches of 256."""

SEQUENTIAL_DEFAULTS: dict[str, int] = {"epochs": 1, "batch_size": 256, "repeat": 100}
"""The sequential ablation: each transition 100 times in a row (the paper), one pass over the repeated data."""

EBM_OFFLINE_KEYS: frozenset[str] = frozenset({"num_candidates"})
"""``learn_offline`` settings a pretrained EBM job may also set (``EBMPlannerAgent.learn_offline``'s own keywords;
left out, the agent's defaults)."""

COLLECT_CHECKPOINT_EVERY = 10_000
"""Transitions between two checkpoints of a directed collection (on the Sawyer 12-20 min of one core; 18.7 and about
20 min measured on 2026-12-03 beside other processes)."""


def pretrain(model: BaseAlgorithm, job: Job) -> dict[str, Any]:
    """Build (or load) the job's dataset and train ``model`` on it with ``learn_offline``.

    :param model: an untrained agent with ``learn_offline`` (the EBM agent, Action FF).
    :param job: a job with ``mode="pretrained"``; ``timesteps`` is the dataset size.
    :return: what was done, for ``metrics.json``: dataset, its size and file, the time earlier processes spent on
        the directed collection this job finished (``collect_time_earlier_processes_s``, counted in the run's wall
        and learn times), epochs, batch size, repeat, gradient steps.
    :raises TypeError: for an agent that cannot learn offline.
    :raises ValueError: for unknown ``offline_kwargs``.
    """
    learn_offline = getattr(model, "learn_offline", None)
    if not callable(learn_offline):
        raise TypeError(
            f"agent {job.agent!r} ({type(model).__name__}) has no learn_offline, so it cannot be pretrained; "
            "pretrained jobs need the EBM agent or Action FF"
        )
    sequential = job.dataset == "directed+sequential"
    settings = offline_settings(job)
    base, path, earlier = _load_or_build(job)
    repeat = int(settings.get("repeat", 1))
    data = training_data(base, job)
    updates_before = int(getattr(model, "_n_updates", 0))
    learn_offline(
        data,
        epochs=int(settings["epochs"]),
        batch_size=int(settings["batch_size"]),
        sequential=sequential,
        tb_log_name=job.tb_log_name,
        **{key: settings[key] for key in sorted(EBM_OFFLINE_KEYS & set(settings))},
    )
    return {
        "dataset": job.dataset,
        "dataset_size": len(base),
        "dataset_file": str(path),
        "dataset_info": base.info,
        "collect_time_earlier_processes_s": earlier,
        "epochs": int(settings["epochs"]),
        "batch_size": int(settings["batch_size"]),
        "repeat": repeat,
        "sequential": sequential,
        "gradient_steps": int(getattr(model, "_n_updates", 0)) - updates_before,
    }


def offline_settings(job: Job) -> dict[str, Any]:
    """A pretrained job's ``learn_offline`` settings: its ``offline_kwargs`` over its dataset kind's defaults.

    :param job: the pretrained job.
    :return: ``epochs``, ``batch_size`` and, for the sequential dataset, ``repeat``; for an EBM job, any of
        :data:`EBM_OFFLINE_KEYS` it sets.
    :raises ValueError: for ``offline_kwargs`` the dataset kind or the agent does not understand.
    """
    defaults = SEQUENTIAL_DEFAULTS if job.dataset == "directed+sequential" else OFFLINE_DEFAULTS
    known = set(defaults) | (EBM_OFFLINE_KEYS if job.agent == "ebm" else set())
    unknown = sorted(set(job.offline_kwargs) - known)
    if unknown:
        raise ValueError(
            f"offline_kwargs {unknown} are not understood for dataset {job.dataset!r} and agent {job.agent!r}; known: "
            f"{sorted(known)}"
        )
    return {**defaults, **job.offline_kwargs}


def training_data(base: TransitionDataset, job: Job) -> TransitionDataset:
    """The transitions a pretrained job trains on (and builds its subgoal graph over): its base dataset, repeated
    ``repeat`` times where its :func:`offline_settings` say so.

    :param base: the job's base dataset (:func:`load_or_build_dataset`).
    :param job: the pretrained job.
    :return: the dataset ``learn_offline`` is given.
    """
    repeat = int(offline_settings(job).get("repeat", 1))
    return repeat_transitions(base, repeat) if repeat > 1 else base


def dataset_path(job: Job) -> Path:
    """The cache file of the job's base dataset (the directed one for ``directed+sequential``).

    :param job: a pretrained job.
    :return: ``<out>/datasets/<env>/<kind>_n<size>_s<seed>_<hash>.npz``.
    """
    kind = "random" if job.dataset == "random" else "directed"
    key = {
        "env_id": job.env_id,
        "env_kwargs": job.env_kwargs,
        "kind": kind,
        "size": job.timesteps,
        "seed": job.seed,
        "collector": collector_settings(job) if kind == "directed" else {},
    }
    digest = hashlib.sha256(json.dumps(to_plain(key), sort_keys=True).encode()).hexdigest()[:10]
    return Path(job.out_dir) / "datasets" / job.env_short / f"{kind}_n{job.timesteps}_s{job.seed}_{digest}.npz"


def collector_settings(job: Job) -> dict[str, Any]:
    """The keyword arguments of the EBM agent that collects a directed dataset: the job's agent preset
    (``ebm_agent.presets``) with ``Job.dataset_kwargs`` over it.

    :param job: a pretrained job.
    :return: a new dict.
    """

    return merge_settings(preset_settings(job.preset, "EBMPlannerAgent"), job.dataset_kwargs)


def collection_checkpoint_dir(job: Job) -> Path:
    """Where an unfinished directed collection keeps its checkpoint: ``<cache file>.collect/``.

    :param job: a pretrained job.
    :return: the folder (it exists only while a collection is unfinished).
    """
    return dataset_path(job).with_suffix(".collect")


def load_or_build_dataset(job: Job) -> tuple[TransitionDataset, Path]:
    """The job's base dataset from the cache, collected first when missing.

    :param job: a pretrained job.
    :return: the dataset and its file.
    """
    dataset, path, _ = _load_or_build(job)
    return dataset, path


def _load_or_build(job: Job) -> tuple[TransitionDataset, Path, float]:
    """``load_or_build_dataset``, and the collecting time of earlier processes when this call finished a collection.

    :return: the dataset, its file, and the seconds earlier processes spent on the collection this call resumed
        (0 when the dataset came from the cache or was collected in one go).
    """
    path = dataset_path(job)
    with file_lock(path.with_suffix(".lock")):
        if path.exists():
            return TransitionDataset.load(path), path, 0.0
        if job.dataset == "random":
            dataset = collect_random_transitions(job.env_id, job.timesteps, seed=job.seed, **job.env_kwargs)
        else:
            dataset = collect_directed_transitions(
                job.env_id,
                job.env_kwargs,
                job.timesteps,
                job.seed,
                collector_settings(job),
                job.device,
                checkpoint_dir=collection_checkpoint_dir(job),
                checkpoint_every=COLLECT_CHECKPOINT_EVERY,
            )
        earlier = float(dataset.info.pop("collect_time_before_s", 0.0))
        dataset.info = to_plain({**dataset.info, "env_kwargs": job.env_kwargs})
        dataset.save(path)
        shutil.rmtree(collection_checkpoint_dir(job), ignore_errors=True)  # saved: the checkpoint is spent
    return dataset, path, earlier


def collect_directed_transitions(
    env_id: str,
    env_kwargs: dict[str, Any],
    num_transitions: int,
    seed: int,
    agent_kwargs: dict[str, Any] | None = None,
    device: str = "auto",
    checkpoint_dir: Path | None = None,
    checkpoint_every: int = COLLECT_CHECKPOINT_EVERY,
) -> TransitionDataset:
    """The real transitions of an EBM agent learning online for ``num_transitions`` transitions, in order.

    With ``checkpoint_dir``, a checkpoint is written there every ``checkpoint_every`` transitions, and a collection
    found there (same env, size, seed and agent) is continued rather than started again; the result equals an
    uninterrupted collection's.

    :param env_id: registered Gymnasium id.
    :param env_kwargs: keyword arguments of ``gym.make``.
    :param num_transitions: M, the transitions recorded (the agent's whole budget).
    :param seed: seed of the agent and its env.
    :param agent_kwargs: keyword arguments of ``EBMPlannerAgent``.
    :param device: torch device of the agent.
    :param checkpoint_dir: folder of the collection's checkpoint (None: no checkpoints).
    :param checkpoint_every: transitions between two checkpoints.
    :return: the dataset; ``info`` names the policy ``"directed"``, the agent's settings, the collection's time over
        all processes (``collect_time_s``; ``collect_time_before_s`` of the earlier ones) and where it resumed
        (``resumed_at``).
    """

    if checkpoint_every < 1:
        raise ValueError(f"checkpoint_every must be a positive number of transitions, got {checkpoint_every}")
    identity = to_plain(
        {"env_id": env_id, "env_kwargs": env_kwargs, "size": num_transitions, "seed": seed, "agent_kwargs": agent_kwargs}
    )
    found = read_checkpoint_files(checkpoint_dir, identity) if checkpoint_dir is not None else None
    if found is None:
        recorder = TransitionRecorder(gym.make(env_id, **env_kwargs))
        vec_env = DummyVecEnv([lambda: Monitor(recorder)])
        agent = EBMPlannerAgent("MultiInputPolicy", vec_env, seed=seed, device=device, **(agent_kwargs or {}))
        time_before, resumed_at = 0.0, []
    else:  # go on from the checkpoint, with the env (and the transitions it recorded) as they were
        state, agent_path, payload = found
        recorder, vec_env = payload["recorder"], payload["env"]
        agent = EBMPlannerAgent.load_checkpoint(agent_path, env=vec_env, device=device, force_reset=False)
        time_before = float(state.get("collect_time_s", 0.0))
        resumed_at = [*state.get("resumed_at", []), int(state["num_timesteps"])]
    start = time.perf_counter()
    learn = functools.partial(
        agent.learn, total_timesteps=num_transitions - int(agent.num_timesteps), reset_num_timesteps=found is None
    )

    def write(elapsed_s: float) -> None:
        assert checkpoint_dir is not None
        state = {**identity, "collect_time_s": time_before + elapsed_s, "resumed_at": resumed_at}
        write_checkpoint_files(checkpoint_dir, agent, {"env": agent.get_env(), "recorder": recorder}, state)

    try:
        if checkpoint_dir is None:
            learn()
        else:
            with stop_at_next_step() as flag:  # SIGTERM, Ctrl-C: a checkpoint at the next step, then stop
                learn(callback=ResumeCheckpoint(write, num_transitions, every=checkpoint_every, flag=flag))
            what = f"directed collection of {num_transitions:,} {env_id} transitions (seed {seed})"
            raise_if_stopped(flag, int(agent.num_timesteps), num_transitions, what, checkpoint_dir)
    finally:
        vec_env.close()
    info = {
        "env_id": env_id,
        "seed": seed,
        "policy": "directed",
        "agent": "EBMPlannerAgent",
        "agent_kwargs": agent_kwargs,
        "collect_time_s": time_before + time.perf_counter() - start,
        "collect_time_before_s": time_before,
        "resumed_at": resumed_at,
    }
    return recorder.dataset(info=to_plain(info))


class TransitionRecorder(gym.Wrapper):
    """Records every (s, a, s') the wrapped goal env steps through, with its episode index.

    States are the ``"observation"`` entry of the Dict observation; an episode's last transition keeps its true
    final state (the wrapper sees it before any auto-reset), and the next reset starts a new episode index.

    :param env: the env to record.
    """

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self._states: list[np.ndarray] = []
        self._next_states: list[np.ndarray] = []
        self._actions: list[np.ndarray] = []
        self._episode_ids: list[int] = []
        self._state: np.ndarray | None = None
        self._episode = -1

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        """Reset the env and start a new episode index."""
        observation, info = self.env.reset(**kwargs)
        self._state = _state_of(observation)
        self._episode += 1
        return observation, info

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        """Step the env and record the transition."""
        observation, reward, terminated, truncated, info = self.env.step(action)
        next_state = _state_of(observation)
        if self._state is not None:
            self._states.append(self._state)
            self._next_states.append(next_state)
            self._actions.append(np.asarray(action, dtype=np.float32).reshape(-1))
            self._episode_ids.append(self._episode)
        self._state = next_state
        return observation, reward, terminated, truncated, info

    def __len__(self) -> int:
        return len(self._states)

    def dataset(self, info: dict[str, Any] | None = None) -> TransitionDataset:
        """The recorded transitions.

        :param info: metadata to store with them.
        :return: states [M, D], next states [M, D], actions [M, A], episode ids [M].
        """
        if not self._states:
            raise ValueError("TransitionRecorder recorded no transition: step the env first")
        return TransitionDataset(
            np.stack(self._states),
            np.stack(self._next_states),
            np.stack(self._actions),
            np.asarray(self._episode_ids),
            info=dict(info or {}),
        )


def repeat_transitions(dataset: TransitionDataset, repeat: int) -> TransitionDataset:
    """Every transition ``repeat`` times in a row (the sequential ablation's correlated stream).

    :param dataset: M transitions.
    :param repeat: copies of each.
    :return: M * repeat transitions, copies adjacent, in the dataset's order.
    """
    if repeat < 1:
        raise ValueError(f"repeat must be a positive number of copies, got {repeat}")
    return TransitionDataset(
        np.repeat(dataset.states, repeat, axis=0),  # [M * repeat, D]
        np.repeat(dataset.next_states, repeat, axis=0),
        np.repeat(dataset.actions, repeat, axis=0),
        np.repeat(dataset.episode_ids, repeat),
        info={**dataset.info, "repeat": repeat},
    )


def _state_of(observation: Any) -> np.ndarray:
    state = observation["observation"] if isinstance(observation, dict) else observation
    return np.asarray(state, dtype=np.float32).reshape(-1).copy()


__all__ = [
    "COLLECT_CHECKPOINT_EVERY",
    "OFFLINE_DEFAULTS",
    "SEQUENTIAL_DEFAULTS",
    "TransitionRecorder",
    "collect_directed_transitions",
    "collection_checkpoint_dir",
    "dataset_path",
    "load_or_build_dataset",
    "offline_settings",
    "pretrain",
    "repeat_transitions",
    "training_data",
]
