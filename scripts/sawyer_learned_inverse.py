"""Why an EBM with learned inverse dynamics (MLP or RLS) fails on the Sawyer: the model, the plans, or both.

Usage:
    python scripts/sawyer_learned_inverse.py runs/results/online_invdyn_rls/sawyer/ebm/seed_0/model.zip
        [--steps 300] [--every 50] [--real 1000]

Loads a Sawyer EBM trained online with ``inverse_dynamics="mlp"`` or ``"rls"`` (the inverse-dynamics ablation) and
prints three tables:

1. On ``--real`` real transitions (half the env's exploration actions, half uniform torques): the mean |error| of
   the learned model's actions against the actions that made them, beside the env's ground-truth inverse dynamics'
   error. This says whether the model learned the arm's dynamics where it has data.
2. One deterministic evaluation episode (the harness's evaluation seed), acting with the learned model, every
   ``--every`` steps: the finger-to-target distance, the largest |planned - real| state error of the step, the
   largest |torque| of the learned action, and the mean |learned - ground truth| action for the same (state,
   planned next state) pair. This says what the model does with the plans it is given.
3. The first ``--steps`` steps of that episode acting with the learned model, and again with the same energy and
   planner but the ground-truth inverse dynamics: the return of each. This says whether the plans themselves are
   usable.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import torch

import envs  # noqa: F401  (registers ebm/SawyerReach-v0)
from ebm_agent import EBMPlannerAgent
from ebm_agent.goal_spec import env_inverse_dynamics
from eval.jobs import EVAL_SEED_OFFSET
from eval.plan_trace import sawyer_real_transitions, trace_plans

InverseFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


def real_errors(learned: InverseFn, truth: InverseFn, count: int) -> dict[str, float]:
    """Mean |action error| of the learned and of the ground-truth inverse dynamics on real transitions.

    :param learned: the learned model: ``(states [B, 20], next states [B, 20]) -> actions [B, 7]``.
    :param truth: the env's ground-truth inverse dynamics, same signature.
    :param count: how many real transitions.
    :return: ``learned_error``, ``truth_error`` (mean over transitions and joints) and ``mean_abs_action`` (of the
        true actions, the scale of the errors).
    """
    states, next_states, actions = sawyer_real_transitions(count)
    return {
        "learned_error": float(np.abs(learned(states, next_states) - actions).mean()),
        "truth_error": float(np.abs(truth(states, next_states) - actions).mean()),
        "mean_abs_action": float(np.abs(actions).mean()),
    }


def episode(agent: EBMPlannerAgent, env: gym.Env, steps: int, every: int, truth: InverseFn) -> dict[str, Any]:
    """Act for ``steps`` steps of one evaluation episode and record, every ``every`` steps, how the actions compare.

    :param agent: the loaded agent, acting with whatever inverse dynamics it holds.
    :param env: its env.
    :param steps: steps to run.
    :param every: recording interval.
    :param truth: the ground-truth inverse dynamics, to compare the agent's action with.
    :return: ``rows`` (one dict per recorded step: ``step``, ``distance``, ``plan_error``, ``max_torque``,
        ``action_gap``) and ``return`` (the sum of the rewards of the steps run).
    """
    spec = agent.goal_spec
    assert spec is not None
    rows, total = [], 0.0
    for traced in trace_plans(agent, env, steps, EVAL_SEED_OFFSET):
        total += traced.reward
        if traced.step % every:
            continue
        state = np.asarray(traced.obs["observation"], dtype=np.float32)[None]  # [1, 20]
        wanted = np.asarray(traced.planned_next, dtype=np.float32)[None]  # [1, 20]
        rows.append(
            {
                "step": traced.step,
                "distance": float(np.linalg.norm(state[0, spec.goal_indices] - traced.obs["desired_goal"])),
                "plan_error": float(np.abs(traced.planned_next - traced.next_obs["observation"]).max()),
                "max_torque": float(np.abs(traced.action).max()),
                "action_gap": float(np.abs(np.asarray(traced.action) - truth(state, wanted)[0]).mean()),
            }
        )
    return {"rows": rows, "return": total}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Print the three tables.

    :param argv: command-line arguments (None: ``sys.argv``).
    :return: ``{"real": real_errors(...), "learned": episode(...), "ground_truth_return": float, "kind": str}``.
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="a Sawyer EBMPlannerAgent trained with inverse_dynamics='mlp' or 'rls'")
    parser.add_argument("--steps", type=int, default=300, help="steps of the evaluation episode to run")
    parser.add_argument("--every", type=int, default=50, help="print every this many steps")
    parser.add_argument("--real", type=int, default=1000, help="real transitions to check the model on")
    args = parser.parse_args(argv)
    if args.steps < 1 or args.every < 1 or args.real < 1:
        parser.error("--steps, --every and --real must be >= 1")
    torch.set_num_threads(1)
    env = gym.make("ebm/SawyerReach-v0")
    agent = EBMPlannerAgent.load(args.model, env=env)
    kind = agent.inverse_dynamics_kind
    if kind not in ("mlp", "rls"):
        parser.error(f"{args.model} acts with inverse_dynamics={kind!r}; give a model trained with 'mlp' or 'rls'")
    truth = env_inverse_dynamics(agent.get_env())  # type: ignore[arg-type]
    assert truth is not None and agent.inverse_model is not None
    results: dict[str, Any] = {"kind": kind, "real": real_errors(agent.inverse_model, truth, args.real)}
    real = results["real"]
    print(f"Real transitions ({args.real}; mean |true action| {real['mean_abs_action']:.3f}):\n")
    print("| inverse dynamics | mean abs action error |\n|---|---|")
    print(f"| learned ({kind}) | {real['learned_error']:.3f} |\n| ground truth | {real['truth_error']:.3f} |\n")

    results["learned"] = episode(agent, env, args.steps, args.every, truth)
    print(f"Evaluation episode acting with the learned model ({kind}):\n")
    print("| step | finger to target (m) | max plan error | max torque | mean abs (learned - ground truth) action |")
    print("|---|---|---|---|---|")
    for row in results["learned"]["rows"]:
        print(
            f"| {row['step']} | {row['distance']:.3f} | {row['plan_error']:.3f} | {row['max_torque']:.2f} "
            f"| {row['action_gap']:.3f} |"
        )

    agent.inverse_dynamics_kind = "ground_truth"
    agent._build_inverse_dynamics()  # the same energy and planner, the env's inverse dynamics
    results["ground_truth_return"] = episode(agent, env, args.steps, args.steps, truth)["return"]
    print(f"\nReturn over the first {args.steps} steps of the evaluation episode, same energy and planner:\n")
    print("| inverse dynamics | return |\n|---|---|")
    print(f"| learned ({kind}) | {results['learned']['return']:.2f} |")
    print(f"| ground truth | {results['ground_truth_return']:.2f} |")
    return results


if __name__ == "__main__":
    main()
