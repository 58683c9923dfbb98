"""Throughput of every registered environment: ``python -m benchmarks.envs`` (``make bench-envs``).

Prints a markdown table with, per env id of ``envs.ENV_IDS``: env steps per second through ``gym.make`` (the
wrappers a user gets, random actions, resetting when an episode ends), physics steps per second where the env is
MuJoCo, and ground-truth inverse-dynamics transitions per second on a batch of recorded transitions.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

import envs


@dataclass
class BenchResult:
    """Measured throughput of one environment.

    :param env_id: the Gymnasium id.
    :param env_steps_per_s: ``env.step`` calls per second.
    :param physics_steps_per_s: simulator steps per second (``None`` for the analytic envs).
    :param inverse_per_s: transitions per second through ``inverse_dynamics`` on one batch.
    """

    env_id: str
    env_steps_per_s: float
    physics_steps_per_s: float | None
    inverse_per_s: float


def bench_env(env_id: str, steps: int = 5000, inverse_batch: int = 256, seed: int = 0) -> BenchResult:
    """Time ``steps`` random steps of one env and one batched inverse-dynamics call.

    :param env_id: a registered Gymnasium id.
    :param steps: env steps to time.
    :param inverse_batch: transitions in the inverse-dynamics batch.
    :param seed: seeds the env and its action space.
    :return: the measured throughput.
    """
    if steps < 1 or inverse_batch < 1:
        raise ValueError(f"steps and inverse_batch must be >= 1, got {steps} and {inverse_batch}.")
    env = gym.make(env_id)
    env.action_space.seed(seed)
    obs, _ = env.reset(seed=seed)
    actions = [env.action_space.sample() for _ in range(steps)]
    unwrapped: Any = env.unwrapped
    physics_before = getattr(unwrapped, "physics_steps", None)
    states: list[np.ndarray] = []
    next_states: list[np.ndarray] = []
    start = time.perf_counter()
    for action in actions:
        next_obs, _, terminated, truncated, _ = env.step(action)
        if len(states) < inverse_batch:
            states.append(obs["observation"])
            next_states.append(next_obs["observation"])
        obs = env.reset()[0] if terminated or truncated else next_obs
    elapsed = time.perf_counter() - start
    physics_rate = None
    if physics_before is not None:
        physics_rate = (unwrapped.physics_steps - physics_before) / elapsed

    start = time.perf_counter()
    unwrapped.inverse_dynamics(np.array(states), np.array(next_states))
    inverse_elapsed = time.perf_counter() - start
    env.close()
    return BenchResult(env_id, steps / elapsed, physics_rate, len(states) / inverse_elapsed)


def format_table(results: list[BenchResult]) -> str:
    """Render results as a markdown table.

    :param results: one entry per env.
    :return: the table text.
    """
    lines = [
        "| env | env steps/s | physics steps/s | inverse dynamics transitions/s |",
        "|---|---:|---:|---:|",
    ]
    for result in results:
        physics = "-" if result.physics_steps_per_s is None else f"{result.physics_steps_per_s:,.0f}"
        lines.append(f"| {result.env_id} | {result.env_steps_per_s:,.0f} | {physics} | {result.inverse_per_s:,.0f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """Command-line entry: benchmark every env of ``envs.ENV_IDS`` (or those named) and print the table.

    :param argv: arguments (default: ``sys.argv``).
    """
    parser = argparse.ArgumentParser(prog="python -m benchmarks.envs", description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="short names or ids (default: all of envs.ENV_IDS)")
    parser.add_argument("--steps", type=int, default=5000, help="env steps timed per env")
    parser.add_argument("--inverse-batch", type=int, default=256, help="transitions in the inverse-dynamics batch")
    args = parser.parse_args(argv)
    env_ids = [envs.resolve_env_id(name) for name in args.names] or list(envs.ENV_IDS.values())
    print(format_table([bench_env(env_id, args.steps, args.inverse_batch) for env_id in env_ids]))


if __name__ == "__main__":
    main()
