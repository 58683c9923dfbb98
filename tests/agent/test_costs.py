"""Plan cost terms: goal energies, priors, the box obstacle, and PlanCost's single batched energy call."""

from __future__ import annotations

import pytest
import torch
from torch import Tensor

from ebm_agent.costs import (
    AccelerationPrior,
    BoxObstacleEnergy,
    ExtraEnergy,
    GaussianGoalEnergy,
    GoalEnergy,
    PlanCost,
    RampedGoalEnergy,
    RewardGoalEnergy,
    VelocityPrior,
    wrap_difference,
)


def straight_plans(start: Tensor, velocity: Tensor, horizon: int) -> Tensor:
    """[N, D] starts -> [N, 1, T+1, D] constant-velocity plans."""
    steps = torch.arange(horizon + 1, dtype=start.dtype)[None, :, None]
    return (start[:, None, :] + steps * velocity)[:, None]


def test_gaussian_goal_is_zero_at_goal_and_quadratic() -> None:
    energy = GaussianGoalEnergy(goal_indices=(0, 1), weight=2.0)
    goals = torch.tensor([[0.5, -0.25]])
    plans = torch.zeros(1, 3, 6, 3)  # [N, K, T+1, D]
    plans[:, 0, -1, :2] = goals
    plans[:, 1, -1, :2] = goals + torch.tensor([0.1, 0.0])
    plans[:, 2, -1, :2] = goals + torch.tensor([0.2, 0.0])
    plans[:, :, -1, 2] = 5.0  # not a goal dim
    costs = energy(plans, goals)
    assert costs.shape == (1, 3)
    assert costs[0, 0].item() == 0.0
    assert costs[0, 1].item() == pytest.approx(2.0 * 0.01, rel=1e-5)
    assert costs[0, 2].item() == pytest.approx(4.0 * costs[0, 1].item(), rel=1e-5)
    # Only the final state matters.
    plans[:, :, 2, :] = 9.0
    torch.testing.assert_close(energy(plans, goals), costs)


def test_ramped_goal_weights_late_states_more() -> None:
    energy = RampedGoalEnergy(goal_indices=(0,), weight=1.0)
    goals = torch.zeros(1, 1)
    horizon = 4
    plans = torch.zeros(1, 3, horizon + 1, 1)
    plans[0, 1, 1, 0] = 1.0  # off the goal early
    plans[0, 2, 3, 0] = 1.0  # off the goal late
    costs = energy(plans, goals)[0]
    assert costs[0].item() == 0.0
    # mean over T+1 = 5 states of ((t/T)^2 * 1)^2
    assert costs[1].item() == pytest.approx((1 / 4) ** 4 / 5, rel=1e-5)
    assert costs[2].item() == pytest.approx((3 / 4) ** 4 / 5, rel=1e-5)
    # The start (t = 0) has zero weight.
    plans[0, 0, 0, 0] = 3.0
    assert energy(plans, goals)[0, 0].item() == 0.0


def test_periodic_wrap() -> None:
    difference = wrap_difference(torch.tensor([-1.8, 1.8, 0.3, -1.0]), period=2.0)
    torch.testing.assert_close(difference, torch.tensor([0.2, -0.2, 0.3, -1.0]))
    goals = torch.tensor([[0.9]])
    plans = torch.full((1, 1, 3, 1), -0.9)
    assert GaussianGoalEnergy((0,), period=2.0)(plans, goals).item() == pytest.approx(0.04, rel=1e-4)
    assert GaussianGoalEnergy((0,))(plans, goals).item() == pytest.approx(3.24, rel=1e-5)
    # Negative-L1 reward over the two planned states (the start is excluded): cost = 2 * 0.2.
    assert RewardGoalEnergy.negative_l1((0,), period=2.0)(plans, goals).item() == pytest.approx(0.4, rel=1e-4)


def test_reward_goal_energy_sums_rewards_after_the_start() -> None:
    def reward(states: Tensor, goals: Tensor) -> Tensor:
        return -(states[..., 0] - goals[..., 0]).abs()

    energy = RewardGoalEnergy(reward, weight=3.0)
    plans = torch.tensor([0.0, 1.0, 2.0, 3.0])[None, None, :, None].repeat(2, 1, 1, 1)  # [2, 1, 4, 1]
    plans[1, 0, 0, 0] = 100.0  # the start does not count
    goals = torch.tensor([[3.0], [3.0]])
    costs = energy(plans, goals)
    torch.testing.assert_close(costs, torch.tensor([[9.0], [9.0]]))  # 3 * (2 + 1 + 0)
    with pytest.raises(ValueError, match="one reward per state"):
        RewardGoalEnergy(lambda states, goals: states.sum())(plans, goals)


def test_velocity_and_acceleration_priors() -> None:
    velocity = torch.tensor([0.1, -0.2])
    plans = straight_plans(torch.zeros(1, 2), velocity, horizon=5)
    assert VelocityPrior(weight=2.0)(plans).item() == pytest.approx(2.0 * (0.01 + 0.04) / 2, rel=1e-5)
    assert VelocityPrior(weight=1.0, dims=(1,))(plans).item() == pytest.approx(0.04, rel=1e-5)
    assert AccelerationPrior(weight=1.0)(plans).item() == pytest.approx(0.0, abs=1e-12)
    # One kink: +1 then back, second differences over 3 triples x 1 dim: [1, -2, 1] -> mean 6 / 3 = 2.
    kinked = torch.tensor([0.0, 0.0, 1.0, 1.0, 1.0])[None, None, :, None] * torch.tensor([1.0, 0.0])
    kinked[0, 0, 2, 0] = 1.0
    kinked[0, 0, 3:, 0] = 0.0
    assert AccelerationPrior(weight=1.0, dims=(0,))(kinked).item() == pytest.approx((1 + 4 + 1) / 3, rel=1e-5)
    assert AccelerationPrior()(torch.zeros(2, 3, 2, 4)).shape == (2, 3)  # T = 1: no second difference


def test_box_obstacle_energy() -> None:
    box = BoxObstacleEnergy(low=(-0.1, -0.1), high=(0.1, 0.1), weight=100.0)
    far = torch.tensor([[[-0.5, 0.5], [-0.4, 0.5], [-0.3, 0.5]]])[None]  # [1, 1, 3, 2]
    inside = torch.tensor([[[-0.5, 0.0], [-0.2, 0.0], [0.0, 0.0]]])[None]
    crossing = torch.tensor([[[-0.5, 0.0], [-0.3, 0.0], [0.3, 0.0]]])[None]  # endpoints outside, segment through
    corner = torch.tensor([[[-0.5, 0.0], [-0.3, 0.0], [-0.095, 0.0]]])[None]
    assert box(far).item() == 0.0
    assert box(inside).item() > 0.0
    assert box(crossing).item() > 0.0
    assert 0.0 < box(corner).item() < box(inside).item(), "deeper penetration must cost more"
    # A margin makes a near miss count.
    near = torch.tensor([[[-0.5, 0.12], [0.5, 0.12]]])[None]
    assert box(near).item() == 0.0
    assert BoxObstacleEnergy((-0.1, -0.1), (0.1, 0.1), margin=0.05)(near).item() > 0.0
    # Only the configured dims matter.
    box_yz = BoxObstacleEnergy(low=(-0.1, -0.1), high=(0.1, 0.1), dims=(1, 2))
    assert box_yz(torch.zeros(1, 1, 2, 3)).item() > 0.0
    assert box_yz(torch.tensor([[0.0, 0.0, 0.5], [0.0, 0.0, 0.5]])[None, None]).item() == 0.0
    with pytest.raises(ValueError, match="low < high"):
        BoxObstacleEnergy(low=(0.1, 0.0), high=(0.0, 1.0))
    with pytest.raises(ValueError, match="one value per box dim"):
        BoxObstacleEnergy(low=(0.0,), high=(1.0, 1.0))


class CountingEnergy:
    """E(s, s') = |s' - s - v|^2 that records its calls."""

    def __init__(self, velocity: Tensor) -> None:
        self.velocity = velocity
        self.shapes: list[tuple[tuple[int, ...], tuple[int, ...]]] = []

    def __call__(self, states: Tensor, next_states: Tensor) -> Tensor:
        self.shapes.append((tuple(states.shape), tuple(next_states.shape)))
        return (next_states - states - self.velocity).square().sum(-1)


def test_plan_cost_calls_the_transition_energy_once() -> None:
    energy = CountingEnergy(torch.tensor([0.1, 0.0]))
    cost = PlanCost(energy, GaussianGoalEnergy((0, 1)), [VelocityPrior(0.1), AccelerationPrior(0.01)])
    plans = torch.randn(3, 5, 7, 2)  # [N, K, T+1, D]
    goals = torch.randn(3, 2)
    total = cost(plans, goals)
    assert total.shape == (3, 5)
    assert energy.shapes == [((3, 5, 6, 2), (3, 5, 6, 2))]
    terms = cost.terms(plans, goals)
    assert list(terms) == ["transition", "goal", "velocity_prior", "acceleration_prior"]
    torch.testing.assert_close(sum(terms.values()), total)
    expected_transition = (plans[:, :, 1:] - plans[:, :, :-1] - energy.velocity).square().sum((-2, -1))
    torch.testing.assert_close(terms["transition"], expected_transition)


def test_prior_scale_linear_decay_and_with_extra() -> None:
    energy = CountingEnergy(torch.tensor([0.0]))
    goal = GaussianGoalEnergy((0,))
    cost = PlanCost(energy, goal)
    plans = torch.tensor([0.0, 1.0, 1.0, 3.0])[None, None, :, None]  # steps 1, 0, 2 -> energies 1, 0, 4
    goals = torch.tensor([[0.0]])
    assert cost.terms(plans, goals)["transition"].item() == pytest.approx(5.0)
    cost.prior_scale = 0.5
    terms = cost.terms(plans, goals)
    assert terms["goal"].item() == pytest.approx(0.5 * 9.0)
    assert terms["transition"].item() == pytest.approx(5.0), "prior_scale must not touch the dynamics"
    decayed = PlanCost(energy, transition_weights="linear_decay")
    assert decayed(plans, None).item() == pytest.approx(3 * 1 + 2 * 0 + 1 * 4)
    box = BoxObstacleEnergy((0.5,), (1.5,), dims=(0,))
    extended = cost.with_extra(box, box)
    assert list(extended.terms(plans, goals)) == ["transition", "goal", "box_obstacle_energy", "box_obstacle_energy_2"]
    assert extended.prior_scale == 0.5
    assert cost.extra_energies == (), "with_extra must not change the original cost"
    assert isinstance(goal, GoalEnergy) and isinstance(box, ExtraEnergy)


def test_plan_cost_errors() -> None:
    plans = torch.zeros(2, 3, 4, 2)
    with pytest.raises(ValueError, match="goals"):
        PlanCost(None, GaussianGoalEnergy((0,)))(plans, None)
    with pytest.raises(ValueError, match="one energy per transition"):
        PlanCost(lambda s, s2: (s2 - s).sum(-1, keepdim=True))(plans, None)
    with pytest.raises(ValueError, match="transition_weights"):
        PlanCost(None, transition_weights="exponential")
    with pytest.raises(ValueError, match="T\\+1"):
        PlanCost(None)(torch.zeros(3, 4, 2), None)
    with pytest.raises(ValueError, match="goals must be"):
        GaussianGoalEnergy((0, 1))(plans, torch.zeros(2, 3))
    assert PlanCost(None)(plans, None).shape == (2, 3)
