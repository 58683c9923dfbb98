"""Diagnose a maze agent: does its energy tell a move through a wall from a free move, and where does it get stuck?

Usage:
    python scripts/maze_walls.py runs/results/pretrained_random/maze/ebm/seed_0/model.zip [--steps 300]

Prints the energy E(s, s') of a few hand-picked transitions of the maze (``ebm/Maze-v0``; the first wall is the
column x in [-0.5, 0) below y = 0.25, the boundary is |x|, |y| >= 0.99): free moves, a move into the wall, a move out
of the box, standing still and an impossible 0.2 jump. Then it runs one deterministic episode from the paper's start
and prints the position every 25 steps. A model that has learned the walls gives the two blocked moves energies well
above the free ones; the real env rejects a blocked move, so an agent whose plans go through a wall stands still.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import torch

import envs  # noqa: F401  (registers ebm/Maze-v0)
from ebm_agent import EBMPlannerAgent

TRANSITIONS = (
    ("free move from the start", (-0.85, -0.85), (-0.80, -0.80)),
    ("free move up along the wall", (-0.55, -0.80), (-0.55, -0.75)),
    ("free move in column 1 above the wall", (-0.30, 0.50), (-0.25, 0.50)),
    ("blocked: into the first wall", (-0.52, -0.80), (-0.47, -0.80)),
    ("blocked: out of the box", (-0.70, -0.97), (-0.70, -1.02)),
    ("standing still at the wall", (-0.52, -0.80), (-0.52, -0.80)),
    ("impossible: a 0.2 jump", (-0.85, -0.85), (-0.65, -0.85)),
)
"""(what, s, s') pairs in the maze's coordinates."""


def main(argv: list[str] | None = None) -> tuple[dict[str, float], list[list[float]]]:
    """Print the energies and the rollout.

    :param argv: the arguments (default: the command line).
    :return: (energy of each transition by its description, positions every 25 steps from the start).
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="a saved EBMPlannerAgent trained on ebm/Maze-v0")
    parser.add_argument("--steps", type=int, default=300, help="steps of the deterministic rollout")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    env = gym.make("ebm/Maze-v0")
    agent = EBMPlannerAgent.load(args.model, env=env, device="cpu")
    states = torch.tensor([s for _, s, _ in TRANSITIONS], dtype=torch.float32)  # [M, 2]
    next_states = torch.tensor([n for _, _, n in TRANSITIONS], dtype=torch.float32)  # [M, 2]
    with torch.no_grad():
        energies = agent.energy_model(states, next_states).numpy()  # [M]
    print("| transition | s | s' | energy |\n|---|---|---|---|")
    for (what, s, n), energy in zip(TRANSITIONS, energies, strict=True):
        print(f"| {what} | {s} | {n} | {energy:.3f} |")
    obs, _ = env.reset(seed=0)
    positions = [[round(float(x), 3) for x in obs["observation"]]]
    for step in range(1, args.steps + 1):
        action, _ = agent.predict(obs, deterministic=True)
        obs, _, terminated, truncated, _ = env.step(action)
        if step % 25 == 0:
            positions.append([round(float(x), 3) for x in obs["observation"]])
        if terminated or truncated:
            break
    print(f"\npositions every 25 steps from {positions[0]}: {positions[1:]}")
    print(f"goal {[round(float(x), 3) for x in obs['desired_goal']]}")
    return {what: float(energy) for (what, _, _), energy in zip(TRANSITIONS, energies, strict=True)}, positions


if __name__ == "__main__":
    main()
