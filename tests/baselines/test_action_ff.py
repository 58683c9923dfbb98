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
        states, actions = (torch.as_tensor(a[:2000], device=agent.device) for a in (dataset.states, dataset.actions))
        predicted = agent.policy.dynamics(states, actions)  # [2000, D]
    return float(np.abs(predicted.cpu().numpy() - dataset.next_states[:2000]).mean())


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


def test_standardized_outputs_keep_exact_running_statistics_of_the_targets():
    from baselines.action_ff import ForwardDynamicsModel

    model = ForwardDynamicsModel(3, 2, masked_dims=[2], standardize_outputs=True)
    scale, shift = model.output_scale()
    assert torch.equal(scale, torch.ones(3)) and torch.equal(shift, torch.zeros(3))  # nothing observed yet
    generator = torch.Generator().manual_seed(0)
    states = torch.randn(50, 3, generator=generator)
    changes = torch.randn(50, 3, generator=generator) * torch.tensor([1.0, 0.01, 0.0])
    for rows in torch.split(torch.arange(50), [7, 1, 30, 12]):
        model.observe_transitions(states[rows], states[rows] + changes[rows])
    assert model.target_count.item() == 50
    scale, shift = model.output_scale()
    assert torch.allclose(shift, changes.mean(dim=0), atol=1e-6)
    assert torch.allclose(scale[:2], changes[:, :2].std(dim=0, unbiased=False), rtol=1e-4)
    assert scale[2] == pytest.approx(1e-6)  # a dim that never changed gets the floor
    zeros_s, zeros_a = torch.zeros(4, 3), torch.zeros(4, 2)
    fast = model.inference_evaluator()
    assert fast is not None
    with torch.no_grad():
        assert torch.allclose(fast(zeros_s, zeros_a), model(zeros_s, zeros_a), atol=1e-6)
        raw = model.net(torch.cat([zeros_s, zeros_a], dim=-1))  # [4, 3] the network's standardized changes
        assert torch.allclose(model(zeros_s, zeros_a)[:, :2], (raw * scale + shift)[:, :2], atol=1e-6)
    absolute = ForwardDynamicsModel(3, 2, residual=False, standardize_outputs=True)
    absolute.observe_transitions(states, states + changes)  # without residual the target is the next state
    assert torch.allclose(absolute.output_scale()[1], (states + changes).mean(dim=0), atol=1e-6)
    with pytest.raises(RuntimeError, match="standardize_outputs=True"):
        ForwardDynamicsModel(3, 2).observe_transitions(states, states)


def test_standardized_outputs_fit_a_dim_whose_changes_are_small_where_plain_mse_neglects_it(particle_dataset, tmp_path):
    from ebm_agent import TransitionDataset

    # The particle with its y moves shrunk 100 times: under plain MSE y's errors hardly count; standardized, they do.
    change = particle_dataset.next_states - particle_dataset.states
    change[:, 1] *= 0.01
    shrunk = TransitionDataset(
        particle_dataset.states, particle_dataset.states + change, particle_dataset.actions, particle_dataset.episode_ids
    )
    relative = {}
    for standardize in (False, True):
        agent = ActionFFAgent("MultiInputPolicy", "ebm/Particle-v0", seed=0, standardize_outputs=standardize, **TINY)
        agent.learn_offline(shrunk, epochs=3, batch_size=256, log_interval=0)
        errors = np.abs(_predict(agent, shrunk) - shrunk.next_states[:2000])  # [2000, D]
        relative[standardize] = errors.mean(axis=0) / np.abs(change[:2000]).mean(axis=0)  # [D] error / change
    assert relative[True][1] < 0.3 < 1.0 < relative[False][1], relative  # y: fitted, against worse than no model
    assert relative[True][0] < relative[False][0], relative

    agent.save(tmp_path / "ff.zip")
    loaded = ActionFFAgent.load(tmp_path / "ff.zip")
    assert loaded.standardize_outputs is True
    assert torch.equal(loaded.dynamics_model.target_mean, agent.dynamics_model.target_mean)
    assert loaded.dynamics_model.target_count.item() == agent.dynamics_model.target_count.item() > 0


def test_a_model_saved_before_standardized_outputs_existed_loads_as_trained_without(tmp_path):
    import json
    import zipfile

    agent = ActionFFAgent("MultiInputPolicy", "ebm/Particle-v0", seed=0, standardize_outputs=False, **TINY)
    agent.save(tmp_path / "new.zip")
    with zipfile.ZipFile(tmp_path / "new.zip") as source, zipfile.ZipFile(tmp_path / "old.zip", "w") as legacy:
        for item in source.infolist():
            content = source.read(item.filename)
            if item.filename == "data":  # what a save of the earlier code held: no standardize_outputs
                data = json.loads(content)
                del data["standardize_outputs"]
                content = json.dumps(data).encode()
            legacy.writestr(item, content)
    loaded = ActionFFAgent.load(tmp_path / "old.zip")
    assert loaded.standardize_outputs is False and not loaded.dynamics_model.standardize_outputs
    assert ActionFFAgent("MultiInputPolicy", "ebm/Particle-v0", seed=0, **TINY).standardize_outputs is True


def _predict(agent: ActionFFAgent, dataset) -> np.ndarray:
    with torch.no_grad():
        states, actions = (torch.as_tensor(a[:2000], device=agent.device) for a in (dataset.states, dataset.actions))
        predicted = agent.dynamics_model(states, actions)  # [2000, D]
    return predicted.cpu().numpy()
