"""Periodic state dims (Reacher's normalised joint angles): the energy's circle features and wrap-aware warm starts."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

import envs  # noqa: F401  (registers the ids)
from ebm_agent import EBMPlannerAgent

FAST = {
    "horizon": 5,
    "planner_config": {"num_samples": 16, "iterations": 4},
    "online": {"pos_buffer_size": 1_000},
    "image_log_interval": 0,
}


@pytest.fixture(scope="module")
def reacher_agent() -> EBMPlannerAgent:
    return EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Reacher-v0"), seed=0, **FAST)


def test_the_reacher_energy_sees_its_angles_on_the_circle(reacher_agent):
    energy = reacher_agent.energy_model
    assert energy.features is not None and energy.features.dims == (0, 1) and energy.features.period == 2.0
    assert energy.net[0].in_features == 2 * (4 + 2)
    raw = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Reacher-v0"), seed=0, energy={"periodic_inputs": False}, **FAST)
    assert raw.energy_model.features is None and raw.energy_model.net[0].in_features == 8
    particle = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Particle-v0"), seed=0, **FAST)
    assert particle.energy_model.features is None  # no periodic dims: the paper's input


def test_warm_starts_move_by_whole_periods_to_follow_a_wrapped_state(reacher_agent):
    plans = np.zeros((2, 3, 4), dtype=np.float32)  # [n, T+1, D]
    plans[0, :, 0] = [0.98, 1.01, 1.04]  # ran past the wrap...
    plans[1, :, 1] = [-0.5, -0.4, -0.3]
    plans[:, :, 2] = 0.7  # a velocity: never moved
    states = np.array([[-0.97, 0.0, 0.7, 0.0], [-0.5, -0.5, 0.7, 0.0]], dtype=np.float32)  # ...the env wrapped it
    reacher_agent._align_periodic(plans, states)
    np.testing.assert_allclose(plans[0, :, 0], [-1.02, -0.99, -0.96], atol=1e-6)
    np.testing.assert_allclose(plans[1, :, 1], [-0.5, -0.4, -0.3], atol=1e-6)  # already next to its state
    np.testing.assert_allclose(plans[:, :, 2], 0.7)


def test_a_reacher_agent_learns_saves_and_loads_with_circle_features(reacher_agent, tmp_path):
    reacher_agent.learn(total_timesteps=60)
    obs, _ = reacher_agent.get_env().envs[0].reset(seed=3)  # type: ignore[union-attr]
    action, _ = reacher_agent.predict(obs, deterministic=True)
    reacher_agent.save(tmp_path / "reacher.zip")
    loaded = EBMPlannerAgent.load(tmp_path / "reacher.zip", env=gym.make("ebm/Reacher-v0"))
    again, _ = loaded.predict(obs, deterministic=True)
    np.testing.assert_array_equal(action, again)


def test_action_ff_sees_the_same_circle_features_and_a_wrapped_error():
    from baselines.action_ff import ActionFFAgent

    agent = ActionFFAgent(
        "MultiInputPolicy", gym.make("ebm/Reacher-v0"), seed=0, horizon=5, planner_config={"num_samples": 16, "iterations": 4}
    )
    model = agent.dynamics_model
    assert model.features is not None and model.net[0].in_features == (4 + 2) + 2
    predicted = torch.tensor([[0.99, 0.2, 0.1, 0.0]])
    real = torch.tensor([[-0.99, 0.2, 0.1, 0.0]])
    torch.testing.assert_close(model.error(predicted, real), torch.tensor([[-0.02, 0.0, 0.0, 0.0]]), atol=1e-6, rtol=0)
    agent.learn(total_timesteps=60)
    with torch.inference_mode():
        states = torch.rand(7, 4, device=agent.device) * 2 - 1  # [7, 4]
        actions = torch.rand(7, 2, device=agent.device) * 2 - 1  # [7, 2]
        fast = model.inference_evaluator()
        assert fast is not None
        torch.testing.assert_close(fast(states, actions), model(states, actions), atol=1e-5, rtol=1e-5)


def test_wrap_array_is_the_numpy_twin_of_wrap_difference_and_wraps_only_periodic_dims():
    from ebm_agent.costs import wrap_array, wrap_difference

    rng = np.random.default_rng(0)
    difference = rng.uniform(-5, 5, size=(64, 3)).astype(np.float32)  # [N, D]
    expected = wrap_difference(torch.as_tensor(difference), 2.0).numpy()
    np.testing.assert_allclose(wrap_array(difference, 2.0), expected, atol=1e-6)
    per_dim = wrap_array(difference, np.array([2.0, 0.0, 2.0], np.float32))  # dim 1 is not periodic
    np.testing.assert_allclose(per_dim[:, [0, 2]], expected[:, [0, 2]], atol=1e-6)
    np.testing.assert_array_equal(per_dim[:, 1], difference[:, 1])
    assert np.all((per_dim[:, [0, 2]] >= -1.0) & (per_dim[:, [0, 2]] < 1.0))
    assert wrap_array(difference, None) is difference
