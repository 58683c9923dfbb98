"""Probe: does online learning matter on the particle? Train with a given goal weight, evaluate every 1/5 budget.

Usage: python scripts/particle_goal_weight.py --goal-weight 0.1 --timesteps 10000 [--seed 0]

Prints transitions, the score of one deterministic episode from (0, 0) to (0.5, 0.5) and its length, and seconds.
With the default goal weight (1.0) an untrained agent already scores about -4.5; with 0.1 it scores about -98, so
any improvement there comes from the learned energy.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
from stable_baselines3.common.evaluation import evaluate_policy

import envs  # noqa: F401
from ebm_agent import EBMPlannerAgent


def main() -> None:
    """Run the probe."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--goal-weight", type=float, default=0.1)
    parser.add_argument("--timesteps", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    agent = EBMPlannerAgent(
        "MultiInputPolicy", gym.make("ebm/Particle-v0"), seed=args.seed, cost={"goal_weight": args.goal_weight}
    )
    eval_env = gym.make("ebm/Particle-v0", start=(0.0, 0.0), goal=(0.5, 0.5))
    start = time.time()
    rewards, lengths = evaluate_policy(agent, eval_env, n_eval_episodes=1, return_episode_rewards=True)
    print(f"0 {rewards[0]:.2f}/{lengths[0]} 0")
    for chunk in range(5):
        agent.learn(args.timesteps // 5, reset_num_timesteps=chunk == 0)
        rewards, lengths = evaluate_policy(agent, eval_env, n_eval_episodes=1, return_episode_rewards=True)
        print(f"{agent.num_timesteps} {rewards[0]:.2f}/{lengths[0]} {time.time() - start:.0f}", flush=True)


if __name__ == "__main__":
    main()
