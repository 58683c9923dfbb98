"""Langevin planner: reduces a quadratic cost, keeps the start pinned, clips steps, and leaves the energy's grads alone."""

from __future__ import annotations

import pytest
import torch
from torch import Tensor, nn

from ebm_agent.costs import GaussianGoalEnergy, PlanCost
from ebm_agent.langevin import LangevinConfig, LangevinPlanner
from ebm_agent.planner import Planner, initial_plan

VELOCITY = torch.tensor([0.03, -0.02])
HORIZON = 10


def drift_energy(states: Tensor, next_states: Tensor) -> Tensor:
    return (next_states - states - VELOCITY).square().sum(-1)


def drift_problem() -> tuple[Tensor, Tensor, PlanCost]:
    start = torch.tensor([[0.0, 0.0], [0.2, 0.1], [-0.5, 0.3]])
    goals = start + HORIZON * VELOCITY
    return start, goals, PlanCost(drift_energy, GaussianGoalEnergy((0, 1), weight=1.0))


def test_reduces_the_cost_and_keeps_the_start() -> None:
    start, goals, cost = drift_problem()
    planner = LangevinPlanner(LangevinConfig(horizon=HORIZON, iterations=200, step_size=0.1, noise_std=0.001), state_dim=2)
    assert isinstance(planner, Planner)
    result = planner.plan(start, goals, cost, generator=torch.Generator().manual_seed(0))
    initial_cost = cost(initial_plan(start, HORIZON)[:, None], goals)[:, 0]
    assert result.plans.shape == (3, HORIZON + 1, 2) and result.iterations == 200
    assert torch.equal(result.plans[:, 0], start)
    assert torch.all(result.costs < 0.01 * initial_cost), (result.costs, initial_cost)
    line = start[:, None] + torch.arange(HORIZON + 1)[None, :, None] * VELOCITY
    assert (result.plans - line).abs().max() < 0.03
    assert not result.plans.requires_grad and not result.costs.requires_grad


def test_grad_clip_bounds_each_step() -> None:
    start, goals, _ = drift_problem()
    cost = PlanCost(None, GaussianGoalEnergy((0, 1), weight=1000.0))  # a huge gradient
    config = LangevinConfig(horizon=HORIZON, iterations=1, step_size=1.0, noise_std=0.0, grad_clip=0.05)
    result = LangevinPlanner(config, state_dim=2).plan(start, goals, cost)
    moved = (result.plans - initial_plan(start, HORIZON)).abs()
    assert moved.max().item() == pytest.approx(0.05)
    unclipped = LangevinPlanner(LangevinConfig(horizon=HORIZON, iterations=1, noise_std=0.0, grad_clip=None), state_dim=2)
    assert (unclipped.plan(start, goals, cost).plans - initial_plan(start, HORIZON)).abs().max() > 1.0


def test_anneal_shrinks_early_steps() -> None:
    start, goals, _ = drift_problem()
    cost = PlanCost(None, GaussianGoalEnergy((0, 1), weight=1000.0))
    config = LangevinConfig(horizon=HORIZON, iterations=4, noise_std=0.0, grad_clip=0.04, anneal=True)
    result = LangevinPlanner(config, state_dim=2).plan(start, goals, cost, iterations=1)
    # One iteration out of one: k/K = 1, so the full clipped step.
    assert (result.plans[:, -1] - start).abs().max().item() == pytest.approx(0.04)
    planner = LangevinPlanner(config, state_dim=2)
    # Four iterations with steps 0.01, 0.02, 0.03, 0.04 (all clipped) move the end state by 0.1 in total.
    assert (planner.plan(start, goals, cost).plans[:, -1] - start).abs().max().item() == pytest.approx(0.1, abs=1e-6)


def test_seeded_bounds_and_inference_mode_caller() -> None:
    start, goals, cost = drift_problem()
    planner = LangevinPlanner(
        LangevinConfig(horizon=HORIZON, iterations=20, noise_std=0.05), state_dim=2, state_low=-0.45, state_high=0.45
    )
    first = planner.plan(start, goals, cost, generator=torch.Generator().manual_seed(1)).plans
    again = planner.plan(start, goals, cost, generator=torch.Generator().manual_seed(1)).plans
    other = planner.plan(start, goals, cost, generator=torch.Generator().manual_seed(2)).plans
    assert torch.equal(first, again) and not torch.equal(first, other)
    assert first[:, 1:].abs().max() <= 0.45
    with torch.inference_mode():  # the agent may call planners from inference code
        inside = planner.plan(start.clone(), goals.clone(), cost, generator=torch.Generator().manual_seed(1)).plans
    torch.testing.assert_close(inside, first)


def test_energy_parameters_do_not_accumulate_grads() -> None:
    network = nn.Sequential(nn.Linear(4, 8), nn.Tanh(), nn.Linear(8, 1))
    cost = PlanCost(lambda s, s2: network(torch.cat([s, s2], dim=-1)).squeeze(-1).square())
    planner = LangevinPlanner(LangevinConfig(horizon=4, iterations=3), state_dim=2)
    result = planner.plan(torch.zeros(2, 2), None, cost)
    assert torch.isfinite(result.plans).all()
    assert all(parameter.grad is None for parameter in network.parameters())


def test_bad_config_is_rejected() -> None:
    with pytest.raises(ValueError, match="grad_clip"):
        LangevinConfig(grad_clip=0.0)
    with pytest.raises(ValueError, match="step_size"):
        LangevinConfig(step_size=-1.0)
    with pytest.raises(TypeError, match="LangevinConfig"):
        LangevinPlanner(object(), state_dim=2)  # type: ignore[arg-type]
