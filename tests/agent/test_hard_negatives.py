"""Hard negatives from failed plan steps (issue #34, ``TrainingConfig.hard_negatives``, off by default): labelling,
the ranking term, the option's wiring into the online loss and its checkpoint."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

import envs  # noqa: F401
from baselines.action_ff import ActionFFAgent
from ebm_agent import EBMPlannerAgent
from ebm_agent.base import Segment
from ebm_agent.config import TrainingConfig
from ebm_agent.losses import ContrastBatch, contrastive_divergence_loss, hard_negative_margin_loss

SMALL = {
    "planner_config": {"num_samples": 16, "iterations": 2},
    "energy": {"hidden_dim": 16, "num_hidden_layers": 2},
    "image_log_interval": 0,
    "device": "cpu",
}
"""A cheap agent: these tests check the wiring, not the planning."""


def _agent(training: dict | None = None, **kwargs) -> EBMPlannerAgent:
    """An agent with ``training`` (its ``TrainingConfig``), ``loss`` and ``l2_coeff`` among them."""
    torch.set_num_threads(1)
    training = {**(training or {}), **{key: kwargs.pop(key) for key in ("loss", "l2_coeff") if key in kwargs}}
    return EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Maze-v0"), seed=0, training=training, **SMALL, **kwargs)


def _segment(states: np.ndarray, planned_next: np.ndarray, real_next: np.ndarray) -> Segment:
    """One segment whose step i went from states[i] toward planned_next[i] and landed at real_next[i] ([k, 2] each)."""
    planned = np.concatenate([states[:1], planned_next]).astype(np.float32)  # [k + 1, 2]
    return Segment(planned, states.astype(np.float32), real_next.astype(np.float32), np.zeros((len(states), 2), np.float32))


@pytest.mark.parametrize(
    "bad, match",
    [
        ({"hard_negative_threshold": 0.0}, "hard_negative_threshold"),
        ({"hard_negative_weight": -1.0}, "hard_negative_weight"),
        ({"hard_negative_margin": -0.5}, "hard_negative_margin"),
        ({"hard_negative_batch": -1}, "hard_negative_batch"),
        ({"hard_negative_buffer_size": 0}, "hard_negative_buffer_size"),
        ({"hard_negative_loss": "hinge"}, "hard_negative_loss"),
    ],
)
def test_bad_hard_negative_settings_are_refused(bad: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        TrainingConfig(**bad)


def test_off_by_default_and_refused_by_action_ff() -> None:
    assert TrainingConfig().hard_negatives is False
    assert _agent().hard_negative_buffer is None
    with pytest.raises(TypeError, match=r"online\.hard_negatives moved to training\.hard_negatives"):
        ActionFFAgent("MultiInputPolicy", gym.make("ebm/Maze-v0"), online={"hard_negatives": True}, device="cpu")
    with pytest.raises(ValueError, match="loss='cd'"):
        _agent({"hard_negatives": True}, loss="infonce")


def test_margin_term_pushes_the_failed_step_above_the_real_one() -> None:
    failed = torch.tensor([0.0, 3.0], requires_grad=True)  # [H]
    real = torch.tensor([0.0, 0.0], requires_grad=True)  # [H]
    term, stats = hard_negative_margin_loss(failed, real, margin=1.0)
    expected = (torch.nn.functional.softplus(torch.tensor(1.0)) + torch.nn.functional.softplus(torch.tensor(-2.0))) / 2
    assert torch.isclose(term, expected)
    term.backward()
    assert failed.grad is not None and real.grad is not None
    assert torch.all(failed.grad < 0) and torch.all(real.grad > 0)  # descent raises E(failed), lowers E(real)
    assert failed.grad[0] < failed.grad[1]  # the pair below the margin pulls harder
    assert stats["num_failed"] == 2.0
    with pytest.raises(ValueError, match="pair up"):
        hard_negative_margin_loss(failed, real[:1])
    with pytest.raises(ValueError, match="empty"):
        hard_negative_margin_loss(torch.zeros(0), torch.zeros(0))


def test_only_missed_steps_are_labelled_and_replayed() -> None:
    agent = _agent({"hard_negatives": True, "hard_negative_batch": 4})
    states = np.array([[-0.6, -0.8], [-0.55, -0.8], [-0.52, -0.8]])  # [3, 2]
    planned_next = np.array([[-0.55, -0.8], [-0.50, -0.8], [-0.47, -0.8]])  # the last step is into the wall x = -0.5
    real_next = np.array([[-0.55, -0.8], [-0.50, -0.8], [-0.52, -0.8]])  # the env kept the agent there
    batch, fresh = agent._hard_negatives([_segment(states, planned_next, real_next)])
    assert fresh == 1 and batch is not None and len(batch) == 1
    np.testing.assert_allclose(batch.states, states[2:], atol=1e-6)
    np.testing.assert_allclose(batch.next_states, planned_next[2:], atol=1e-6)  # the impossible move
    np.testing.assert_allclose(batch.actions, real_next[2:], atol=1e-6)  # paired with where the env went
    assert len(agent.hard_negative_buffer) == 1
    # A segment without a failed step still trains on the stored one.
    batch, fresh = agent._hard_negatives([_segment(states[:2], planned_next[:2], real_next[:2])])
    assert fresh == 0 and batch is not None and len(batch) == 1


def test_reach_clipping_keeps_the_refused_in_reach_move_and_drops_executed_long_jumps() -> None:
    states = np.array([[-0.8, -0.8], [-0.52, -0.8]])  # [2, 2]
    planned_next = np.array([[-0.5, -0.8], [-0.2, -0.8]])  # two jumps of 0.3: one in the open, one through the wall
    real_next = np.array([[-0.75, -0.8], [-0.52, -0.8]])  # the env moved one step (0.05) and refused the other
    plain = _agent({"hard_negatives": True})
    _, fresh = plain._hard_negatives([_segment(states, planned_next, real_next)])
    assert fresh == 2  # both jumps missed
    clipped = _agent({"hard_negatives": True, "hard_negative_reach": True})
    clipped._record_real_moves(states, real_next)
    batch, fresh = clipped._hard_negatives([_segment(states, planned_next, real_next)])
    assert fresh == 1 and batch is not None
    np.testing.assert_allclose(clipped.real_moves.largest, [0.05, 0.0], atol=1e-6)
    np.testing.assert_allclose(batch.next_states, [[-0.47, -0.8]], atol=1e-6)  # one step into the wall


@pytest.mark.parametrize("loss", ["margin", "negatives"])
def test_learning_with_hard_negatives_trains_on_failed_steps(loss: str, tmp_path) -> None:
    agent = _agent({"hard_negatives": True, "hard_negative_loss": loss, "hard_negative_reach": True})
    agent.learn(total_timesteps=600)
    assert len(agent.hard_negative_buffer) > 0  # the maze's first wall is reached within 600 steps from its start
    assert all(torch.isfinite(p).all() for p in agent.energy_model.parameters())
    path = agent.save_checkpoint(tmp_path / "checkpoint")
    loaded = EBMPlannerAgent.load_checkpoint(path, env=gym.make("ebm/Maze-v0"), device="cpu")
    assert loaded.training.hard_negatives and len(loaded.hard_negative_buffer) == len(agent.hard_negative_buffer)
    np.testing.assert_array_equal(
        loaded.hard_negative_buffer.get(np.arange(3)).next_states, agent.hard_negative_buffer.get(np.arange(3)).next_states
    )


def _gap_after_margin_steps(weight: float) -> tuple[float, float]:
    """The mean E(s, failed) - E(s, real) over 8 wall states before and after 30 gradient steps whose CD term cancels
    (positives = negatives), so that only the hard-negative term (weight ``weight``) moves the gap."""
    agent = _agent({"hard_negatives": True, "hard_negative_batch": 0, "hard_negative_weight": weight}, learning_rate=1e-2)
    states = np.full((8, 2), [-0.52, -0.8], np.float32)  # [8, 2] at the wall
    states[:, 1] += np.linspace(0.0, 0.07, 8, dtype=np.float32)
    failed_next = states + np.array([0.05, 0.0], np.float32)  # [8, 2] one step into the wall
    agent._hard_negatives([_segment(states, failed_next, states)])  # fill the buffer
    batch = agent.hard_negative_buffer.get(np.arange(8))
    energy = lambda a, b: agent.energy_model(torch.as_tensor(a), torch.as_tensor(b)).detach()  # noqa: E731
    before = float((energy(states, failed_next) - energy(states, states)).mean())
    for _ in range(30):
        agent._gradient_step(states, states, states, states, hard=batch)
    return before, float((energy(states, failed_next) - energy(states, states)).mean())


def test_margin_step_raises_the_failed_energy_against_the_real_one() -> None:
    before, after = _gap_after_margin_steps(10.0)
    control_before, control_after = _gap_after_margin_steps(0.0)
    assert after - before > 0.05
    assert abs(control_after - control_before) < 0.02


def test_negatives_mode_at_weight_one_is_cd_over_the_joined_negatives() -> None:
    agent = _agent({"hard_negatives": True, "hard_negative_loss": "negatives"}, l2_coeff=0.5)
    rng = np.random.default_rng(0)
    states = rng.uniform(-0.9, -0.6, (5, 2)).astype(np.float32)  # [5, 2]
    next_states = rng.uniform(-0.9, -0.6, (5, 2)).astype(np.float32)  # [5, 2]
    hard = agent._hard_negatives([_segment(states, next_states + 0.04, next_states)])[0]  # every step missed
    assert hard is not None and len(hard) == 5
    energy = agent.energy_model
    energy_pos, energy_neg = (
        energy(torch.as_tensor(states), torch.as_tensor(next_states)),
        energy(torch.as_tensor(next_states), torch.as_tensor(states)),
    )  # [5], [5]
    assert agent.loss_fn.hard_negative_loss == "negatives"  # built from the online settings
    as_tensor = torch.as_tensor
    batch = ContrastBatch(
        as_tensor(states),
        as_tensor(next_states),
        as_tensor(next_states),
        as_tensor(states),
        hard=(as_tensor(hard.states), as_tensor(hard.next_states), as_tensor(hard.actions)),
    )
    loss, stats = agent.loss_fn(energy, batch, agent.training.l2_coeff)
    joined = torch.cat([energy_neg, energy(torch.as_tensor(hard.states), torch.as_tensor(hard.next_states))])  # [10]
    expected, _ = contrastive_divergence_loss(energy_pos, joined, l2_coeff=0.5)
    assert torch.isclose(loss, expected, atol=1e-6) and stats["num_failed"] == 5.0


def test_a_model_saved_before_the_configs_were_split_loads_into_them(tmp_path) -> None:
    agent = _agent()
    # the layout of a model saved before issue 45: training settings as attributes and inside online
    del agent.training
    agent.__dict__.update(loss="cd", l2_coeff=0.3, reach_candidates=64, perturbed_negatives=0, perturb_scales=(1.0,))
    agent.online.hard_negatives = True  # type: ignore[attr-defined]
    agent.online.l2_final = 0.1  # type: ignore[attr-defined]
    agent.online.prior_warmup_plans = 50  # type: ignore[attr-defined]
    agent.save(tmp_path / "old.zip")
    loaded = EBMPlannerAgent.load(tmp_path / "old.zip", env=gym.make("ebm/Maze-v0"), device="cpu")
    assert loaded.training == TrainingConfig(l2_coeff=0.3, perturb_scales=(1.0,), hard_negatives=True, l2_final=0.1)
    assert loaded.cost_config.warmup_plans == 50 and loaded.hard_negative_buffer is not None
    assert "hard_negatives" not in vars(loaded.online) and "l2_coeff" not in vars(loaded)
    # a fresh save holds today's layout and loads as it was
    loaded.save(tmp_path / "new.zip")
    again = EBMPlannerAgent.load(tmp_path / "new.zip", env=gym.make("ebm/Maze-v0"), device="cpu")
    assert again.training == loaded.training and again.cost_config.warmup_plans == 50
