"""Diagnose a Sawyer agent: where its plans say the finger will be, and where the finger really goes.

Usage:
    python scripts/sawyer_plan_gap.py runs/results/pretrained_random/sawyer/ebm/seed_0/model.zip [--steps 150]
        [--finger-weight 0]

Runs one deterministic evaluation episode of ``ebm/SawyerReach-v0`` (the harness's evaluation seed) and prints,
every ``--every`` steps: the real finger-to-target distance, the distance the current plan claims for its last state
(the finger xyz dims of the plan), the mean distance between the plan's finger dims and the finger that forward
kinematics puts at the plan's joint dims, the largest |planned - real| state error of the step just taken, and the
largest |torque| (1 is the actuator limit); at the end, the return of the steps run. The finger xyz are state dims
of their own, so a planner can move them towards the target in a plan whose joint dims do not put the finger there.
``--finger-weight`` sets the env's ``inverse_finger_weight`` (how much the inverse dynamics follows the plan's finger
rather than its joints; default: the env's).
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import mujoco
import numpy as np
import torch

import envs  # noqa: F401  (registers ebm/SawyerReach-v0)
from ebm_agent import EBMPlannerAgent
from eval.jobs import EVAL_SEED_OFFSET


def main(argv: list[str] | None = None) -> list[dict[str, float]]:
    """Print the gap between the plans and the real finger along one episode.

    :param argv: command-line arguments (None: ``sys.argv``).
    :return: one row per printed step: ``step``, ``distance``, ``plan_end_distance``, ``plan_inconsistency``,
        ``plan_error``, ``max_torque``, ``return`` (so far).
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="a saved EBMPlannerAgent trained on ebm/SawyerReach-v0")
    parser.add_argument("--steps", type=int, default=150, help="steps of the episode to run")
    parser.add_argument("--every", type=int, default=10, help="print every this many steps")
    parser.add_argument("--seed", type=int, default=EVAL_SEED_OFFSET, help="reset seed (the harness's evaluation)")
    parser.add_argument("--finger-weight", type=float, help="the env's inverse_finger_weight (default: the env's)")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    env_kwargs = {} if args.finger_weight is None else {"inverse_finger_weight": args.finger_weight}
    env = gym.make("ebm/SawyerReach-v0", **env_kwargs)
    agent = EBMPlannerAgent.load(args.model, env=env)
    spec = agent.goal_spec
    assert spec is not None
    kinematics = _FingerKinematics(env.unwrapped)  # type: ignore[arg-type]
    obs, _ = env.reset(seed=args.seed)
    state, start, rows, total = None, True, [], 0.0
    print(
        "| step | finger to target (m) | plan's last state to target (m) | plan finger vs FK of plan joints (m) "
        "| max plan error | max torque |"
    )
    print("|---|---|---|---|---|---|")
    for step in range(args.steps):
        action, state = agent.predict(obs, state=state, episode_start=np.array([start]), deterministic=True)
        start = False
        plans, _, steps = state  # [1, T+1, D], planned actions, [1] steps of the plan taken after this one
        goal = np.asarray(obs["desired_goal"])
        distance = float(np.linalg.norm(obs["observation"][spec.goal_indices] - goal))
        plan_end = float(np.linalg.norm(plans[0, -1, spec.goal_indices] - goal))
        planned_next = plans[0, int(steps[0])]  # the state this action should reach
        inconsistency = kinematics.gap(plans[0, 1:])
        obs, reward, terminated, truncated, _ = env.step(action)
        total += float(reward)
        error = float(np.abs(planned_next - obs["observation"]).max())
        if step % args.every == 0:
            row = {
                "step": step,
                "distance": distance,
                "plan_end_distance": plan_end,
                "plan_inconsistency": inconsistency,
                "plan_error": error,
                "max_torque": float(np.abs(action).max()),
                "return": total,
            }
            rows.append(row)
            print(
                f"| {step} | {distance:.3f} | {plan_end:.3f} | {inconsistency:.3f} | {error:.3f} | {row['max_torque']:.2f} |"
            )
        if terminated or truncated:
            break
    print(f"return over {step + 1} steps: {total:.2f}")
    if rows:
        rows[-1]["return"] = total
    return rows


class _FingerKinematics:
    """Forward kinematics of the Sawyer's finger (the mean of the two pad sites) on a private MjData."""

    def __init__(self, env: gym.Env) -> None:
        self.model = env.unwrapped.model  # type: ignore[attr-defined]
        self.data = mujoco.MjData(self.model)
        self.sites = env.unwrapped._finger_sites  # type: ignore[attr-defined]

    def gap(self, states: np.ndarray) -> float:
        """Mean distance between the finger dims of planned states [T, 20] and the finger at their joint dims."""
        gaps = []
        for state in states:
            self.data.qpos[:] = state[:7]
            mujoco.mj_kinematics(self.model, self.data)
            finger = 0.5 * (self.data.site_xpos[self.sites[0]] + self.data.site_xpos[self.sites[1]])
            gaps.append(float(np.linalg.norm(finger - state[14:17])))
        return float(np.mean(gaps))


if __name__ == "__main__":
    main()
