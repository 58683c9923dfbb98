"""Probe: does a longer planning horizon get the pretrained maze EBM past the first wall?

Usage: python scripts/maze_horizon.py 30 [--seed 0] [--episodes 2] [--out runs/probe_maze_horizon]

Runs the Table 1 maze pretrained EBM job (``ebm-eval --experiment table1 --part table1/maze/pretrained``: 100,000
random transitions, 10 epochs) with only the horizon changed, and prints the score of its deterministic evaluation
episodes from the paper's start and the wall time. The maze's optimum is -73.67 and waiting at the first wall scores
about -1,210 to -1,240.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

from eval.paper.experiments import build_parts, make_context, select_parts
from eval.run import run_job


def main() -> None:
    """Run the probe."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("horizon", type=int, help="planned steps (the agent's default is 10)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--episodes", type=int, default=2, help="deterministic evaluation episodes")
    parser.add_argument("--out", default="runs/probe_maze_horizon", help="results folder (its own datasets cache)")
    args = parser.parse_args()
    context = make_context("paper", f"{args.out}/h{args.horizon}")
    part = select_parts(build_parts(["table1"], context), ["table1/maze/pretrained"])[0]
    job = next(job for cell in part.cells if cell.agent == "ebm" for job in cell.jobs if job.seed == args.seed)
    job = replace(job, hyperparams={**job.hyperparams, "horizon": args.horizon}, eval_episodes=args.episodes)
    result = run_job(job)
    scores = ", ".join(f"{score:.2f}" for score in result.episode_scores)
    print(f"horizon {args.horizon} seed {args.seed}: score {result.score_mean:.2f} ({scores}), {result.wall_time_s:.0f} s")


if __name__ == "__main__":
    main()
