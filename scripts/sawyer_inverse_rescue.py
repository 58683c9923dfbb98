"""What the Sawyer inverse dynamics' multi-start rescue buys, on real transitions and on a planner's wanted ones.

Usage:
    python scripts/sawyer_inverse_rescue.py <a saved Sawyer EBM model.zip> [--plan-steps 100] [--real 1000]

Collects two sets of (state, wanted next state) pairs: ``--real`` real transitions of ``ebm/SawyerReach-v0`` (half
from ``sample_exploration_action``, half from uniform torques in [-1, 1]), and the planned next states of the
model's first ``--plan-steps`` deterministic evaluation steps (the harness's evaluation seed). Each set is solved
with the rescue on every stalled sample (``inverse_rescue_ceiling=None``) and with the env's default ceiling, and
the script prints, per set: how many samples stall after Gauss-Newton (residual norm > the rescue tolerance), the
quantiles of their residual norms, how much the rescue lowers their squared residual, the largest action error
(real set: against the actions that made the transitions), and the milliseconds per sample of each setting.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np
import torch

import envs  # noqa: F401  (registers ebm/SawyerReach-v0)
from ebm_agent import EBMPlannerAgent
from envs.sawyer import INVERSE_RESCUE_CEILING, SawyerReachEnv
from eval.jobs import EVAL_SEED_OFFSET
from eval.plan_trace import sawyer_real_transitions


def planned_transitions(model: str, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """The (real state [B, 20], planned next state [B, 20]) pairs of a model's first evaluation steps."""
    env = gym.make("ebm/SawyerReach-v0")
    agent = EBMPlannerAgent.load(model, env=env)
    obs, _ = env.reset(seed=EVAL_SEED_OFFSET)
    state, start, states, wanted = None, True, [], []
    for _ in range(steps):
        action, state = agent.predict(obs, state=state, episode_start=np.array([start]), deterministic=True)
        start = False
        plans, _, taken = state  # [1, T+1, D], planned actions, [1] steps of the plan taken after this one
        states.append(obs["observation"])
        wanted.append(plans[0, int(taken[0])])
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    return np.array(states), np.array(wanted)


def compare(states: np.ndarray, wanted: np.ndarray, actions: np.ndarray | None = None) -> dict[str, float]:
    """Solve every pair without and with the default ceiling; the stalled samples' statistics.

    :param states: [B, 20] start states.
    :param wanted: [B, 20] wanted next states.
    :param actions: [B, 7] the true actions, or None.
    :return: ``stalled``, residual quantiles ``residual_p10/p50/p90/max``, ``gain_p50``, ``gain_p90`` and
        ``gain_max`` (fraction of the squared residual the rescue removes, every-sample rescue), ``error_all`` /
        ``error_ceiling`` (largest action error, real set only), ``ms_all`` / ``ms_ceiling`` per sample.
    """
    out: dict[str, float] = {}
    costs, recovered = {}, {}
    for label, ceiling in (("no_rescue", None), ("all", None), ("ceiling", INVERSE_RESCUE_CEILING)):
        env = SawyerReachEnv(inverse_rescue_ceiling=ceiling)
        if label == "no_rescue":
            env._inverse.rescue_tolerance = None
        began = time.perf_counter()
        recovered[label], costs[label] = env._solve_inverse(states.astype(np.float64), wanted.astype(np.float64))
        elapsed = time.perf_counter() - began
        if label != "no_rescue":
            out[f"ms_{label}"] = 1000.0 * elapsed / len(states)
    tolerance = SawyerReachEnv()._inverse.rescue_tolerance
    assert tolerance is not None
    stalled = costs["no_rescue"] > tolerance**2
    norms = np.sqrt(costs["no_rescue"][stalled])
    out["stalled"] = float(stalled.sum())
    for name, q in (("p10", 0.1), ("p50", 0.5), ("p90", 0.9), ("max", 1.0)):
        out[f"residual_{name}"] = float(np.quantile(norms, q)) if norms.size else float("nan")
    gain = 1.0 - costs["all"][stalled] / np.maximum(costs["no_rescue"][stalled], 1e-300)
    out["gain_p50"] = float(np.quantile(gain, 0.5)) if gain.size else float("nan")
    out["gain_p90"] = float(np.quantile(gain, 0.9)) if gain.size else float("nan")
    out["gain_max"] = float(gain.max()) if gain.size else float("nan")
    if actions is not None:
        out["error_all"] = float(np.abs(recovered["all"] - actions).max())
        out["error_ceiling"] = float(np.abs(recovered["ceiling"] - actions).max())
    return out


def main(argv: list[str] | None = None) -> dict[str, dict[str, float]]:
    """Print the comparison for the real and the planned set.

    :param argv: command-line arguments (None: ``sys.argv``).
    :return: ``{"real": ..., "planned": ...}``, each as ``compare`` returns it.
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="a saved EBMPlannerAgent trained on ebm/SawyerReach-v0")
    parser.add_argument("--plan-steps", type=int, default=100, help="evaluation steps whose plans are collected")
    parser.add_argument("--real", type=int, default=1000, help="real transitions collected")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    states, next_states, actions = sawyer_real_transitions(args.real)
    results = {"real": compare(states, next_states, actions)}
    results["planned"] = compare(*planned_transitions(args.model, args.plan_steps))
    print(
        "| set | pairs | stalled | stalled residual p10 / p50 / p90 / max | rescue gain p50 / p90 / max | max action error "
        "(rescue all / ceiling) | ms per pair (rescue all / ceiling) |"
    )
    print("|---|---|---|---|---|---|---|")
    for name, pairs in (("real", len(states)), ("planned", args.plan_steps)):
        row = results[name]
        errors = f"{row['error_all']:.2g} / {row['error_ceiling']:.2g}" if "error_all" in row else "-"
        residuals = " / ".join(f"{row[f'residual_{q}']:.3g}" for q in ("p10", "p50", "p90", "max"))
        gains = " / ".join(f"{row[f'gain_{q}']:.2%}" for q in ("p50", "p90", "max"))
        print(
            f"| {name} | {pairs} | {row['stalled']:.0f} | {residuals} | {gains} | {errors} | "
            f"{row['ms_all']:.1f} / {row['ms_ceiling']:.1f} |"
        )
    return results


if __name__ == "__main__":
    main()
