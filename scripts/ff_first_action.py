"""Diagnose a particle Action FF: how much does its final-state cost pin down the first action of a plan?

Usage:
    python scripts/ff_first_action.py runs/probe/table1/particle/pretrained/action-ff/residual-True/.../model.zip
    python scripts/ff_first_action.py <model.zip> --state 0.4 0.4 --plans 8 --steps 100

The paper's Action FF scores a plan by the L2 distance of its final predicted state to the goal, and nothing else.
Once the goal is within T moves, many action sequences end on it, and their first actions (the one the agent acts
on) can point anywhere. This script plans ``--plans`` times from ``--state`` with different noise seeds and prints
each plan's first action, its predicted path length and its final distance, next to the straight-line distance.
Then it runs one deterministic episode from the paper's start (0, 0) to the goal (0.5, 0.5) and prints the real
path's length, the steps taken and whether the goal was reached; the shortest path is 10 moves of length 0.0707.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np
import torch

import envs  # noqa: F401  (registers ebm/Particle-v0)
from baselines.action_ff import ActionFFAgent
from eval.paper.figures.common import run_episode

START, GOAL = (0.0, 0.0), (0.5, 0.5)
"""The paper's particle start and goal (DESIGN.md)."""


def plan_spread(agent: ActionFFAgent, state: np.ndarray, goal: np.ndarray, plans: int) -> list[dict[str, object]]:
    """Plan ``plans`` times from one state with noise seeds 0, 1, ...

    :param agent: a particle Action FF.
    :param state: [2] start position.
    :param goal: [2] goal position.
    :param plans: how many plans.
    :return: per plan, its first action [2], predicted path length and predicted final distance to the goal.
    """
    start = torch.as_tensor(state, dtype=torch.float32, device=agent.device)[None]  # [1, 2]
    target = torch.as_tensor(goal, dtype=torch.float32, device=agent.device)[None]  # [1, 2]
    rows = []
    for seed in range(plans):
        generator = torch.Generator(device=agent.device).manual_seed(seed)
        predicted, actions, distance = agent.planner.plan(agent.dynamics_model, start, target, generator)
        path = predicted[0].cpu().numpy()  # [T+1, 2]
        rows.append(
            {
                "first_action": [round(float(a), 3) for a in actions[0, 0]],
                "path_length": float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()),
                "final_distance": float(distance[0]),
            }
        )
    return rows


def episode(agent: ActionFFAgent, steps: int) -> dict[str, float]:
    """One deterministic episode from the paper's start to its goal (``eval.paper.figures.common.run_episode``).

    :param agent: a particle Action FF.
    :param steps: the episode's step limit.
    :return: steps taken, real path length, final distance to the goal and success (1.0 or 0.0).
    """
    env = gym.make("ebm/Particle-v0", start=START, goal=GOAL, max_episode_steps=steps)
    _score, path, success = run_episode(agent, env, seed=0)  # path: [steps + 1, 2] positions
    return {
        "steps": float(len(path) - 1),
        "path_length": float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()),
        "final_distance": float(np.linalg.norm(path[-1] - np.asarray(GOAL))),
        "success": float(success),
    }


def main(argv: list[str] | None = None) -> tuple[list[dict[str, object]], dict[str, float]]:
    """Print the plans' spread and the episode.

    :param argv: the arguments (default: the command line).
    :return: (the plans' rows, the episode's summary).
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="a particle Action FF's model.zip")
    parser.add_argument("--state", nargs=2, type=float, default=(0.4, 0.4), help="where to plan from")
    parser.add_argument("--plans", type=int, default=8, help="plans from --state, one noise seed each")
    parser.add_argument("--steps", type=int, default=100, help="the episode's step limit (the env's: 100)")
    args = parser.parse_args(argv)
    env = gym.make("ebm/Particle-v0", start=START, goal=GOAL)
    agent = ActionFFAgent.load(args.model, env=env, device="cpu")
    state, goal = np.asarray(args.state, dtype=np.float32), np.asarray(GOAL, dtype=np.float32)
    print(
        f"horizon T = {agent.planner_config.horizon}; from {args.state} to {GOAL}: "
        f"straight line {np.linalg.norm(goal - state):.3f}"
    )
    rows = plan_spread(agent, state, goal, args.plans)
    print("| noise seed | first action | predicted path length | predicted final distance |")
    print("|---|---|---|---|")
    for seed, row in enumerate(rows):
        print(f"| {seed} | {tuple(row['first_action'])} | {row['path_length']:.3f} | {row['final_distance']:.4f} |")
    summary = episode(agent, args.steps)
    print(
        f"episode from {list(START)}: {summary['steps']:.0f} steps, path length {summary['path_length']:.3f} "
        f"(shortest 0.707), final distance {summary['final_distance']:.3f}, success {summary['success']:.0f}"
    )
    return rows, summary


if __name__ == "__main__":
    main()
