"""ebm-agent: model-based planning with energy-based models (Du, Lin & Mordatch, CoRL 2019) for Gymnasium and SB3.

The main entry point is :class:`EBMPlannerAgent`, an SB3 ``BaseAlgorithm``::

    import gymnasium as gym
    import envs  # registers ebm/Particle-v0, ebm/Maze-v0, ebm/Reacher-v0, ebm/SawyerReach-v0
    from ebm_agent import EBMPlannerAgent

    agent = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Particle-v0"), seed=0)
    agent.learn(total_timesteps=50_000)
"""

from ebm_agent.agent import CostConfig, EBMPlannerAgent
from ebm_agent.base import PlannerAgentBase
from ebm_agent.config import OnlineConfig, TrainingConfig
from ebm_agent.costs import BoxObstacleEnergy, GaussianGoalEnergy, PlanCost, RampedGoalEnergy, RewardGoalEnergy
from ebm_agent.datasets import TransitionDataset, collect_random_transitions
from ebm_agent.energy import EnergyConfig, EnergyModel
from ebm_agent.langevin import LangevinConfig, LangevinPlanner
from ebm_agent.mppi import MPPIConfig, MPPIPlanner

__version__ = "0.1.0"

__all__ = [
    "BoxObstacleEnergy",
    "CostConfig",
    "EBMPlannerAgent",
    "EnergyConfig",
    "EnergyModel",
    "GaussianGoalEnergy",
    "LangevinConfig",
    "LangevinPlanner",
    "MPPIConfig",
    "MPPIPlanner",
    "OnlineConfig",
    "PlanCost",
    "PlannerAgentBase",
    "RampedGoalEnergy",
    "RewardGoalEnergy",
    "TrainingConfig",
    "TransitionDataset",
    "__version__",
    "collect_random_transitions",
]
