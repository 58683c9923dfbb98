"""Baselines with the same SB3 API as the EBM agent: Action FF, a per-env tuned PPO factory, and a random agent."""

from baselines.action_ff import ActionFFAgent, ForwardDynamicsModel
from baselines.action_planner import ActionPlanner, ActionPlannerConfig
from baselines.ppo import exact_budget_callback, make_ppo, ppo_hyperparams
from baselines.random_agent import RandomAgent

__all__ = [
    "ActionFFAgent",
    "ActionPlanner",
    "ActionPlannerConfig",
    "ForwardDynamicsModel",
    "RandomAgent",
    "exact_budget_callback",
    "make_ppo",
    "ppo_hyperparams",
]
