"""Diagnose a Sawyer agent: where its plans say the finger will be, and where the finger really goes.

Usage:
    python scripts/sawyer_plan_gap.py runs/results/pretrained_random/sawyer/ebm/seed_0/model.zip [--steps 150]

Runs one deterministic evaluation episode of ``ebm/SawyerReach-v0`` (the harness's evaluation seed) and prints,
every ``--every`` steps: the real finger-to-target distance, the distance the current plan claims for its last state
(the finger xyz dims of the plan), the largest |planned - real| state error of the step just taken, and the largest
|torque| (1 is the actuator limit). The finger xyz are state dims of their own, so a planner can move them towards
the target in a plan whose joint dims do not put the finger there; the inverse dynamics follows the joint dims. A
plan that keeps claiming the goal while the real distance grows is such a plan.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np
import torch

import envs  # noqa: F401  (registers ebm/SawyerReach-v0)
from ebm_agent import EBMPlannerAgent
from eval.jobs import EVAL_SEED_OFFSET


def main(argv: list[str] | None = None) -> list[dict[str, float]]:
    """Print the gap between the plans and the real finger along one episode.

    :param argv: command-line arguments (None: ``sys.argv``).
    :return: one row per printed step: ``step``, ``distance``, ``plan_end_distance``, ``plan_error``, ``max_torque``.
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="a saved EBMPlannerAgent trained on ebm/SawyerReach-v0")
    parser.add_argument("--steps", type=int, default=150, help="steps of the episode to run")
    parser.add_argument("--every", type=int, default=10, help="print every this many steps")
    parser.add_argument("--seed", type=int, default=EVAL_SEED_OFFSET, help="reset seed (the harness's evaluation)")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    env = gym.make("ebm/SawyerReach-v0")
    agent = EBMPlannerAgent.load(args.model, env=env)
    spec = agent.goal_spec
    assert spec is not None
    obs, _ = env.reset(seed=args.seed)
    state, start, rows = None, True, []
    print("| step | finger to target (m) | plan's last state to target (m) | max plan error | max torque |")
    print("|---|---|---|---|---|")
    for step in range(args.steps):
        action, state = agent.predict(obs, state=state, episode_start=np.array([start]), deterministic=True)
        start = False
        plans, _, steps = state  # [1, T+1, D], planned actions, [1] steps of the plan taken after this one
        goal = np.asarray(obs["desired_goal"])
        distance = float(np.linalg.norm(obs["observation"][spec.goal_indices] - goal))
        plan_end = float(np.linalg.norm(plans[0, -1, spec.goal_indices] - goal))
        planned_next = plans[0, int(steps[0])]  # the state this action should reach
        obs, _, terminated, truncated, _ = env.step(action)
        error = float(np.abs(planned_next - obs["observation"]).max())
        if step % args.every == 0:
            row = {
                "step": step,
                "distance": distance,
                "plan_end_distance": plan_end,
                "plan_error": error,
                "max_torque": float(np.abs(action).max()),
            }
            rows.append(row)
            print(f"| {step} | {distance:.3f} | {plan_end:.3f} | {error:.3f} | {row['max_torque']:.2f} |")
        if terminated or truncated:
            break
    return rows


if __name__ == "__main__":
    main()
