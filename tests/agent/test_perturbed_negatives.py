"""Near-miss negatives of real next states (``perturbed_negatives``, ``loss="infonce_perturb"``): the Reacher energy
must tell a real s' from the same s' with its angles moved off their velocities, which planned negatives rarely show."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

import envs  # noqa: F401
from ebm_agent import EBMPlannerAgent, collect_random_transitions


def make_agent(**kwargs: object) -> EBMPlannerAgent:
    """A Reacher agent; ``loss``, ``perturbed_negatives`` and ``perturb_scales`` go to its ``training``."""
    training = {key: kwargs.pop(key) for key in ("loss", "perturbed_negatives", "perturb_scales") if key in kwargs}
    return EBMPlannerAgent(
        "MultiInputPolicy", gym.make("ebm/Reacher-v0"), seed=0, image_log_interval=0, device="cpu", training=training, **kwargs
    )


def test_perturbed_next_states_follow_the_real_moves_scale() -> None:
    agent = make_agent(perturbed_negatives=50, perturb_scales=(1.0,))
    rng = np.random.default_rng(0)
    states = rng.uniform(-1, 1, (400, 4)).astype(np.float32)
    moves = rng.normal(0.0, [0.01, 0.02, 0.3, 0.5], (400, 4)).astype(np.float32)
    next_states = states + moves
    agent._record_real_moves(states, next_states)
    perturbed = agent._perturbed_next_states(states, next_states)
    assert perturbed.shape == (400, 50, 4)
    noise_std = (perturbed - next_states[:, None, :]).reshape(-1, 4).std(axis=0)
    np.testing.assert_allclose(noise_std, [0.01, 0.02, 0.3, 0.5], rtol=0.1)
    # An angle move across the wrap (0.99 -> -0.99) counts as a move of 0.02, not 1.98.
    agent = make_agent(perturbed_negatives=4, perturb_scales=(1.0,))
    wrap_states = np.tile(np.array([[0.99, 0.0, 0.0, 0.0], [-0.99, 0.0, 0.0, 0.0]], np.float32), (50, 1))
    wrap_next = np.tile(np.array([[-0.99, 0.0, 0.0, 0.0], [0.99, 0.0, 0.0, 0.0]], np.float32), (50, 1))
    agent._record_real_moves(wrap_states, wrap_next)
    assert agent.real_moves.count == 100
    assert agent.real_moves.std[0] == pytest.approx(0.02, abs=1e-5)
    assert agent.real_moves.largest[0] == pytest.approx(0.02, abs=1e-5)  # the reach box and hard-negative clip too


def test_options_are_validated_and_off_by_default() -> None:
    assert make_agent().training.perturbed_negatives == 0
    with pytest.raises(ValueError, match="perturbed_negatives"):
        make_agent(perturbed_negatives=-1)
    with pytest.raises(ValueError, match="perturb_scales"):
        make_agent(perturbed_negatives=2, perturb_scales=(0.0,))
    with pytest.raises(ValueError, match="infonce_perturb"):
        make_agent(loss="infonce_perturb")


@pytest.mark.parametrize("loss", ["cd", "infonce_perturb"])
def test_near_miss_losses_train_offline_and_online(loss: str) -> None:
    agent = make_agent(loss=loss, perturbed_negatives=4)
    data = collect_random_transitions(gym.make("ebm/Reacher-v0"), 200, seed=0)
    agent.learn_offline(data, epochs=1, log_interval=0)
    stats = agent._gradient_step(data.states[:16], data.next_states[:16], data.states[:8], data.next_states[:8])
    assert np.isfinite(stats["loss"]) and ("energy_perturbed" in stats if loss == "cd" else "loss_anchor" in stats)
    agent.learn(total_timesteps=20)
    assert all(torch.isfinite(p).all() for p in agent.energy_model.parameters())


def test_infonce_perturb_with_move_input_learns_that_angles_move_by_their_velocities() -> None:
    """After a short offline fit on random Reacher transitions, the real s' has a lower energy than the same s' with
    its angles moved by 0.03 (2.5 full-torque steps). Measured (5,000 transitions, 8 epochs, 1,000 held out): 1.00 with
    the standardised move input, 0.60 without it, 0.78 for the paper's CD with box negatives."""
    data = collect_random_transitions(gym.make("ebm/Reacher-v0"), 2000, seed=0)
    agent = make_agent(loss="infonce_perturb", perturbed_negatives=16, energy={"move_input": True})
    agent.learn_offline(data, epochs=8, batch_size=128, log_interval=0)
    held = collect_random_transitions(gym.make("ebm/Reacher-v0"), 500, seed=1)
    rng = np.random.default_rng(0)
    moved = held.next_states.copy()
    moved[:, :2] += 0.03 * rng.choice([-1.0, 1.0], size=(len(moved), 2))
    from ebm_agent.probe import transition_energies

    real = transition_energies(agent, held.states, held.next_states)
    off = transition_energies(agent, held.states, moved.astype(np.float32))
    assert np.mean(off > real) > 0.9


def test_move_input_is_the_standardised_wrapped_move_and_is_saved() -> None:
    from ebm_agent.energy import EnergyConfig, EnergyModel

    torch.manual_seed(0)
    model = EnergyModel(4, EnergyConfig(move_input=True), periodic_dims=[0, 1], period=2.0)
    model.set_move_statistics(np.array([0.0, 0.0, 0.1, 0.0]), np.array([0.01, 0.02, 0.5, 0.5]))
    states = torch.tensor([[0.99, 0.0, 0.0, 0.0]])
    next_states = torch.tensor([[-0.99, 0.01, 0.6, -0.5]])
    move = model.standardised_move(states, next_states)
    torch.testing.assert_close(move, torch.tensor([[2.0, 0.5, 1.0, -1.0]]), atol=1e-4, rtol=0)
    assert model.inference_evaluator() is None  # the planner falls back to the module
    copy = EnergyModel(4, EnergyConfig(move_input=True), periodic_dims=[0, 1], period=2.0)
    copy.load_state_dict(model.state_dict())
    torch.testing.assert_close(copy(states, next_states), model(states, next_states))
    assert "move_std" not in EnergyModel(4).state_dict()  # off by default: the paper's network


def test_langevin_plans_through_the_acceleration_prior() -> None:
    """The priors' in-place squaring broke autograd, so the Langevin planner raised with the default cost (which has
    the acceleration prior)."""
    from ebm_agent.costs import AccelerationPrior, PlanCost
    from ebm_agent.langevin import LangevinConfig, LangevinPlanner

    cost = PlanCost(None, None, [AccelerationPrior(1.0)])
    planner = LangevinPlanner(LangevinConfig(horizon=4, iterations=3), 2)
    start = torch.zeros(1, 2)
    init = torch.randn(1, 5, 2, generator=torch.Generator().manual_seed(0))
    result = planner.plan(start, None, cost, init_plan=init, generator=torch.Generator().manual_seed(0))
    assert torch.isfinite(result.plans).all()


def test_random_action_prob_replaces_some_actions_within_bounds() -> None:
    from ebm_agent.config import OnlineConfig

    with pytest.raises(ValueError, match="random_action_prob"):
        OnlineConfig(random_action_prob=1.5)
    agent = make_agent(online={"random_action_prob": 0.5})
    planned = np.full((1000, 2), 0.25, dtype=np.float32)
    taken = agent._explore(planned)
    replaced = np.any(taken != planned, axis=1)
    assert 0.4 < replaced.mean() < 0.6 and np.all(np.abs(taken) <= 1.0)
    agent.learn(total_timesteps=20)
