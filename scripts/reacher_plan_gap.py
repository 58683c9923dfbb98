"""Diagnose a Reacher agent: whether its plans move the angles as their velocities say, and what the arm then does.

Usage:
    python scripts/reacher_plan_gap.py runs/results/pretrained_random/reacher/ebm/seed_0/model.zip [--steps 50]
        [--angle-weight 1]

Runs one deterministic evaluation episode of ``ebm/Reacher-v0`` (the harness's evaluation seed) and prints, every
``--every`` steps: the real wrapped-L1 distance of the angles to the goal, the distance the current plan claims for
its last state, the plan's velocity inconsistency (the mean |planned angle change - the change its velocities give|
over the plan's transitions, in normalised angle units), the largest |planned - real| state error of the step just
taken, the largest |torque| (1 is the actuator limit) and whether a new plan started; at the end, the return and the
number of plans made. A plan that jumps its angles towards the goal without the velocities that would carry them
there is fitted by the inverse dynamics on its velocity dims, which then ask for almost no torque.
``--angle-weight`` sets the env's ``inverse_angle_weight`` (default: the env's).
"""

from __future__ import annotations

import math

import numpy as np

import envs  # noqa: F401  (registers ebm/Reacher-v0)
from envs.reacher import ReacherEnv, wrap_difference, wrapped_l1_distance
from eval.plan_trace import load_traced_agent, trace_parser, trace_plans


def velocity_inconsistency(plan: np.ndarray, dt: float) -> float:
    """Mean |planned angle change - the change the plan's own velocities give| over a plan's transitions.

    A step of constant torque moves an angle by dt * (w_t + w_{t+1}) / 2 rad (w the joint velocity), that is by
    dt * 10 * (v_t + v_{t+1}) / (2 pi) in the state's units (angle / pi, velocity / 10).

    :param plan: [T+1, 4] planned states.
    :param dt: seconds per env step.
    :return: the mean over the T transitions and 2 joints.
    """
    change = np.diff(plan[:, :2], axis=0)  # [T, 2]
    change = wrap_difference(change)  # the angles are periodic
    implied = dt * 10.0 * (plan[:-1, 2:] + plan[1:, 2:]) / (2.0 * math.pi)  # [T, 2]
    return float(np.abs(change - implied).mean())


def state_difference(planned: np.ndarray, real: np.ndarray) -> np.ndarray:
    """planned - real [4], the angle dims wrapped into [-1, 1) (plans may run past the seam at +-1)."""
    difference = np.asarray(planned, dtype=np.float64) - np.asarray(real, dtype=np.float64)
    difference[:2] = wrap_difference(difference[:2])
    return difference


def main(argv: list[str] | None = None) -> list[dict[str, float]]:
    """Print the gap between the plans and the arm along one episode.

    :param argv: command-line arguments (None: ``sys.argv``).
    :return: one row per printed step: ``step``, ``distance``, ``plan_end_distance``, ``plan_inconsistency``,
        ``plan_error``, ``max_torque``, ``new_plan``; the last row also ``return`` and ``plans``.
    """
    parser = trace_parser(__doc__.splitlines()[0], "ebm/Reacher-v0", 50, 5, "--angle-weight")
    args, env, agent = load_traced_agent(parser, argv, "ebm/Reacher-v0")
    dt = env.unwrapped.dt  # type: ignore[attr-defined]
    assert isinstance(env.unwrapped, ReacherEnv)
    rows, total, plans = [], 0.0, 0
    print(
        "| step | distance to goal | plan's last state to goal | plan velocity inconsistency | plan error "
        "| max torque | new plan |"
    )
    print("|---|---|---|---|---|---|---|")
    for traced in trace_plans(agent, env, args.steps, args.seed):
        total += traced.reward
        plans += traced.plan_index == 1
        if traced.step % args.every:
            continue
        goal = np.asarray(traced.obs["desired_goal"])
        row = {
            "step": traced.step,
            "distance": float(wrapped_l1_distance(traced.obs["achieved_goal"], goal)),
            "plan_end_distance": float(wrapped_l1_distance(traced.plan[-1, :2], goal)),
            "plan_inconsistency": velocity_inconsistency(traced.plan, dt),
            "plan_error": float(np.abs(state_difference(traced.planned_next, traced.next_obs["observation"])).max()),
            "max_torque": float(np.abs(traced.action).max()),
            "new_plan": float(traced.plan_index == 1),
        }
        rows.append(row)
        print(
            f"| {row['step']} | {row['distance']:.3f} | {row['plan_end_distance']:.3f} | {row['plan_inconsistency']:.4f} "
            f"| {row['plan_error']:.3f} | {row['max_torque']:.2f} | {'yes' if row['new_plan'] else 'no'} |"
        )
    print(f"return over {traced.step + 1} steps: {total:.2f}; plans made: {plans}")
    if rows:
        rows[-1].update({"return": total, "plans": float(plans)})
    return rows


if __name__ == "__main__":
    main()
