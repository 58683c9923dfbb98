"""Final evaluation of a trained model: per-episode scores, lengths and successes, and the SB3 ``evaluations.npz``.

An evaluation asks for ``n`` deterministic episodes. Where they are bound to be one episode ``n`` times (an agent
whose deterministic ``predict`` depends only on the episode's observations, on an env that draws no random number in
``reset`` or ``step``, e.g. the maze from its fixed start), the episode is run once and stands for all ``n``: the
scores, the mean, the std (0) and the recorded rows are the same numbers, for a tenth of the cost
(:func:`repeats_exactly`; ``EpisodeScores.evaluated`` says how many ran).
"""

from __future__ import annotations

import copy
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv

from eval import stats


@dataclass
class EpisodeScores:
    """What one evaluation measured, episode by episode.

    :param scores: undiscounted sum of per-step rewards of each episode (the paper's score).
    :param lengths: number of steps of each episode.
    :param successes: ``info["is_success"]`` at the end of each episode; empty when the env does not report it.
    :param evaluated: the episodes that were really run, when fewer than listed: 1 where the episodes repeat
        exactly (:func:`repeats_exactly`) and one stands for them all; None when every listed episode ran.
    """

    scores: list[float]
    lengths: list[int]
    successes: list[bool] = field(default_factory=list)
    evaluated: int | None = None

    @property
    def score_mean(self) -> float:
        """Mean score over the episodes."""
        return stats.mean(self.scores)

    @property
    def score_std(self) -> float:
        """Population std of the scores over the episodes (``ddof=0``, as SB3's ``evaluate_policy``)."""
        return stats.std(self.scores)

    @property
    def success_rate(self) -> float | None:
        """Fraction of successful episodes, or None when the env reports no ``is_success``."""
        return float(np.mean(self.successes)) if self.successes else None


PROBE_STEPS = 20
"""Steps of random actions with which :func:`draws_no_randomness` checks that an env's ``step`` draws nothing."""


def _same_observation(first: Any, second: Any) -> bool:
    if isinstance(first, dict):
        return (
            isinstance(second, dict)
            and first.keys() == second.keys()
            and all(np.array_equal(first[k], second[k]) for k in first)
        )
    return bool(np.array_equal(first, second))


def draws_no_randomness(env: gym.Env) -> bool:
    """Whether a fresh copy of ``env`` (same spec, same kwargs) starts every episode alike and draws no random number.

    The copy is reset with a seed, then without one: the observation must be bit-identical and ``np_random`` (every
    gymnasium env's source of randomness) untouched by the second reset; then ``PROBE_STEPS`` random actions must
    leave ``np_random`` untouched. An env that draws from another generator escapes the check: such an env is
    outside gymnasium's seeding contract.

    :param env: the env (its ``spec`` is what is copied; ``env`` itself is not touched).
    :return: False as well when it cannot be told (no spec, an action space other than a ``Box``).
    """
    spec = env.unwrapped.spec  # as registered and made, without the wrappers added after (Monitor)
    if spec is None or not isinstance(env.action_space, gym.spaces.Box):
        return False
    try:
        probe = gym.make(spec)
    except Exception:  # a spec gymnasium cannot make again: it cannot be told
        return False
    try:
        first, _ = probe.reset(seed=0)
        generator = probe.unwrapped.np_random
        state = copy.deepcopy(generator.bit_generator.state)
        second, _ = probe.reset()
        if generator.bit_generator.state != state or not _same_observation(first, second):
            return False
        space = probe.action_space
        assert isinstance(space, gym.spaces.Box)
        low, high = np.clip(space.low, -1.0, 1.0), np.clip(space.high, -1.0, 1.0)
        actions = np.random.default_rng(0)
        for _ in range(PROBE_STEPS):
            _, _, terminated, truncated, _ = probe.step(actions.uniform(low, high).astype(space.dtype))
            if generator.bit_generator.state != state:
                return False
            if terminated or truncated:
                break
        return True
    finally:
        probe.close()


def repeats_exactly(model: Any, eval_env: VecEnv) -> bool:
    """Whether every deterministic evaluation episode of ``model`` on ``eval_env`` is bound to be the same episode.

    True when the model declares that its deterministic ``predict`` depends on nothing but the episode's observations
    (``deterministic_episodes_repeat``: the planning agents without a subgoal graph, whose stall bookkeeping carries
    over from one episode to the next) and the evaluation env is one plain env that draws no random number
    (:func:`draws_no_randomness`).

    :param model: the model evaluated.
    :param eval_env: its evaluation ``VecEnv``.
    :return: whether one episode can stand for all of them.
    """
    if not getattr(model, "deterministic_episodes_repeat", False):
        return False
    if not isinstance(eval_env, DummyVecEnv) or eval_env.num_envs != 1:
        return False
    return draws_no_randomness(eval_env.envs[0])


def evaluate_episodes(model: BaseAlgorithm, eval_env: VecEnv, n_eval_episodes: int) -> EpisodeScores:
    """Run ``n_eval_episodes`` deterministic episodes with SB3's ``evaluate_policy`` and keep every number.

    Where the episodes repeat exactly (:func:`repeats_exactly`) one is run and listed ``n_eval_episodes`` times
    (``evaluated=1``): the same numbers as running them all.

    :param model: the trained model.
    :param eval_env: a Monitor-wrapped evaluation ``VecEnv`` (never the training env).
    :param n_eval_episodes: number of episodes.
    :return: per-episode scores, lengths and successes.
    """
    if n_eval_episodes > 1 and repeats_exactly(model, eval_env):
        one = evaluate_episodes(model, eval_env, 1)
        return _listed(one, n_eval_episodes)
    successes: list[bool] = []

    def track_success(locals_: dict[str, Any], _globals: dict[str, Any]) -> None:
        # Same bookkeeping as EvalCallback._log_success_callback: the flag of the step that ends the episode.
        if locals_["done"]:
            is_success = episode_success(locals_["info"])
            if is_success is not None:
                successes.append(bool(is_success))

    scores, lengths = evaluate_policy(  # lists, as return_episode_rewards=True
        model,
        eval_env,
        n_eval_episodes=n_eval_episodes,
        deterministic=True,
        return_episode_rewards=True,
        callback=track_success,
        warn=False,
    )
    assert isinstance(scores, list) and isinstance(lengths, list)
    return EpisodeScores([float(s) for s in scores], [int(n) for n in lengths], successes)


SUCCESS_KEYS = ("is_success", "success")
"""The ``info`` keys that report success, first found wins: gymnasium-robotics' GoalEnv convention (Fetch, the
``ebm/`` envs) and its maze envs' own key (PointMaze, AntMaze)."""


def episode_success(info: dict[str, Any]) -> Any:
    """The success flag of a step's ``info`` under any of :data:`SUCCESS_KEYS`, or None when the env reports none.

    :param info: one env's step info.
    :return: the flag as the env gave it, or None.
    """
    for key in SUCCESS_KEYS:
        flag = info.get(key)
        if flag is not None:
            return flag
    return None


def _listed(one: EpisodeScores, n: int) -> EpisodeScores:
    """The evaluation of one episode that stands for ``n`` identical ones."""
    return EpisodeScores(one.scores * n, one.lengths * n, one.successes * n, evaluated=len(one.scores))


class RepeatAwareEvalCallback(EvalCallback):
    """SB3's ``EvalCallback`` that runs one episode where the episodes repeat exactly (:func:`repeats_exactly`).

    That episode is listed ``n_eval_episodes`` times in the learning curve (``evaluations.npz``) and in what the
    callbacks after it read: the same numbers as running them all. Whether they repeat is checked once, at the
    first evaluation (it depends on the model's settings and the env, neither of which ``learn`` changes).
    """

    repeats: bool | None = None
    """Whether the episodes repeat exactly (None until the first evaluation)."""

    _episodes: tuple[list[float], list[int]] | None = None
    """The lists of scores and lengths that ``evaluate_policy`` fills (seen by its per-step callback)."""

    def _log_success_callback(self, locals_: dict[str, Any], globals_: dict[str, Any]) -> None:
        # SB3's bookkeeping (the flag of the step that ends an episode), reading any of SUCCESS_KEYS.
        self._episodes = (locals_["episode_rewards"], locals_["episode_lengths"])
        if locals_["done"]:
            flag = episode_success(locals_["info"])
            if flag is not None:
                self._is_success_buffer.append(flag)

    def _on_step(self) -> bool:
        if not (self.eval_freq > 0 and self.n_calls % self.eval_freq == 0) or self.n_eval_episodes <= 1:
            return super()._on_step()
        if self.repeats is None:
            self.repeats = repeats_exactly(self.model, self.eval_env)
        if not self.repeats:
            return super()._on_step()
        n, log_path = self.n_eval_episodes, self.log_path
        # One episode, with the curve's bookkeeping left to this method (SB3's would save a row of one episode beside
        # rows of n) and the callbacks after an evaluation held back until all n episodes are listed.
        inner, self.callback, self.log_path, self.n_eval_episodes = self.callback, None, None, 1
        self._episodes = None
        try:
            continue_training = super()._on_step()
        finally:
            self.n_eval_episodes, self.callback, self.log_path = n, inner, log_path
        if log_path is not None and self._episodes is not None:
            scores, lengths = self._episodes
            self.evaluations_timesteps.append(self.num_timesteps)
            self.evaluations_results.append(list(scores) * n)
            self.evaluations_length.append(list(lengths) * n)
            extra: dict[str, Any] = {}
            if self._is_success_buffer:
                self.evaluations_successes.append(list(self._is_success_buffer) * n)
                extra["successes"] = self.evaluations_successes
            np.savez(
                log_path,
                timesteps=self.evaluations_timesteps,
                results=self.evaluations_results,
                ep_lengths=self.evaluations_length,
                **extra,
            )
        if inner is not None:
            continue_training = continue_training and self._on_event()
        return continue_training


def last_evaluation(callback: EvalCallback, timesteps: int, n_eval_episodes: int) -> EpisodeScores | None:
    """The episodes of ``EvalCallback``'s last evaluation, if it ran at ``timesteps`` with ``n_eval_episodes``.

    :param callback: the callback used during ``learn`` (with a ``log_path``, so that it kept its history).
    :param timesteps: the model's final ``num_timesteps``.
    :param n_eval_episodes: the number of episodes the final evaluation needs.
    :return: that evaluation, or None when the final evaluation must run anew.
    """
    if not callback.evaluations_timesteps or callback.evaluations_timesteps[-1] != timesteps:
        return None
    scores, lengths = callback.evaluations_results[-1], callback.evaluations_length[-1]
    if len(scores) != n_eval_episodes:
        return None
    successes: list[bool] = []
    if len(callback.evaluations_successes) == len(callback.evaluations_results):
        successes = [bool(flag) for flag in callback.evaluations_successes[-1]]
    evaluated = 1 if getattr(callback, "repeats", False) and n_eval_episodes > 1 else None
    return EpisodeScores([float(s) for s in scores], [int(n) for n in lengths], successes, evaluated)


class EvaluationLine(BaseCallback):
    """``EvalCallback``'s ``callback_after_eval``: one line per learning-curve evaluation, naming the run.

    A long run without a progress bar (``ebm-eval --no-progress`` into a log file; a Sawyer run takes hours) would
    otherwise stay silent until it ends. The line gives the run, the transitions so far out of the budget, the
    evaluation's mean score and success rate, the time since ``learn`` started in this process and a linear estimate
    of the time left from this process's pace (evaluations included). Parallel runs' lines interleave but each
    names its run.

    :param label: the run's name in the line (e.g. its folder).
    :param budget: the run's transition budget.
    :param stream: where to write (default: ``sys.stderr`` at the time of writing).
    """

    def __init__(self, label: str, budget: int, stream: IO[str] | None = None) -> None:
        super().__init__()
        self.label = label
        self.budget = int(budget)
        self.stream = stream
        self.lines: list[str] = []
        self._start = time.perf_counter()
        self._start_steps = 0

    def _init_callback(self) -> None:
        self._start = time.perf_counter()
        self._start_steps = int(self.model.num_timesteps)  # a resumed run starts past 0

    def _on_step(self) -> bool:
        parent = self.parent
        if not isinstance(parent, EvalCallback) or not parent.evaluations_results:
            return True
        scores = np.asarray(parent.evaluations_results[-1], dtype=float)  # [episodes]
        success = ""
        if len(parent.evaluations_successes) == len(parent.evaluations_results):
            success = f", success {np.mean(parent.evaluations_successes[-1]):.2f}"
        elapsed = time.perf_counter() - self._start
        done = max(self.num_timesteps - self._start_steps, 1)  # transitions this process has consumed
        left = elapsed / done * max(self.budget - self.num_timesteps, 0)
        once = " (1 episode run: the deterministic episodes repeat exactly)" if getattr(parent, "repeats", False) else ""
        line = (
            f"{self.label}: {self.num_timesteps}/{self.budget} transitions, evaluation {scores.mean():.2f} "
            f"± {scores.std():.2f}{success}{once}; {elapsed / 60:.1f} min so far, about {left / 60:.0f} min left"
        )
        self.lines.append(line)
        print(line, file=self.stream or sys.stderr, flush=True)
        return True


def append_evaluation(path: Path, timesteps: int, episodes: EpisodeScores) -> None:
    """Add one evaluation to an ``evaluations.npz`` in SB3's format, creating the file if needed.

    The final evaluation is appended when ``EvalCallback``'s last one was not at the final step, so that a
    learning curve always ends at the budget; an evaluation already at ``timesteps`` is left as it is.

    :param path: the ``evaluations.npz`` file.
    :param timesteps: transitions consumed when the evaluation ran.
    :param episodes: the evaluation's episodes.
    """
    timestep_list: list[int] = []
    results: list[list[float]] = []
    ep_lengths: list[list[int]] = []
    successes: list[list[bool]] = []
    if path.exists():
        with np.load(path) as data:
            timestep_list = [int(t) for t in data["timesteps"]]
            results = [list(map(float, row)) for row in data["results"]]
            ep_lengths = [list(map(int, row)) for row in data["ep_lengths"]]
            if "successes" in data:
                successes = [list(map(bool, row)) for row in data["successes"]]
    if timestep_list and timestep_list[-1] == timesteps:
        return
    if timestep_list and len(results[-1]) != len(episodes.scores):
        # npz rows must have one length; an evaluation of a different size cannot join the curve.
        return
    timestep_list.append(timesteps)
    results.append(episodes.scores)
    ep_lengths.append(episodes.lengths)
    # Keys and dtypes as EvalCallback writes them: timesteps [E], results [E, episodes], ep_lengths [E, episodes].
    arrays: dict[str, Any] = {
        "timesteps": np.asarray(timestep_list),
        "results": np.asarray(results),
        "ep_lengths": np.asarray(ep_lengths),
    }
    if episodes.successes and (len(successes) == len(timestep_list) - 1):
        successes.append(episodes.successes)
        arrays["successes"] = np.asarray(successes)  # [E, episodes]
    np.savez(path, **arrays)


__all__ = [
    "PROBE_STEPS",
    "SUCCESS_KEYS",
    "EpisodeScores",
    "RepeatAwareEvalCallback",
    "append_evaluation",
    "draws_no_randomness",
    "episode_success",
    "evaluate_episodes",
    "last_evaluation",
    "repeats_exactly",
]
