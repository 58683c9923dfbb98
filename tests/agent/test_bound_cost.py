"""bind_cost: a PlanCost bound to a buffer gives cost(plans, goals) of the buffer's current contents, bit for bit."""

from __future__ import annotations

import pytest
import torch
from torch import Tensor

from ebm_agent.bound_cost import bind_cost
from ebm_agent.costs import (
    AccelerationPrior,
    BoxObstacleEnergy,
    GaussianGoalEnergy,
    PlanCost,
    RampedGoalEnergy,
    RewardGoalEnergy,
    VelocityPrior,
)
from ebm_agent.energy import EnergyModel


def reward_l1_with_a_user_function(indices: tuple[int, ...]) -> RewardGoalEnergy:
    """The negative-L1 reward written by a user: bind_cost cannot know it, so it must call it as it is."""
    return RewardGoalEnergy(lambda states, goals: -(states[..., list(indices)] - goals).abs().sum(-1))


COSTS = {
    "agent default (L1 reward, acceleration prior)": lambda energy: PlanCost(
        energy, RewardGoalEnergy.negative_l1((0, 1)), [AccelerationPrior(1.0)]
    ),
    "weighted periodic L1, both priors on some dims": lambda energy: PlanCost(
        energy,
        RewardGoalEnergy.negative_l1((1, 2), weight=3.0, period=2.0),
        [VelocityPrior(0.1, dims=(0, 2)), AccelerationPrior(0.01, dims=(1,))],
    ),
    "linear decay, Gaussian goal, box": lambda energy: PlanCost(
        energy,
        GaussianGoalEnergy((0, 1), weight=10.0),
        [BoxObstacleEnergy((0.1, 0.1), (0.2, 0.2))],
        transition_weights="linear_decay",
    ),
    "ramped goal, no transition energy": lambda energy: PlanCost(None, RampedGoalEnergy((0, 1)), [VelocityPrior()]),
    "user reward, no goal-free terms": lambda energy: PlanCost(energy, reward_l1_with_a_user_function((0, 1))),
    "no goal": lambda energy: PlanCost(energy, None, [VelocityPrior(0.5)]),
}


@pytest.mark.parametrize("name", list(COSTS))
@pytest.mark.parametrize("evaluator", [True, False])
@pytest.mark.parametrize("prior_scale", [1.0, 0.25])
def test_bound_cost_equals_the_cost_of_the_current_contents(name: str, evaluator: bool, prior_scale: float) -> None:
    torch.manual_seed(0)
    energy = EnergyModel(3, masked_dims=(2,))
    cost = COSTS[name](energy)
    cost.prior_scale = prior_scale
    with torch.inference_mode():
        if evaluator and cost.transition_energy is not None:
            inference = energy.inference_evaluator()
            assert inference is not None
            cost.transition_energy = inference
        buffer = torch.zeros(2, 200, 9, 3)  # [N, K, T+1, D]; K * T large enough for the fused layers
        goals = torch.tensor([[0.3, -0.2], [0.9, 0.1]]) if cost.goal_energy is not None else None
        bound = bind_cost(cost, buffer, goals)
        for step in range(3):  # the first call checks via cost(...) itself; the later ones take the bound path
            buffer.copy_(torch.rand(buffer.shape, generator=torch.Generator().manual_seed(step)) * 2 - 1)
            expected = cost(buffer.clone(), goals)
            assert torch.equal(bound(), expected), f"call {step}"


def test_bound_cost_raises_the_costs_errors() -> None:
    cost = PlanCost(EnergyModel(2), RewardGoalEnergy.negative_l1((0, 1)))
    with pytest.raises(ValueError, match="goals"):
        bind_cost(cost, torch.zeros(1, 4, 5, 2), None)
    with pytest.raises(ValueError, match=r"\[N, K, T\+1, D\]"):
        bind_cost(cost, torch.zeros(4, 5, 2), torch.zeros(1, 2))
    with pytest.raises(ValueError, match="goals must be"):
        bind_cost(cost, torch.zeros(1, 4, 5, 2), torch.zeros(1, 3))


def test_a_plain_function_is_called_as_it_is() -> None:
    calls: list[Tensor] = []

    def cost(plans: Tensor, goals: Tensor | None) -> Tensor:
        calls.append(plans)
        return plans.sum(dim=(-2, -1))

    buffer = torch.ones(1, 3, 4, 2)
    bound = bind_cost(cost, buffer, None)
    buffer.mul_(2.0)
    assert torch.equal(bound(), torch.full((1, 3), 16.0))
    assert calls[0] is buffer
