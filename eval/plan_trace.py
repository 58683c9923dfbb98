"""Trace a planning agent along one deterministic episode: each step's observation, current plan and outcome.

The diagnostic scripts (``scripts/sawyer_plan_gap.py``, ``scripts/reacher_plan_gap.py``) read from these steps how
far a plan's states are from what the env then does.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
import torch

import envs  # noqa: F401  (registers the ebm/ ids)
from ebm_agent import EBMPlannerAgent
from envs.sawyer import SawyerReachEnv
from eval.jobs import EVAL_SEED_OFFSET

__all__ = ["PlanStep", "load_traced_agent", "sawyer_real_transitions", "trace_parser", "trace_plans"]


@dataclass(frozen=True)
class PlanStep:
    """One step of a traced episode.

    :param step: index of the step in the episode (0 first).
    :param obs: the observation the action was chosen from.
    :param plan: [T+1, D] the agent's current plan, its first state where the plan started.
    :param plan_index: index in ``plan`` of the state this action should reach (1: the plan was made at this step).
    :param planned_next: [D] ``plan[plan_index]``.
    :param action: [A] the action taken.
    :param next_obs: the observation after the action.
    :param reward: the step's reward.
    :param done: the episode ended at this step (terminated or truncated).
    """

    step: int
    obs: dict[str, np.ndarray]
    plan: np.ndarray
    plan_index: int
    planned_next: np.ndarray
    action: np.ndarray
    next_obs: dict[str, np.ndarray]
    reward: float
    done: bool


def trace_plans(agent: EBMPlannerAgent, env: gym.Env, steps: int, seed: int) -> Iterator[PlanStep]:
    """Run ``agent.predict`` (deterministic) on ``env`` for up to ``steps`` steps of one episode and yield each step.

    :param agent: a planning agent whose ``predict`` state is ``(plans [1, T+1, D], actions, steps taken [1])``.
    :param env: a single (not vectorised) env with dict observations.
    :param steps: the most steps to run; the episode's end stops earlier.
    :param seed: the reset seed.
    :return: an iterator over the steps.
    """
    obs, _ = env.reset(seed=seed)
    state: Any = None
    for step in range(steps):
        action, state = agent.predict(obs, state=state, episode_start=np.array([step == 0]), deterministic=True)
        plans, _, taken = state  # [1, T+1, D], the planned actions, [1] steps of the plan taken after this one
        next_obs, reward, terminated, truncated, _ = env.step(action)
        done = bool(terminated or truncated)
        index = int(taken[0])
        yield PlanStep(step, obs, plans[0], index, plans[0, index], np.asarray(action), next_obs, float(reward), done)
        if done:
            return
        obs = next_obs


def trace_parser(description: str, env_id: str, steps: int, every: int, weight_flag: str) -> argparse.ArgumentParser:
    """The command line of a plan-gap script: a saved model, ``--steps``, ``--every``, ``--seed`` and one env weight.

    :param description: the script's one-line purpose.
    :param env_id: the env the model was trained on.
    :param steps: default steps of the episode.
    :param every: default printing interval.
    :param weight_flag: the env weight's flag (``--finger-weight`` sets ``inverse_finger_weight``).
    :return: the parser.
    """

    name = "inverse_" + weight_flag.removeprefix("--").replace("-", "_")
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("model", help=f"a saved EBMPlannerAgent trained on {env_id}")
    parser.add_argument("--steps", type=int, default=steps, help="steps of the episode to run")
    parser.add_argument("--every", type=int, default=every, help="print every this many steps")
    parser.add_argument("--seed", type=int, default=EVAL_SEED_OFFSET, help="reset seed (the harness's evaluation)")
    parser.add_argument(weight_flag, type=float, dest="weight", help=f"the env's {name} (default: the env's)")
    parser.set_defaults(weight_name=name)
    return parser


def load_traced_agent(
    parser: argparse.ArgumentParser, argv: Sequence[str] | None, env_id: str
) -> tuple[argparse.Namespace, gym.Env, EBMPlannerAgent]:
    """Parse a plan-gap script's arguments, make the env (with the weight, if given) and load the model on it.

    :param parser: from ``trace_parser``.
    :param argv: the arguments (None: ``sys.argv``).
    :param env_id: the env.
    :return: the arguments, the env and the agent.
    """

    args = parser.parse_args(argv)
    if args.steps < 1 or args.every < 1:
        parser.error("--steps and --every must be >= 1")
    torch.set_num_threads(1)
    env = gym.make(env_id, **({} if args.weight is None else {args.weight_name: args.weight}))
    return args, env, EBMPlannerAgent.load(args.model, env=env)


def sawyer_real_transitions(count: int, seed: int = 0, actions: str = "mixed") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``count`` real transitions of the variable-goal Sawyer, to check an inverse or a forward model against.

    Episodes last 250 steps. With ``actions="mixed"`` they alternate between the env's exploration actions (random
    joint targets) and uniform torques in [-1, 1], so the set holds both slow, directed moves and fast, jerky ones;
    ``"exploration"`` or ``"uniform"`` keep to one kind.

    :param count: how many transitions.
    :param seed: seed of the resets and of the uniform torques.
    :param actions: ``"mixed"``, ``"exploration"`` or ``"uniform"``.
    :return: states [B, 20], next states [B, 20] and the actions [B, 7] that made them.
    :raises ValueError: for another ``actions``.
    """

    if actions not in ("mixed", "exploration", "uniform"):
        raise ValueError(f"actions must be 'mixed', 'exploration' or 'uniform', got {actions!r}.")
    env = SawyerReachEnv(goal="variable")
    rng = np.random.default_rng(seed)
    states, next_states, taken = [], [], []
    obs, _ = env.reset(seed=seed)
    for step in range(count):
        if step % 250 == 0:
            obs, _ = env.reset(seed=seed + step)
        exploring = actions == "exploration" or (actions == "mixed" and (step // 250) % 2 == 0)
        action = env.sample_exploration_action() if exploring else rng.uniform(-1.0, 1.0, 7).astype(np.float32)
        states.append(obs["observation"])
        obs, *_ = env.step(action)
        next_states.append(obs["observation"])
        taken.append(action)
    return np.array(states), np.array(next_states), np.array(taken)
