"""Final evaluation of a trained model: per-episode scores, lengths and successes, and the SB3 ``evaluations.npz``."""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.vec_env import VecEnv

from eval import stats


@dataclass
class EpisodeScores:
    """What one evaluation measured, episode by episode.

    :param scores: undiscounted sum of per-step rewards of each episode (the paper's score).
    :param lengths: number of steps of each episode.
    :param successes: ``info["is_success"]`` at the end of each episode; empty when the env does not report it.
    """

    scores: list[float]
    lengths: list[int]
    successes: list[bool] = field(default_factory=list)

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


def evaluate_episodes(model: BaseAlgorithm, eval_env: VecEnv, n_eval_episodes: int) -> EpisodeScores:
    """Run ``n_eval_episodes`` deterministic episodes with SB3's ``evaluate_policy`` and keep every number.

    :param model: the trained model.
    :param eval_env: a Monitor-wrapped evaluation ``VecEnv`` (never the training env).
    :param n_eval_episodes: number of episodes.
    :return: per-episode scores, lengths and successes.
    """
    successes: list[bool] = []

    def track_success(locals_: dict[str, Any], _globals: dict[str, Any]) -> None:
        # Same bookkeeping as EvalCallback._log_success_callback: the flag of the step that ends the episode.
        if locals_["done"]:
            is_success = locals_["info"].get("is_success")
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
    return EpisodeScores([float(s) for s in scores], [int(n) for n in lengths], successes)


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
        line = (
            f"{self.label}: {self.num_timesteps}/{self.budget} transitions, evaluation {scores.mean():.2f} "
            f"± {scores.std():.2f}{success}; {elapsed / 60:.1f} min so far, about {left / 60:.0f} min left"
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


__all__ = ["EpisodeScores", "append_evaluation", "evaluate_episodes", "last_evaluation"]
