"""The evaluation goal weight after a short training: ``python -m benchmarks.eval_goal_weight``.

Trains one EBM agent per seed (the library's defaults, or an agent preset) for a few transitions, then evaluates the
same model at each evaluation goal weight (``CostConfig.eval_goal_weight``) with the harness's evaluation (one
deterministic episode stands for all where they repeat exactly), and prints a markdown table of the scores: a paired
comparison, so the weights differ in nothing but the evaluation. The default is the particle at 2,000 transitions
from the paper's start (0, 0) to its goal (0.5, 0.5), where the defaults' weight 10 was chosen.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence

import gymnasium as gym
import torch
from stable_baselines3.common.env_util import make_vec_env

import envs  # noqa: F401  registers the ebm/ ids
from ebm_agent import EBMPlannerAgent
from ebm_agent.presets import preset_settings
from eval.evaluation import evaluate_episodes

PARTICLE_EVALUATION = {"start": (0.0, 0.0), "goal": (0.5, 0.5)}
"""The paper's particle evaluation (the default ``--eval-env-kwargs`` for ``ebm/Particle-v0``)."""


def main(argv: Sequence[str] | None = None) -> int:
    """Print the table.

    :param argv: the arguments (``--env``, ``--timesteps``, ``--seeds``, ``--weights``, ``--episodes``,
        ``--preset``, ``--eval-env-kwargs``, ``--threads``).
    :return: 0.
    """
    parser = argparse.ArgumentParser(prog="python -m benchmarks.eval_goal_weight", description=__doc__)
    parser.add_argument("--env", default="ebm/Particle-v0", help="a registered env id (default: ebm/Particle-v0)")
    parser.add_argument("--timesteps", type=int, default=2000, help="transitions learnt before evaluating (0: untrained)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--weights", type=float, nargs="+", default=[1.0, 10.0], help="evaluation goal weights")
    parser.add_argument("--episodes", type=int, default=10, help="evaluation episodes (default: 10)")
    parser.add_argument("--preset", default="", help="an agent preset (ebm_agent.presets; default: the defaults)")
    parser.add_argument(
        "--eval-env-kwargs",
        type=json.loads,
        default=None,
        help="JSON env kwargs of the evaluation env (default: the "
        "paper's start and goal on the particle, the env's own elsewhere)",
    )
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default: 1)")
    args = parser.parse_args(argv)
    if args.timesteps < 0 or args.episodes < 1 or not all(w >= 0 for w in args.weights):
        parser.error("--timesteps must be >= 0, --episodes >= 1 and every weight >= 0")
    torch.set_num_threads(args.threads)
    eval_kwargs = args.eval_env_kwargs
    if eval_kwargs is None:
        eval_kwargs = PARTICLE_EVALUATION if args.env == "ebm/Particle-v0" else {}
    print(
        f"{args.env}, EBM ({args.preset or 'defaults'}), {args.timesteps} transitions, {args.episodes} deterministic "
        f"episodes, {torch.get_num_threads()} torch thread(s)\n"
    )
    print("| seed | learn s | " + " | ".join(f"eval goal weight {w:g}" for w in args.weights) + " |")
    print("|---" * (2 + len(args.weights)) + "|")
    for seed in args.seeds:
        agent = EBMPlannerAgent(
            "MultiInputPolicy", gym.make(args.env), seed=seed, device="cpu", **preset_settings(args.preset, EBMPlannerAgent)
        )
        start = time.perf_counter()
        if args.timesteps:
            agent.learn(args.timesteps)
        learn_seconds = time.perf_counter() - start
        scores = []
        for weight in args.weights:
            agent.cost_config.eval_goal_weight = weight
            env = make_vec_env(args.env, n_envs=1, seed=seed + 10_000, env_kwargs=eval_kwargs)
            episodes = evaluate_episodes(agent, env, args.episodes)
            env.close()
            success = f", success {episodes.success_rate:.2f}" if episodes.success_rate is not None else ""
            scores.append(f"{episodes.score_mean:.2f}{success}")
        print(f"| {seed} | {learn_seconds:.1f} | " + " | ".join(scores) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
