"""Baselines with the same SB3 API as the EBM agent: Action FF, per-env tuned PPO and SAC + HER factories, and a random
agent."""

from baselines.action_ff import ActionFFAgent, ForwardDynamicsModel
from baselines.action_planner import ActionPlanner, ActionPlannerConfig
from baselines.hyperparams import PPO_HYPERPARAMS
from baselines.ppo import VALID_HYPERPARAMS, ExactBudgetCallback, exact_budget_callback, make_ppo, ppo_hyperparams
from baselines.random_agent import RandomAgent, RandomPolicy, count_occupied_cells
from baselines.sac_her import (
    SAC_HER_HYPERPARAMS,
    OffPolicyBudgetCallback,
    make_sac_her,
    off_policy_budget_callback,
    sac_her_hyperparams,
)

__all__ = [
    "PPO_HYPERPARAMS",
    "SAC_HER_HYPERPARAMS",
    "VALID_HYPERPARAMS",
    "ActionFFAgent",
    "ActionPlanner",
    "ActionPlannerConfig",
    "ExactBudgetCallback",
    "ForwardDynamicsModel",
    "OffPolicyBudgetCallback",
    "RandomAgent",
    "RandomPolicy",
    "count_occupied_cells",
    "exact_budget_callback",
    "make_ppo",
    "make_sac_her",
    "off_policy_budget_callback",
    "ppo_hyperparams",
    "sac_her_hyperparams",
]
