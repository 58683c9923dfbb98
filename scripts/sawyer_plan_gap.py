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

import gymnasium as gym
import mujoco
import numpy as np

import envs  # noqa: F401  (registers ebm/SawyerReach-v0)
from eval.plan_trace import load_traced_agent, trace_parser, trace_plans


def main(argv: list[str] | None = None) -> list[dict[str, float]]:
    """Print the gap between the plans and the real finger along one episode.

    :param argv: command-line arguments (None: ``sys.argv``).
    :return: one row per printed step: ``step``, ``distance``, ``plan_end_distance``, ``plan_inconsistency``,
        ``plan_error``, ``max_torque``, ``return`` (so far).
    """
    parser = trace_parser(__doc__.splitlines()[0], "ebm/SawyerReach-v0", 150, 10, "--finger-weight")
    args, env, agent = load_traced_agent(parser, argv, "ebm/SawyerReach-v0")
    spec = agent.goal_spec
    assert spec is not None
    kinematics = _FingerKinematics(env.unwrapped)  # type: ignore[arg-type]
    rows, total = [], 0.0
    print(
        "| step | finger to target (m) | plan's last state to target (m) | plan finger vs FK of plan joints (m) "
        "| max plan error | max torque |"
    )
    print("|---|---|---|---|---|---|")
    for traced in trace_plans(agent, env, args.steps, args.seed):
        total += traced.reward
        if traced.step % args.every:
            continue
        goal = np.asarray(traced.obs["desired_goal"])
        row = {
            "step": traced.step,
            "distance": float(np.linalg.norm(traced.obs["observation"][spec.goal_indices] - goal)),
            "plan_end_distance": float(np.linalg.norm(traced.plan[-1, spec.goal_indices] - goal)),
            "plan_inconsistency": kinematics.gap(traced.plan[1:]),
            "plan_error": float(np.abs(traced.planned_next - traced.next_obs["observation"]).max()),
            "max_torque": float(np.abs(traced.action).max()),
            "return": total,
        }
        rows.append(row)
        print(
            f"| {row['step']} | {row['distance']:.3f} | {row['plan_end_distance']:.3f} | {row['plan_inconsistency']:.3f} "
            f"| {row['plan_error']:.3f} | {row['max_torque']:.2f} |"
        )
    print(f"return over {traced.step + 1} steps: {total:.2f}")
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
