"""Can the agent's MLP inverse dynamics learn the Sawyer at all? Trained offline, from real transitions.

Usage:
    python scripts/sawyer_inverse_offline.py [--train 30000] [--test 3000] [--steps 20000] [--batch 256] [--seed 0]

The inverse-dynamics ablation's online MLP ends further from the true torques than zero torque is
(``scripts/sawyer_learned_inverse.py``). This script separates the network from the data it learned on: a fresh
``MLPInverseDynamics``, as the agent builds it (32 units, Adam 1e-3, batches of ``--batch``), is trained for
``--steps`` steps on ``--train`` real transitions of ``ebm/SawyerReach-v0`` and scored on ``--test`` others (another
seed, the env's exploration actions and uniform torques, half each). Two training sets:

- ``mixed``: the same kind of transitions as the test set;
- ``bang-bang``: uniform torques pushed to the limits (each joint's torque -1 or +1), the kind of data an agent
  whose inverse model saturates its torques collects (Table 2's directed dataset has 96-99 % of its torques at
  the limits, ``scripts/sawyer_ff_fit.py``).

and two input scalings: raw (s, s'), as the agent and the original feed it, and each dim standardized by the
training set's mean and std. The table gives the held-out mean |action error| every quarter of the steps, next to
zero torque's and the env's ground-truth inverse dynamics'.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
import torch

import envs  # noqa: F401  (registers ebm/SawyerReach-v0)
from ebm_agent.inverse_dynamics import MLPInverseDynamics
from envs.sawyer import SawyerReachEnv
from eval.plan_trace import sawyer_real_transitions

Transitions = tuple[np.ndarray, np.ndarray, np.ndarray]


def bang_bang_transitions(count: int, seed: int) -> Transitions:
    """``count`` real transitions under torques at the limits (a random sign per joint and step).

    :param count: how many transitions (episodes of 250 steps, as ``sawyer_real_transitions``).
    :param seed: seed of the resets and the signs.
    :return: states [B, 20], next states [B, 20], actions [B, 7] in {-1, 1}.
    """
    env = SawyerReachEnv(goal="variable")
    rng = np.random.default_rng(seed)
    states, next_states, taken = [], [], []
    obs: dict[str, Any] = {}
    for step in range(count):
        if step % 250 == 0:
            obs, _ = env.reset(seed=seed + step)
        action = rng.choice(np.array([-1.0, 1.0], dtype=np.float32), size=7)
        states.append(obs["observation"])
        obs, *_ = env.step(action)
        next_states.append(obs["observation"])
        taken.append(action)
    return np.array(states), np.array(next_states), np.array(taken)


def train_and_score(
    train: Transitions, test: Transitions, *, standardize: bool, steps: int, batch: int, seed: int
) -> list[tuple[int, float]]:
    """Train a fresh MLP inverse model on ``train`` and score it on ``test`` four times along the way.

    :param train: states [N, 20], next states [N, 20], actions [N, 7].
    :param test: the same, held out.
    :param standardize: feed each dim standardized by the training states' mean and std instead of raw.
    :param steps: Adam steps.
    :param batch: transitions per step (drawn with replacement).
    :param seed: seed of the network and the batches.
    :return: (step, held-out mean |action error|) after each quarter of the steps.
    """
    states, next_states, actions = train
    mean, std = states.mean(axis=0), states.std(axis=0) + 1e-6  # [20]

    def scaled(array: np.ndarray) -> np.ndarray:
        return ((array - mean) / std).astype(np.float32) if standardize else array

    low, high = -np.ones(7, dtype=np.float32), np.ones(7, dtype=np.float32)
    model = MLPInverseDynamics(20, 7, low, high, seed=seed)
    rng = np.random.default_rng(seed)
    inputs, next_inputs = scaled(states), scaled(next_states)
    test_inputs, test_next = scaled(test[0]), scaled(test[1])
    scores = []
    for step in range(1, steps + 1):
        index = rng.integers(0, len(states), size=batch)
        model.update(inputs[index], next_inputs[index], actions[index])
        if step % max(1, steps // 4) == 0 or step == steps:
            error = float(np.abs(model(test_inputs, test_next) - test[2]).mean())
            if not scores or scores[-1][0] != step:
                scores.append((step, error))
    return scores


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Print the table.

    :param argv: command-line arguments (None: ``sys.argv``).
    :return: ``{"zero": float, "ground_truth": float, "rows": {(training set, scaling): [(step, error), ...]}}``.
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--train", type=int, default=30_000, help="training transitions of each set")
    parser.add_argument("--test", type=int, default=3_000, help="held-out transitions (mixed actions, seed 99)")
    parser.add_argument("--steps", type=int, default=20_000, help="Adam steps")
    parser.add_argument("--batch", type=int, default=256, help="transitions per step")
    parser.add_argument("--seed", type=int, default=0, help="seed of the training transitions and the network")
    args = parser.parse_args(argv)
    if min(args.train, args.test, args.steps, args.batch) < 1:
        parser.error("--train, --test, --steps and --batch must be >= 1")
    torch.set_num_threads(1)
    test = sawyer_real_transitions(args.test, seed=99)
    sets = {
        "mixed": sawyer_real_transitions(args.train, seed=args.seed),
        "bang-bang": bang_bang_transitions(args.train, seed=args.seed),
    }
    truth = SawyerReachEnv(goal="variable").inverse_dynamics
    results: dict[str, Any] = {
        "zero": float(np.abs(test[2]).mean()),
        "ground_truth": float(np.abs(truth(test[0], test[1]) - test[2]).mean()),
        "rows": {},
    }
    for name, train in sets.items():
        for standardize in (False, True):
            scaling = "standardized" if standardize else "raw"
            results["rows"][(name, scaling)] = train_and_score(
                train, test, standardize=standardize, steps=args.steps, batch=args.batch, seed=args.seed
            )
    steps = [step for step, _ in next(iter(results["rows"].values()))]
    print(f"Held-out mean |action error| on {args.test} real transitions (mixed actions):\n")
    print("| training set | inputs | " + " | ".join(f"after {s} steps" for s in steps) + " |")
    print("|---|---|" + "---|" * len(steps))
    for (name, scaling), scores in results["rows"].items():
        print(f"| {name} | {scaling} | " + " | ".join(f"{error:.3f}" for _, error in scores) + " |")
    print(f"| zero torque | | {results['zero']:.3f} |")
    print(f"| ground-truth inverse dynamics | | {results['ground_truth']:.3f} |")
    return results


if __name__ == "__main__":
    main()
