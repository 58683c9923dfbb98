"""Trace a planning agent along one deterministic episode: each step's observation, current plan and outcome.

The diagnostic scripts (``scripts/sawyer_plan_gap.py``, ``scripts/reacher_plan_gap.py``) read from these steps how
far a plan's states are from what the env then does.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from ebm_agent import EBMPlannerAgent

__all__ = ["PlanStep", "trace_plans"]


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
