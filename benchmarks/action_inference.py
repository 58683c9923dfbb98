"""Action inference on an env without inverse dynamics: ``python -m benchmarks.action_inference``.

Trains one EBM agent per seed and setting on an env (default gymnasium-robotics' FetchReach-v4, unmodified), then
evaluates it on deterministic episodes whose resets are seeded 1000, 1001, ... (the same start/goal pairs for every
setting), and prints a markdown table: success rate, the mean distance from the achieved to the desired goal at the
start and at the end of the episodes, and the learn time. Settings are JSON objects of agent keyword arguments over a
preset (``fast`` by default); ``{"online": {"train_every_plan": false}}`` gives the never-trained-energy control.
PointMaze_UMaze-v3 runs with ``continuing_task=False`` (the harness's protocol, ``envs.PROTOCOL_ENV_KWARGS``).

Example (issue 46, docs/agent.md "Envs we did not write")::

    python -m benchmarks.action_inference --env FetchReach-v4 --steps 10000 --seeds 0 1 --episodes 20 \\
        --settings '{"inverse_dynamics": "rls", "planner_config": {"noise_units": "step", "noise_scale": 3e-4}}'
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from ebm_agent import EBMPlannerAgent
from ebm_agent.presets import merge_settings, preset_settings
from envs import PROTOCOL_ENV_KWARGS, resolve_env_id


def run_once(env_id: str, steps: int, seed: int, settings: dict[str, Any], preset: str, episodes: int) -> dict[str, Any]:
    """Train one agent and evaluate it.

    :param env_id: registered id (or short name).
    :param steps: transitions to learn from.
    :param seed: the agent's seed.
    :param settings: agent keyword arguments over the preset's.
    :param preset: ``""`` (the library's defaults) or a preset name.
    :param episodes: deterministic evaluation episodes (reset seeds 1000, 1001, ...).
    :return: ``success``, ``start_distance``, ``final_distance``, ``learn_s``.
    """
    env_id = resolve_env_id(env_id)
    env_kwargs: dict[str, Any] = dict(PROTOCOL_ENV_KWARGS.get(env_id, {}))
    agent = EBMPlannerAgent(
        "MultiInputPolicy",
        gym.make(env_id, **env_kwargs),
        **merge_settings(preset_settings(preset, EBMPlannerAgent), {"seed": seed, **settings}),
    )
    start = time.perf_counter()
    agent.learn(steps)
    learn_s = time.perf_counter() - start
    env = gym.make(env_id, **env_kwargs)
    successes, starts, finals = [], [], []
    for episode in range(episodes):
        obs, info = env.reset(seed=1000 + episode)
        starts.append(float(np.linalg.norm(obs["achieved_goal"] - obs["desired_goal"])))
        state, first, done = None, True, False
        while not done:
            action, state = agent.predict(obs, state=state, episode_start=np.array([first]), deterministic=True)
            first = False
            obs, _reward, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        successes.append(float(info.get("is_success", info.get("success", 0.0))))
        finals.append(float(np.linalg.norm(obs["achieved_goal"] - obs["desired_goal"])))
    return {
        "success": float(np.mean(successes)),
        "start_distance": float(np.mean(starts)),
        "final_distance": float(np.mean(finals)),
        "learn_s": learn_s,
    }


def main(argv: Sequence[str] | None = None) -> int:
    """Run the study and print its table.

    :param argv: command-line arguments (default: ``sys.argv[1:]``).
    :return: the exit status.
    """
    parser = argparse.ArgumentParser(prog="python -m benchmarks.action_inference", description=__doc__.split("\n")[0])
    parser.add_argument("--env", default="FetchReach-v4", help="registered id or short name (default FetchReach-v4)")
    parser.add_argument("--steps", type=int, default=10_000, help="transitions per run (default 10,000)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="agent seeds (default 0)")
    parser.add_argument("--episodes", type=int, default=20, help="evaluation episodes per run (default 20)")
    parser.add_argument("--preset", default="fast", help="agent preset: fast (default), paper, or '' for the defaults")
    parser.add_argument("--settings", nargs="+", default=["{}"], help="JSON agent settings, one run per setting")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    print(
        f"{args.env}, {args.steps} transitions, preset {args.preset or 'defaults'!r}, {args.episodes} episodes, "
        f"{args.threads} torch thread(s)"
    )
    print("| settings | seed | success | start distance | final distance | learn s |")
    print("|---|---|---|---|---|---|")
    for text in args.settings:
        settings = json.loads(text)
        for seed in args.seeds:
            row = run_once(args.env, args.steps, seed, settings, args.preset, args.episodes)
            print(
                f"| `{text}` | {seed} | {row['success']:.2f} | {row['start_distance']:.3f} | "
                f"{row['final_distance']:.3f} | {row['learn_s']:.1f} |",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
