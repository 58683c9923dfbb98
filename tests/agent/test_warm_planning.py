"""Warm-started planning (the fast preset) and the paper preset (the original's budget and the defaults: unchanged plans)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3.common.env_util import make_vec_env

import envs  # noqa: F401  registers the ebm/ ids
from baselines.action_ff import ActionFFAgent
from baselines.action_planner import ActionPlannerConfig
from ebm_agent import EBMPlannerAgent
from ebm_agent.costs import AccelerationPrior, PlanCost, RewardGoalEnergy
from ebm_agent.energy import EnergyModel
from ebm_agent.mppi import MPPIConfig, MPPIPlanner
from ebm_agent.planner import clip_states, shift_plan
from ebm_agent.presets import FAST_ACTION_FF, FAST_EBM, PAPER_ACTION_FF, PAPER_EBM, merge_settings, preset_settings

HORIZON = 10


def random_problem(seed: int, num_envs: int = 16) -> tuple[torch.Tensor, torch.Tensor, PlanCost, torch.Tensor]:
    """A random energy network, random starts and goals in [-1, 1]^2, and a previous plan to warm-start from."""
    torch.manual_seed(seed)
    energy = EnergyModel(2).eval()
    cost = PlanCost(energy, RewardGoalEnergy.negative_l1([0, 1]), [AccelerationPrior(1.0)])
    generator = torch.Generator().manual_seed(seed)
    start = torch.rand(num_envs, 2, generator=generator) * 2 - 1  # [N, 2]
    goals = torch.rand(num_envs, 2, generator=generator) * 2 - 1  # [N, 2]
    steps = torch.randn(num_envs, HORIZON + 1, 2, generator=generator).cumsum(1) * 0.05
    previous = (start[:, None] + steps).clamp(-1, 1)  # [N, T+1, 2]
    return start, goals, cost, previous


def planner(**fields: object) -> MPPIPlanner:
    """A bounded planner with the fast preset's budgets, ``fields`` over them."""
    config = {**FAST_EBM["planner_config"], **fields}
    return MPPIPlanner(MPPIConfig(horizon=HORIZON, **config), state_dim=2, state_low=[-1, -1], state_high=[1, 1])  # type: ignore[arg-type]


def shifted_cost(plans: torch.Tensor, start: torch.Tensor, goals: torch.Tensor, cost: PlanCost) -> torch.Tensor:
    """The cost [N] of the warm start as the planner sees it: the start pinned, the rest clipped to the bounds."""
    pinned = plans.clone()
    pinned[:, 0] = start
    pinned[:, 1:] = clip_states(pinned[:, 1:], torch.tensor([-1.0, -1.0]), torch.tensor([1.0, 1.0]))
    with torch.no_grad():
        return cost(pinned[:, None], goals)[:, 0]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_warm_started_plan_is_never_worse_than_the_shifted_plan(seed: int) -> None:
    start, goals, cost, previous = random_problem(seed)
    warm = shift_plan(previous, torch.randint(0, 4, (len(start),), generator=torch.Generator().manual_seed(seed)))
    before = shifted_cost(warm, start, goals, cost)
    # Few noisy samples make MPPI's average often land on a costlier plan than the one it started from.
    noisy = {"num_samples": 4, "noise_scale": 1e-2, "warm_iterations": 3}
    result = planner(**noisy).plan(start, goals, cost, init_plan=warm, generator=torch.Generator().manual_seed(seed))
    assert result.iterations == 3
    assert torch.all(result.costs <= before), (result.costs - before).max()
    with torch.no_grad():
        torch.testing.assert_close(result.costs, cost(result.plans[:, None], goals)[:, 0])
    # The control: without keep_warm_start the same iterations end worse than the warm start for some env, so the
    # guarantee above is not vacuous.
    loose = planner(**noisy, keep_warm_start=False)
    unguarded = loose.plan(start, goals, cost, init_plan=warm, generator=torch.Generator().manual_seed(seed))
    assert bool((unguarded.costs > before + 1e-6).any())


def test_budgets_fresh_warm_and_explicit() -> None:
    start, goals, cost, previous = random_problem(0, num_envs=2)
    default = planner()  # the fast preset: 80 for a fresh plan unless the agent passes its train budget, 3 warm
    assert default.plan(start, goals, cost).iterations == 80
    assert default.plan(start, goals, cost, init_plan=previous).iterations == 3
    assert default.plan(start, goals, cost, init_plan=previous, iterations=7).iterations == 7
    assert planner(iterations=2).plan(start, goals, cost, init_plan=previous).iterations == 2  # at most `iterations`
    paper = MPPIConfig(**PAPER_EBM["planner_config"])
    assert MPPIPlanner(paper, state_dim=2).plan(start, goals, cost, init_plan=previous).iterations == 80
    assert paper == MPPIConfig()  # the paper preset is the library's defaults
    with pytest.raises(ValueError, match="warm_iterations"):
        MPPIConfig(warm_iterations=-1)
    with pytest.raises(ValueError, match="stop_tolerance"):
        MPPIConfig(stop_tolerance=-1.0)


def test_early_stop_ends_when_no_plan_improves_and_keeps_the_noise_order() -> None:
    start, goals, cost, _ = random_problem(3, num_envs=4)
    # An infinite tolerance stops at the first check; zero tolerance stops once no plan improves at all.
    stopped = planner(stop_tolerance=float("inf"), stop_check=5).plan(
        start, goals, cost, generator=torch.Generator().manual_seed(0)
    )
    assert stopped.iterations == 5
    # The first five iterations draw the same noise as an uninterrupted plan of five.
    five = planner(iterations=5).plan(start, goals, cost, generator=torch.Generator().manual_seed(0))
    torch.testing.assert_close(stopped.plans, five.plans)
    full = planner(stop_tolerance=0.0, stop_check=5, iterations=40).plan(start, goals, cost)
    assert 5 <= full.iterations <= 40


@pytest.mark.parametrize("warm", [False, True])
def test_the_paper_preset_plans_as_the_original_loop(warm: bool) -> None:
    """The paper preset's planner is the original fixed-budget MPPI: 80 iterations of ``update`` on the noise it draws."""
    start, goals, cost, previous = random_problem(4, num_envs=3)
    paper = MPPIPlanner(MPPIConfig(**PAPER_EBM["planner_config"]), state_dim=2, state_low=[-1, -1], state_high=[1, 1])
    init = previous if warm else None
    result = paper.plan(start, goals, cost, init_plan=init, generator=torch.Generator().manual_seed(5))
    noise = paper.draw_noise(3, 80, torch.Generator().manual_seed(5))  # [80, N, K, T, D]
    mean = (previous.clone() if warm else start[:, None].expand(3, HORIZON + 1, 2).clone()).float()
    mean[:, 0] = start
    mean[:, 1:] = clip_states(mean[:, 1:], paper.state_low, paper.state_high)
    with torch.inference_mode():
        for perturbation in noise:
            mean = paper.update(mean, perturbation, goals, cost)
    assert result.iterations == 80
    assert torch.equal(result.plans, mean)


def record_plans(agent: EBMPlannerAgent | ActionFFAgent) -> list[tuple[int, bool, int | None]]:
    """Wrap the agent's planner to record (envs, warm-started, explicit iterations) of every call."""
    calls: list[tuple[int, bool, int | None]] = []
    plan = agent.planner.plan

    def recorded(*args, **kwargs):  # type: ignore[no-untyped-def]
        warm = kwargs.get("init_plan") is not None or kwargs.get("init_actions") is not None
        calls.append((len(args[1] if isinstance(agent, ActionFFAgent) else args[0]), warm, kwargs.get("iterations")))
        return plan(*args, **kwargs)

    agent.planner.plan = recorded  # type: ignore[method-assign]
    return calls


def test_learn_budgets_of_the_fast_and_of_the_paper_preset() -> None:
    env = gym.make("ebm/Particle-v0")
    fast = EBMPlannerAgent("MultiInputPolicy", env, seed=0, device="cpu", image_log_interval=0, **FAST_EBM)
    calls = record_plans(fast)
    fast.learn(150)
    assert any(warm for _, warm, _ in calls) and any(not warm for _, warm, _ in calls)
    # Warm starts take the planner's warm budget (no explicit count), fresh training plans the train budget.
    assert all(iterations is None for _, warm, iterations in calls if warm)
    assert all(iterations == 20 for _, warm, iterations in calls if not warm)
    calls.clear()
    obs, _ = gym.make("ebm/Particle-v0").reset(seed=0)
    fast.predict(obs, deterministic=True)
    assert calls == [(1, False, None)]  # evaluation plans keep the full 80 iterations

    paper = EBMPlannerAgent("MultiInputPolicy", env, seed=0, device="cpu", image_log_interval=0, **PAPER_EBM)
    calls = record_plans(paper)
    paper.learn(150)
    assert calls and all(iterations is None for _, _, iterations in calls)
    assert paper.planner_config.iterations == 80 and paper.planner_config.warm_iterations is None


def test_vec_env_learn_plans_warm_and_fresh_envs_apart_only_with_a_warm_budget() -> None:
    def calls_of(settings: dict) -> list[tuple[int, bool, int | None]]:
        env = make_vec_env("ebm/Particle-v0", n_envs=4, seed=0, env_kwargs={"max_episode_steps": 7})
        agent = EBMPlannerAgent("MultiInputPolicy", env, seed=0, device="cpu", image_log_interval=0, **settings)
        calls = record_plans(agent)
        agent.learn(400)
        return calls

    fast = calls_of(FAST_EBM)
    assert all(warm == (iterations is None) for _, warm, iterations in fast)  # warm groups never carry fresh envs
    paper = calls_of(PAPER_EBM)
    # The paper preset plans every env that needs a plan in one call, as the original: never two calls per step.
    assert sum(n for n, _, _ in paper) > len(paper)


def test_action_ff_warm_starts_from_its_shifted_actions() -> None:
    env = gym.make("ebm/Particle-v0")
    agent = ActionFFAgent("MultiInputPolicy", env, seed=0, device="cpu", **FAST_ACTION_FF)
    calls = record_plans(agent)
    agent.learn(150)
    assert any(warm for _, warm, _ in calls)
    assert all(iterations == 20 for _, warm, iterations in calls if not warm)
    assert agent.planner_config == ActionPlannerConfig(horizon=10, **FAST_ACTION_FF["planner_config"])
    paper = ActionFFAgent("MultiInputPolicy", env, seed=0, device="cpu", **PAPER_ACTION_FF)
    assert paper.planner_config.warm_iterations is None and paper.planner_config.train_iterations is None


def test_presets_merge_and_reject_unknown_names() -> None:
    merged = merge_settings(PAPER_EBM, {"planner_config": {"num_samples": 8}, "horizon": 5})
    assert merged["planner_config"]["iterations"] == 80 and merged["planner_config"]["num_samples"] == 8
    assert merged["horizon"] == 5 and "num_samples" not in PAPER_EBM["planner_config"]
    assert preset_settings("", EBMPlannerAgent) == {}
    assert preset_settings("paper", "EBMPlannerAgent") == PAPER_EBM
    assert preset_settings("paper", "PPO") == {}
    assert preset_settings("fast", EBMPlannerAgent) == FAST_EBM
    with pytest.raises(ValueError, match="unknown agent preset"):
        preset_settings("faster", EBMPlannerAgent)
    assert np.isfinite(MPPIConfig(**PAPER_EBM["planner_config"]).temperature)


def test_learn_budgets_are_read_from_any_planner_config() -> None:
    from ebm_agent.config import learn_budgets
    from ebm_agent.langevin import LangevinConfig

    assert learn_budgets(MPPIConfig(**FAST_EBM["planner_config"])) == (20, 3)
    assert learn_budgets(MPPIConfig(iterations=2, **FAST_EBM["planner_config"])) == (2, 2)  # at most `iterations`
    assert learn_budgets(MPPIConfig()) == (None, None)
    assert learn_budgets(ActionPlannerConfig(**FAST_ACTION_FF["planner_config"])) == (20, 3)
    assert learn_budgets(ActionPlannerConfig(method="gradient", **FAST_ACTION_FF["planner_config"])) == (None, None)
    assert learn_budgets(LangevinConfig()) == (None, None) and learn_budgets(None) == (None, None)
