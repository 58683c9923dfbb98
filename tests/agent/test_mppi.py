"""MPPI planner: convergence on known energies, pinned start, bounds, warm start, determinism and batching."""

from __future__ import annotations

import pytest
import torch
from torch import Tensor, nn

from ebm_agent.costs import BoxObstacleEnergy, GaussianGoalEnergy, PlanCost
from ebm_agent.mppi import MPPIConfig, MPPIPlanner
from ebm_agent.planner import Planner, initial_plan, shift_plan

VELOCITY = torch.tensor([0.03, -0.02])
HORIZON = 10


def drift_energy(states: Tensor, next_states: Tensor) -> Tensor:
    """E(s, s') = |s' - s - v|^2: the most likely plan moves by v every step."""
    return (next_states - states - VELOCITY).square().sum(-1)


def straight_line(start: Tensor, horizon: int = HORIZON) -> Tensor:
    return start[:, None] + torch.arange(horizon + 1)[None, :, None] * VELOCITY  # [N, T+1, D]


def drift_problem(num_envs: int = 3) -> tuple[Tensor, Tensor, PlanCost]:
    start = torch.tensor([[0.0, 0.0], [0.2, 0.1], [-0.5, 0.3], [0.4, -0.4]])[:num_envs]
    goals = start + HORIZON * VELOCITY  # reachable exactly by the straight line, so its cost is 0
    return start, goals, PlanCost(drift_energy, GaussianGoalEnergy((0, 1), weight=1.0))


def test_converges_to_the_known_minimiser() -> None:
    start, goals, cost = drift_problem()
    planner = MPPIPlanner(MPPIConfig(horizon=HORIZON, iterations=80), state_dim=2)
    result = planner.plan(start, goals, cost, generator=torch.Generator().manual_seed(0))
    initial_cost = cost(initial_plan(start, HORIZON)[:, None], goals)[:, 0]
    assert result.plans.shape == (3, HORIZON + 1, 2)
    assert result.costs.shape == (3,) and result.iterations == 80
    assert torch.all(result.costs < 0.01 * initial_cost), (result.costs, initial_cost)
    # Doing nothing is 0.36 away from the line at the end; MPPI should get within 0.05 everywhere.
    assert (result.plans - straight_line(start)).abs().max() < 0.05
    torch.testing.assert_close(result.costs, cost(result.plans[:, None], goals)[:, 0])


def test_start_is_pinned_exactly_even_with_a_warm_start() -> None:
    start, goals, cost = drift_problem()
    start = start + 1e-3 * torch.randn(start.shape, generator=torch.Generator().manual_seed(1))
    warm = straight_line(start) + 0.1  # its first state is not the start
    planner = MPPIPlanner(MPPIConfig(horizon=HORIZON, iterations=5), state_dim=2)
    result = planner.plan(start, goals, cost, init_plan=warm)
    assert torch.equal(result.plans[:, 0], start)


def test_plans_are_clipped_to_bounds() -> None:
    start = torch.tensor([[0.8, 0.0]])
    goals = torch.tensor([[2.0, 0.0]])  # outside the box
    cost = PlanCost(None, GaussianGoalEnergy((0, 1), weight=10.0))
    config = MPPIConfig(horizon=HORIZON, iterations=60, noise_scale=1e-3)
    planner = MPPIPlanner(config, state_dim=2, state_low=[-1.0, -1.0], state_high=[1.0, 1.0])
    result = planner.plan(start, goals, cost, generator=torch.Generator().manual_seed(0))
    assert result.plans.max() <= 1.0
    assert result.plans[0, -1, 0].item() == pytest.approx(1.0, abs=0.02), "the plan should press against the bound"
    unbounded = MPPIPlanner(MPPIConfig(horizon=HORIZON, iterations=60, noise_scale=1e-3), state_dim=2)
    assert unbounded.plan(start, goals, cost, generator=torch.Generator().manual_seed(0)).plans.max() > 1.1


def test_shift_plan_per_env() -> None:
    plans = torch.arange(3 * 5, dtype=torch.float32).reshape(3, 5, 1)  # env e holds 5e .. 5e+4
    shifted = shift_plan(plans, torch.tensor([0, 2, 7]))
    assert shifted[0, :, 0].tolist() == [0, 1, 2, 3, 4]
    assert shifted[1, :, 0].tolist() == [7, 8, 9, 9, 9]
    assert shifted[2, :, 0].tolist() == [14] * 5
    assert torch.equal(shift_plan(plans, 1), shift_plan(plans, torch.tensor([1, 1, 1])))
    with pytest.raises(ValueError, match=">= 0"):
        shift_plan(plans, -1)
    with pytest.raises(ValueError, match=r"\[N\]"):
        shift_plan(plans, torch.tensor([1, 2]))
    with pytest.raises(TypeError, match="integer"):
        shift_plan(plans, torch.tensor([1.0, 2.0, 3.0]))


def test_warm_start_from_a_shifted_plan_stays_good() -> None:
    start, goals, cost = drift_problem()
    planner = MPPIPlanner(MPPIConfig(horizon=HORIZON, iterations=0), state_dim=2)
    previous = straight_line(start)
    warm = shift_plan(previous, torch.tensor([1, 2, 3]))
    result = planner.plan(warm[:, 0], goals, cost, init_plan=warm)
    assert result.iterations == 0
    assert torch.equal(result.plans, warm), "zero iterations must return the warm start unchanged"


def test_seeded_determinism() -> None:
    start, goals, cost = drift_problem()
    planner = MPPIPlanner(MPPIConfig(horizon=HORIZON, iterations=10), state_dim=2)
    first = planner.plan(start, goals, cost, generator=torch.Generator().manual_seed(7)).plans
    again = planner.plan(start, goals, cost, generator=torch.Generator().manual_seed(7)).plans
    other = planner.plan(start, goals, cost, generator=torch.Generator().manual_seed(8)).plans
    assert torch.equal(first, again)
    assert not torch.equal(first, other)


class TinyEnergy(nn.Module):
    """A small MLP transition energy, to check batching with a real network."""

    def __init__(self) -> None:
        super().__init__()
        torch.manual_seed(0)
        self.net = nn.Sequential(nn.Linear(4, 16), nn.LeakyReLU(0.2), nn.Linear(16, 1))

    def forward(self, states: Tensor, next_states: Tensor) -> Tensor:
        return self.net(torch.cat([states, next_states], dim=-1)).squeeze(-1).square()


@pytest.mark.parametrize("energy", [drift_energy, TinyEnergy()], ids=["quadratic", "mlp"])
def test_batched_planning_equals_planning_each_env_alone(energy) -> None:
    start, goals, _ = drift_problem()
    cost = PlanCost(energy, GaussianGoalEnergy((0, 1)))
    config = MPPIConfig(horizon=HORIZON, num_samples=16, iterations=6)
    planner = MPPIPlanner(config, state_dim=2)
    noise = planner.noise.sample((6, 3, 16), state_dim=2, generator=torch.Generator().manual_seed(0))  # [I, N, K, T, D]
    batched = planner.plan(start, goals, cost, noise=noise)
    for env in range(3):
        alone = planner.plan(start[env : env + 1], goals[env : env + 1], cost, noise=noise[:, env : env + 1])
        torch.testing.assert_close(alone.plans[0], batched.plans[env], rtol=0, atol=1e-6)
        torch.testing.assert_close(alone.costs[0], batched.costs[env], rtol=1e-5, atol=1e-6)
    if energy is drift_energy:  # elementwise cost: bit-identical
        alone = planner.plan(start[1:2], goals[1:2], cost, noise=noise[:, 1:2])
        assert torch.equal(alone.plans[0], batched.plans[1])


def test_include_mean_never_makes_the_plan_worse() -> None:
    start, goals, cost = drift_problem()
    planner = MPPIPlanner(MPPIConfig(horizon=HORIZON, num_samples=8, temperature=1e-9, include_mean=True), state_dim=2)
    mean = initial_plan(start, HORIZON)
    generator = torch.Generator().manual_seed(0)
    previous = cost(mean[:, None], goals)[:, 0]
    for _ in range(20):
        mean = planner.update(mean, planner.noise.sample((3, 8), 2, generator), goals, cost)
        current = cost(mean[:, None], goals)[:, 0]
        assert torch.all(current <= previous + 1e-6)
        previous = current


def test_routes_around_an_obstacle() -> None:
    start = torch.tensor([[-0.3, 0.02], [-0.3, -0.03]])
    goals = torch.tensor([[0.3, 0.0], [0.3, 0.0]])
    base = PlanCost(lambda s, s2: 10.0 * (s2 - s).square().sum(-1), GaussianGoalEnergy((0, 1), weight=10.0))
    box = BoxObstacleEnergy(low=(-0.1, -0.1), high=(0.1, 0.1))
    planner = MPPIPlanner(MPPIConfig(horizon=20, iterations=150), state_dim=2)
    straight = planner.plan(start, goals, base, generator=torch.Generator().manual_seed(0)).plans
    detour = planner.plan(start, goals, base.with_extra(box), generator=torch.Generator().manual_seed(0)).plans
    assert torch.all(box(straight[:, None]) > 10.0), "without the obstacle energy the plan goes straight through"
    assert torch.all(box(detour[:, None]) < 0.1)
    assert torch.all((detour[:, -1] - goals).norm(dim=-1) < 0.15)


def test_non_finite_costs_get_no_weight() -> None:
    start, goals, _ = drift_problem(1)

    def energy(states: Tensor, next_states: Tensor) -> Tensor:
        energies = drift_energy(states, next_states)
        return torch.where(next_states[..., 0] > 0.05, torch.full_like(energies, float("nan")), energies)

    planner = MPPIPlanner(MPPIConfig(horizon=HORIZON, iterations=20), state_dim=2)
    cost = PlanCost(energy, GaussianGoalEnergy((0, 1)))
    result = planner.plan(start, goals, cost, generator=torch.Generator().manual_seed(0))
    assert torch.isfinite(result.plans).all()
    assert result.plans[..., 0].max() <= 0.05


def test_result_is_a_normal_tensor_and_protocol() -> None:
    start, goals, cost = drift_problem()
    planner = MPPIPlanner(MPPIConfig(horizon=HORIZON, iterations=2), state_dim=2)
    assert isinstance(planner, Planner)
    plans = planner.plan(start, goals, cost).plans
    assert not plans.is_inference()
    layer = nn.Linear(2, 1)
    layer(plans).sum().backward()  # the agent trains the energy on planned transitions
    assert layer.weight.grad is not None


def test_bad_inputs_are_rejected() -> None:
    start, goals, cost = drift_problem()
    planner = MPPIPlanner(MPPIConfig(horizon=HORIZON, iterations=2), state_dim=2)
    with pytest.raises(ValueError, match=r"start must be \[N, D\]"):
        planner.plan(start[0], goals, cost)
    with pytest.raises(ValueError, match="init_plan"):
        planner.plan(start, goals, cost, init_plan=torch.zeros(3, HORIZON, 2))
    with pytest.raises(ValueError, match="iterations"):
        planner.plan(start, goals, cost, iterations=-1)
    with pytest.raises(ValueError, match="goals"):
        planner.plan(start, goals[:2], cost)
    with pytest.raises(ValueError, match="noise"):
        planner.plan(start, goals, cost, noise=torch.zeros(2, 3, 5, HORIZON, 2))
    with pytest.raises(ValueError, match="temperature"):
        MPPIConfig(temperature=0.0)
    with pytest.raises(ValueError, match="state_high"):
        MPPIPlanner(MPPIConfig(), state_dim=2, state_high=[1.0, 1.0, 1.0])


def test_noise_units_step_scales_each_dims_noise_by_its_unit() -> None:
    planner = MPPIPlanner(MPPIConfig(horizon=HORIZON, noise_units="step"), state_dim=2)
    plain = planner.draw_noise(2, 3, torch.Generator().manual_seed(0))  # no unit yet: state units
    planner.noise_unit = torch.tensor([0.5, 1e-3])
    scaled = planner.draw_noise(2, 3, torch.Generator().manual_seed(0))
    torch.testing.assert_close(scaled, plain * torch.tensor([0.5, 1e-3]))
    with pytest.raises(ValueError, match="noise_units"):
        MPPIConfig(noise_units="steps")


def test_agent_sets_the_planner_noise_unit_from_the_measured_step() -> None:
    import gymnasium as gym

    import envs  # noqa: F401
    from ebm_agent import EBMPlannerAgent

    agent = EBMPlannerAgent(
        "MultiInputPolicy",
        gym.make("ebm/Particle-v0"),
        seed=0,
        planner_config={"noise_units": "step", "noise_scale": 4e-3, "iterations": 2},
    )
    agent.learn(30)
    assert agent.planner.noise_unit is not None
    torch.testing.assert_close(agent.planner.noise_unit, torch.as_tensor(agent._measured_step(), dtype=torch.float32))
