"""Probe: the maze coverage of the goal-free exploring EBM (paper Fig. 7) with some of its settings changed.

Usage:
    python scripts/maze_explore_probe.py "online={replay_positives: false}" --seed 0
    python scripts/maze_explore_probe.py "cost={goal_weight: 0.0, acceleration_weight: 0.0}" --seed 0

Trains the EBM of ``ebm-eval --experiment maze_exploration`` (its budget, planner settings and goal-free cost
``{"goal_weight": 0}``) for one seed with the given keyword arguments of the agent replaced (values in YAML; a
``cost`` given here replaces the goal-free one, so keep ``goal_weight: 0.0`` in it), and prints its coverage of the
20 x 20 maze grid at 10 points of training. Compare with the figure's per-seed coverage in
``runs/results/figures/maze_exploration/figure.json`` (``agents.ebm.coverage.per_seed``).
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import torch
import yaml

import envs  # noqa: F401  (registers ebm/Maze-v0)
from eval.paper.figures.callbacks import VisitedStatesCallback, grid_coverage, linear_checkpoints
from eval.paper.figures.common import budget_for, build_ebm
from eval.paper.figures.exploration import MAZE_BINS, NO_GOAL


def main(argv: list[str] | None = None) -> list[tuple[int, float]]:
    """Train the changed explorer and print its coverage curve.

    :param argv: command-line arguments (None: ``sys.argv``).
    :return: (transitions, coverage) at each checkpoint.
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("changes", nargs="*", help="KEY=VALUE agent arguments, the value in YAML")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--scale", default="paper", help="paper (50,000 transitions) or smoke")
    parser.add_argument("--points", type=int, default=10, help="checkpoints of the coverage curve")
    args = parser.parse_args(argv)
    changes: dict[str, object] = {"cost": NO_GOAL}
    for text in args.changes:
        key, sep, value = text.partition("=")
        if not sep or not key:
            parser.error(f"expected KEY=VALUE, got {text!r}")
        changes[key] = yaml.safe_load(value)
    torch.set_num_threads(1)
    budget = budget_for(args.scale)
    start = time.perf_counter()
    agent = build_ebm(gym.make("ebm/Maze-v0"), args.seed, budget, **changes)  # type: ignore[arg-type]
    callback = VisitedStatesCallback(
        linear_checkpoints(budget.maze_timesteps, args.points), lambda states: grid_coverage(states, MAZE_BINS)
    )
    agent.learn(budget.maze_timesteps, callback=callback)
    curve = [(int(t), float(c)) for t, c in zip(callback.curve_timesteps, callback.curve_values)]
    print(f"maze coverage, seed {args.seed}, changes {changes}:")
    print("  " + ", ".join(f"{t}: {c:.4f}" for t, c in curve))
    print(f"  {(time.perf_counter() - start) / 60:.1f} min")
    return curve


if __name__ == "__main__":
    main()
