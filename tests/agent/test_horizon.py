"""The planner owns the horizon: the agents set it in their own copy of the planner config and read it back."""

from __future__ import annotations

import gymnasium as gym
import pytest

import envs  # noqa: F401  (registers the ids)
from baselines.action_ff import ActionFFAgent
from baselines.action_planner import ActionPlannerConfig
from ebm_agent import EBMPlannerAgent
from ebm_agent.mppi import MPPIConfig, MPPIPlanner

CASES = [(EBMPlannerAgent, MPPIConfig), (ActionFFAgent, ActionPlannerConfig)]


def _agent(agent_class, **kwargs):
    return agent_class("MultiInputPolicy", gym.make("ebm/Particle-v0"), seed=0, **kwargs)


@pytest.mark.parametrize(("agent_class", "config_class"), CASES)
def test_the_callers_config_is_never_changed(agent_class, config_class):
    config = config_class(num_samples=8, iterations=2)
    agent = _agent(agent_class, horizon=7, planner_config=config)
    assert config.horizon == 10  # the caller's object kept its value
    assert agent.planner_config is not config and agent.planner_config.horizon == 7 and agent.horizon == 7
    assert agent.planner.horizon == 7


@pytest.mark.parametrize(("agent_class", "config_class"), CASES)
def test_the_horizon_comes_from_the_planner_config_when_not_given(agent_class, config_class):
    agent = _agent(agent_class, planner_config={"horizon": 4, "num_samples": 8, "iterations": 2})
    assert agent.horizon == 4 and agent.planner.horizon == 4
    assert _agent(agent_class, planner_config={"num_samples": 8, "iterations": 2}).horizon == 10


@pytest.mark.parametrize(("agent_class", "config_class"), CASES)
def test_two_different_horizons_are_an_error(agent_class, config_class):
    with pytest.raises(ValueError, match="disagree"):
        _agent(agent_class, horizon=5, planner_config={"horizon": 6})
    with pytest.raises(ValueError, match="positive int"):
        _agent(agent_class, horizon=0)


def test_a_planner_instance_brings_its_own_horizon():
    planner = MPPIPlanner(MPPIConfig(horizon=6, num_samples=8, iterations=2), 2)
    agent = _agent(EBMPlannerAgent, planner=planner)
    assert agent.horizon == 6
    with pytest.raises(ValueError, match="planner instance plans 6 steps"):
        _agent(EBMPlannerAgent, planner=planner, horizon=5)
