"""How well a pretrained Sawyer Action FF fits its dataset, real transitions and its own evaluation episode.

Usage:
    python scripts/sawyer_ff_fit.py runs/results/datasets/sawyer/directed_n100000_s0_<hash>.npz \
        runs/results/pretrained_directed/sawyer/action-ff/seed_0/model.zip [--samples 2000] [--steps 200]

Prints three tables:

1. The dataset's actions: per joint, the fraction at the torque limit (|a| >= 0.99) and the mean |a|. The
   directed dataset holds the real transitions of an EBM learning online, whose actions come from the env's
   ground-truth inverse dynamics; the random dataset holds the env's exploration actions.
2. The model's one-step error (mean |predicted - real next state|) per group of state dims (joint angles, joint
   velocities, finger xyz) beside the mean |change| of those dims, which is the error of predicting "no change":
   on ``--samples`` transitions of the dataset, on as many real transitions of the env's exploration actions, and
   on as many of uniform torques.
3. The Action FF agent acting for ``--steps`` steps of one deterministic evaluation episode (the harness's
   evaluation seed): the fraction of its torques at the limit, their mean |a|, the model's error and the change along
   the episode, and the return.
"""

from __future__ import annotations

import argparse
from typing import Any

import gymnasium as gym
import numpy as np
import torch

import envs  # noqa: F401  (registers ebm/SawyerReach-v0)
from baselines.action_ff import ActionFFAgent
from eval.jobs import EVAL_SEED_OFFSET
from eval.plan_trace import sawyer_real_transitions

GROUPS = {"joint angles": slice(0, 7), "joint velocities": slice(7, 14), "finger xyz": slice(14, 17)}
"""The Sawyer's state dims the actions move (the target dims 17:20 never change)."""
LIMIT = 0.99
"""|a| at or above this counts as the torque limit (the bounds are +-1)."""


def action_stats(actions: np.ndarray) -> dict[str, list[float]]:
    """Per joint: the fraction of actions at the limit and the mean |a|.

    :param actions: [B, 7].
    :return: ``at_limit`` and ``mean_abs``, one value per joint.
    """
    magnitude = np.abs(actions)  # [B, 7]
    return {"at_limit": (magnitude >= LIMIT).mean(axis=0).tolist(), "mean_abs": magnitude.mean(axis=0).tolist()}


def fit(model: torch.nn.Module, states: np.ndarray, next_states: np.ndarray, actions: np.ndarray) -> dict[str, Any]:
    """The model's one-step error and the no-change error per group of dims.

    :param model: the Action FF's ``ForwardDynamicsModel``: ``(states [B, 20], actions [B, 7]) -> next states``.
    :param states: [B, 20].
    :param next_states: [B, 20].
    :param actions: [B, 7].
    :return: ``{group: {"error": float, "change": float}}``.
    """
    device = next(model.parameters()).device  # a model loaded on a GPU machine is on CUDA
    with torch.no_grad():
        predicted = model(*(torch.as_tensor(a, dtype=torch.float32, device=device) for a in (states, actions)))
    predicted = predicted.cpu().numpy()  # [B, 20]
    return {
        group: {
            "error": float(np.abs(predicted - next_states)[:, dims].mean()),
            "change": float(np.abs(next_states - states)[:, dims].mean()),
        }
        for group, dims in GROUPS.items()
    }


def evaluation(agent: ActionFFAgent, steps: int) -> dict[str, Any]:
    """Act deterministically for ``steps`` steps of the evaluation episode; the actions taken and the model's fit.

    :param agent: the loaded agent (its env is used).
    :param steps: steps to run (the episode's end stops earlier).
    :return: ``actions`` (``action_stats`` of the torques taken), ``fit`` (as :func:`fit`) and ``return``.
    """
    env = gym.make("ebm/SawyerReach-v0")
    obs, _ = env.reset(seed=EVAL_SEED_OFFSET)
    state: Any = None
    states, next_states, actions, total = [], [], [], 0.0
    for step in range(steps):
        action, state = agent.predict(obs, state=state, episode_start=np.array([step == 0]), deterministic=True)
        next_obs, reward, terminated, truncated, _ = env.step(action)
        states.append(obs["observation"])
        next_states.append(next_obs["observation"])
        actions.append(np.asarray(action, dtype=np.float32).reshape(-1))
        total += float(reward)
        obs = next_obs
        if terminated or truncated:
            break
    taken = np.array(actions)  # [L, 7]
    return {
        "actions": action_stats(taken),
        "fit": fit(agent.dynamics_model, np.array(states), np.array(next_states), taken),
        "return": total,
    }


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Print the three tables.

    :param argv: command-line arguments (None: ``sys.argv``).
    :return: ``{"dataset_actions": ..., "fit": {"dataset": ..., "real exploration": ..., "real uniform": ...},
        "episode": evaluation(...)}``.
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset", help="the .npz the model was pretrained on (runs/results/datasets/sawyer/)")
    parser.add_argument("model", help="the pretrained Action FF's model.zip")
    parser.add_argument("--samples", type=int, default=2000, help="transitions of each set the fit is measured on")
    parser.add_argument("--steps", type=int, default=200, help="steps of the evaluation episode")
    args = parser.parse_args(argv)
    if args.samples < 2 or args.steps < 1:
        parser.error("--samples must be >= 2 and --steps >= 1")
    torch.set_num_threads(1)
    data = np.load(args.dataset)
    agent = ActionFFAgent.load(args.model, env=gym.make("ebm/SawyerReach-v0"))
    pick = np.random.default_rng(0).choice(len(data["actions"]), size=min(args.samples, len(data["actions"])), replace=False)
    states, next_states, actions = (data[key][pick] for key in ("states", "next_states", "actions"))
    real = {kind: sawyer_real_transitions(args.samples, actions=kind) for kind in ("exploration", "uniform")}
    results: dict[str, Any] = {
        "dataset_actions": action_stats(data["actions"]),
        "fit": {
            "dataset": fit(agent.dynamics_model, states, next_states, actions),
            **{f"real {kind}": fit(agent.dynamics_model, *transitions) for kind, transitions in real.items()},
        },
    }
    results["episode"] = evaluation(agent, args.steps)

    joints = " | ".join(f"j{joint}" for joint in range(7))
    print(f"Actions ({len(data['actions'])} in the dataset; {len(results['episode']['actions']['mean_abs'])} joints):\n")
    print(f"| set | statistic | {joints} |\n|---|---|{'---|' * 7}")
    for name, stats in (("dataset", results["dataset_actions"]), ("FF evaluation episode", results["episode"]["actions"])):
        print(f"| {name} | at the limit | " + " | ".join(f"{v:.2f}" for v in stats["at_limit"]) + " |")
        print(f"| {name} | mean abs | " + " | ".join(f"{v:.2f}" for v in stats["mean_abs"]) + " |")
    print("\nOne-step error of the model, against the error of predicting no change (mean |change|):\n")
    print("| set | " + " | ".join(f"{group}: error / change" for group in GROUPS) + " |")
    print("|---|" + "---|" * len(GROUPS))
    for name, groups in (*results["fit"].items(), ("FF evaluation episode", results["episode"]["fit"])):
        print(f"| {name} | " + " | ".join(f"{g['error']:.4f} / {g['change']:.4f}" for g in groups.values()) + " |")
    print(f"\nReturn of the FF evaluation episode's first {args.steps} steps: {results['episode']['return']:.2f}")
    return results


if __name__ == "__main__":
    main()
