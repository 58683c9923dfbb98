"""The annealed L2 term (``TrainingConfig.l2_final``): validation, the schedule, and its wiring into ``learn``."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

import envs  # noqa: F401
from baselines.action_ff import ActionFFAgent
from ebm_agent import EBMPlannerAgent
from ebm_agent.config import TrainingConfig

SMALL = {
    "planner_config": {"num_samples": 8, "iterations": 1},
    "energy": {"hidden_dim": 16, "num_hidden_layers": 2},
    "horizon": 4,
    "image_log_interval": 0,
    "device": "cpu",
}
"""A cheap agent: these tests check the schedule, not the planning."""


def _agent(training: dict | None = None, **kwargs) -> EBMPlannerAgent:
    """An agent with ``training`` (its ``TrainingConfig``), ``loss`` and ``l2_coeff`` among them."""
    torch.set_num_threads(1)
    training = {**(training or {}), **{key: kwargs.pop(key) for key in ("loss", "l2_coeff") if key in kwargs}}
    return EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Maze-v0"), seed=0, training=training, **SMALL, **kwargs)


@pytest.mark.parametrize(
    "bad, match",
    [
        ({"l2_final": -0.1}, "l2_final"),
        ({"l2_anneal_start": 0.8, "l2_anneal_end": 0.5}, "l2_anneal_start"),
        ({"l2_anneal_end": 1.5}, "l2_anneal_end"),
        ({"l2_anneal_start": -0.1}, "l2_anneal_start"),
    ],
)
def test_bad_anneal_settings_are_refused(bad: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        TrainingConfig(**bad)


def test_off_by_default_and_refused_by_action_ff() -> None:
    assert TrainingConfig().l2_final is None
    with pytest.raises(TypeError, match=r"online\.l2_final moved to training\.l2_final"):
        ActionFFAgent("MultiInputPolicy", gym.make("ebm/Maze-v0"), online={"l2_final": 0.1}, device="cpu")


@pytest.mark.parametrize(
    "progress, expected",
    [(0.0, 1.0), (0.25, 1.0), (0.5, 1.0), (0.65, 0.55), (0.8, 0.1), (1.0, 0.1)],
)
def test_schedule_is_linear_between_start_and_end(progress: float, expected: float) -> None:
    agent = _agent({"l2_final": 0.1, "l2_anneal_start": 0.5, "l2_anneal_end": 0.8}, l2_coeff=1.0)
    assert agent.scheduled_l2_coeff() == 1.0  # outside learn: l2_coeff
    agent._total_timesteps, agent.num_timesteps = 1000, int(progress * 1000)
    assert agent.scheduled_l2_coeff() == pytest.approx(expected)


def test_switch_and_no_anneal() -> None:
    switch = _agent({"l2_final": 0.2, "l2_anneal_start": 0.3, "l2_anneal_end": 0.3}, l2_coeff=1.0)
    switch._total_timesteps = 100
    switch.num_timesteps = 29
    assert switch.scheduled_l2_coeff() == 1.0
    switch.num_timesteps = 30
    assert switch.scheduled_l2_coeff() == pytest.approx(0.2)
    plain = _agent(l2_coeff=0.7)
    plain._total_timesteps, plain.num_timesteps = 100, 90
    assert plain.scheduled_l2_coeff() == 0.7


def _record_l2(agent: EBMPlannerAgent, seen: list[tuple[int, float]]) -> None:
    """Make every gradient step of ``agent`` append (timestep, its L2 weight) to ``seen``."""
    step = agent._gradient_step

    def spy(*args, l2_coeff=None, **kwargs):
        seen.append((agent.num_timesteps, agent.training.l2_coeff if l2_coeff is None else l2_coeff))
        return step(*args, l2_coeff=l2_coeff, **kwargs)

    agent._gradient_step = spy  # type: ignore[method-assign]


def test_learn_trains_with_the_annealed_weight_and_a_continued_learn_keeps_its_place() -> None:
    agent = _agent({"l2_final": 0.0, "l2_anneal_start": 0.0, "l2_anneal_end": 1.0}, l2_coeff=1.0)
    seen: list[tuple[int, float]] = []
    _record_l2(agent, seen)
    agent.learn(total_timesteps=120)
    assert len(seen) >= 10
    steps, weights = (np.array(column) for column in zip(*seen))
    np.testing.assert_allclose(weights, 1.0 - steps / 120, atol=1e-6)
    assert weights[0] > 0.9 and weights[-1] < 0.1
    seen.clear()
    agent.learn(total_timesteps=120, reset_num_timesteps=False)  # one budget of 240: the weight goes on from 0.5
    steps, weights = (np.array(column) for column in zip(*seen))
    np.testing.assert_allclose(weights, 1.0 - steps / 240, atol=1e-6)
    assert 0.4 < weights[0] < 0.55


def test_the_annealed_weight_changes_the_update() -> None:
    def trained(online: dict | None) -> list[torch.Tensor]:
        agent = _agent(online, l2_coeff=1.0)
        agent.learn(total_timesteps=60)
        return [p.detach().clone() for p in agent.energy_model.parameters()]

    plain = trained(None)
    annealed = trained({"l2_final": 0.0, "l2_anneal_start": 0.0, "l2_anneal_end": 0.0})
    same = trained({"l2_final": 1.0})  # annealing to l2_coeff itself changes nothing
    assert all(torch.equal(a, b) for a, b in zip(plain, same))
    assert not all(torch.equal(a, b) for a, b in zip(plain, annealed))
