"""What an evaluation of repeating episodes costs: ``python -m benchmarks.evaluation``.

Evaluates one untrained EBM agent (the library's defaults) with ``eval.evaluation.evaluate_episodes`` on an env whose
deterministic episodes repeat exactly (the maze from its fixed start, by default), once as the harness does (one
episode stands for all) and once running every episode, in the same process, and prints a markdown table of the
episodes run, the mean score, its std and the seconds each took. The two scores must be the same number.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence

import gymnasium as gym
import torch
from stable_baselines3.common.env_util import make_vec_env

import envs  # noqa: F401  registers the ebm/ ids
from ebm_agent import EBMPlannerAgent
from eval.evaluation import EpisodeScores, evaluate_episodes


class _EveryEpisode:
    """The agent as an evaluation sees it, less its ``deterministic_episodes_repeat``: every episode is run."""

    deterministic_episodes_repeat = False

    def __init__(self, agent: EBMPlannerAgent) -> None:
        self._agent = agent

    def __getattr__(self, name: str) -> object:
        return getattr(self._agent, name)

    def predict(self, *args: object, **kwargs: object) -> object:
        """The agent's ``predict``."""
        return self._agent.predict(*args, **kwargs)  # type: ignore[arg-type]


def main(argv: Sequence[str] | None = None) -> int:
    """Print the table.

    :param argv: the arguments (``--env``, ``--episodes``, ``--seed``, ``--threads``).
    :return: 0.
    """
    parser = argparse.ArgumentParser(prog="python -m benchmarks.evaluation", description=__doc__)
    parser.add_argument("--env", default="ebm/Maze-v0", help="a registered env id (default: ebm/Maze-v0)")
    parser.add_argument("--episodes", type=int, default=10, help="evaluation episodes (default: 10)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default: 1)")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    agent = EBMPlannerAgent("MultiInputPolicy", gym.make(args.env), seed=args.seed, device="cpu")
    rows: list[tuple[str, EpisodeScores, float]] = []
    for label, model in (("one episode for all", agent), ("every episode", _EveryEpisode(agent))):
        env = make_vec_env(args.env, n_envs=1, seed=args.seed + 10_000)
        start = time.perf_counter()
        episodes = evaluate_episodes(model, env, args.episodes)  # type: ignore[arg-type]
        rows.append((label, episodes, time.perf_counter() - start))
        env.close()
    print(f"{args.env}, untrained EBM (defaults), seed {args.seed}, {torch.get_num_threads()} torch thread(s)\n")
    print("| evaluation | episodes run | score | std | seconds |")
    print("|---|---|---|---|---|")
    for label, episodes, seconds in rows:
        run = episodes.evaluated or len(episodes.scores)
        print(f"| {label} | {run} | {episodes.score_mean:.6f} | {episodes.score_std:.2f} | {seconds:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
