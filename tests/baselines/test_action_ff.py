"""Action FF learning, every agent on every env through evaluate_policy, and the inverse-dynamics ablations."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3.common.evaluation import evaluate_policy

import envs  # noqa: F401
from baselines import ActionFFAgent, RandomAgent
from ebm_agent import EBMPlannerAgent, collect_random_transitions

TINY = {"horizon": 4, "planner_config": {"num_samples": 8, "iterations": 2}, "online": {"pos_buffer_size": 1000}}


@pytest.fixture(scope="module")
def particle_dataset():
    return collect_random_transitions("ebm/Particle-v0", num_transitions=6000, seed=0)


def test_action_ff_pretrained_on_random_particle_transitions_reaches_the_goal_region(particle_dataset):
    torch.manual_seed(0)
    eval_env = gym.make("ebm/Particle-v0", start=(0.0, 0.0), goal=(0.5, 0.5))
    agent = ActionFFAgent("MultiInputPolicy", eval_env, seed=0, residual=True, planner_config={"iterations": 20})
    untrained_error = _one_step_error(agent, particle_dataset)
    agent.learn_offline(particle_dataset, epochs=8, batch_size=256, log_interval=0)
    assert _one_step_error(agent, particle_dataset) < 0.3 * untrained_error

    obs, _ = eval_env.reset(seed=0)
    state, closest = None, np.inf
    for step in range(40):
        action, state = agent.predict(obs, state=state, episode_start=np.array([step == 0]), deterministic=True)
        obs, _, terminated, _, _ = eval_env.step(action)
        closest = min(closest, float(np.abs(obs["achieved_goal"] - obs["desired_goal"]).sum()))
        if terminated:
            break
    # The goal region: within 0.1 (L1) of (0.5, 0.5), from 1.0 away; standing still never gets closer than 1.0.
    assert closest < 0.1, closest


def _one_step_error(agent: ActionFFAgent, dataset) -> float:
    with torch.no_grad():
        predicted = agent.policy.dynamics(torch.as_tensor(dataset.states[:2000]), torch.as_tensor(dataset.actions[:2000]))
    return float(np.abs(predicted.numpy() - dataset.next_states[:2000]).mean())


@pytest.mark.parametrize("env_id", ["ebm/Particle-v0", "ebm/Maze-v0", "ebm/Reacher-v0", "ebm/SawyerReach-v0"])
@pytest.mark.parametrize("agent_class", [EBMPlannerAgent, ActionFFAgent, RandomAgent])
def test_evaluate_policy_for_every_agent_on_every_env(agent_class, env_id):
    kwargs = {} if agent_class is RandomAgent else TINY
    agent = agent_class("MultiInputPolicy", gym.make(env_id), seed=0, **kwargs)
    agent.learn(8)
    eval_env = gym.make(env_id, max_episode_steps=6)
    rewards, lengths = evaluate_policy(agent, eval_env, n_eval_episodes=1, return_episode_rewards=True, warn=False)
    assert len(rewards) == 1 and np.isfinite(rewards[0]) and lengths[0] <= 6


@pytest.mark.parametrize("inverse_dynamics", ["mlp", "rls"])
def test_sawyer_inverse_dynamics_ablation_is_a_parameter(inverse_dynamics):
    env = gym.make("ebm/SawyerReach-v0")
    agent = EBMPlannerAgent("MultiInputPolicy", env, seed=0, inverse_dynamics=inverse_dynamics, **TINY)
    assert type(agent.inverse_model).__name__.lower().startswith(inverse_dynamics)
    agent.learn(12)  # learned inverse dynamics train on the executed transitions
    obs, _ = env.reset(seed=1)
    action, _ = agent.predict(obs, deterministic=True)
    assert action.shape == (7,) and np.all(np.isfinite(action)) and np.all(np.abs(action) <= 1.0)
