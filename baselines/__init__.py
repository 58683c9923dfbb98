"""Baselines with the same SB3 API as the EBM agent: Action FF, a per-env tuned PPO factory, and a random agent."""

from baselines.action_ff import ActionFFAgent, ForwardDynamicsModel
from baselines.action_planner import ActionPlanner, ActionPlannerConfig
from baselines.hyperparams import PPO_HYPERPARAMS
from baselines.ppo import VALID_HYPERPARAMS, ExactBudgetCallback, exact_budget_callback, make_ppo, ppo_hyperparams
from baselines.random_agent import RandomAgent, RandomPolicy, count_occupied_cells

__all__ = [
    "PPO_HYPERPARAMS",
    "VALID_HYPERPARAMS",
    "ActionFFAgent",
    "ActionPlanner",
    "ActionPlannerConfig",
    "ExactBudgetCallback",
    "ForwardDynamicsModel",
    "RandomAgent",
    "RandomPolicy",
    "count_occupied_cells",
    "exact_budget_callback",
    "make_ppo",
    "ppo_hyperparams",
]
