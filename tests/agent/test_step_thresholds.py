"""Thresholds in units of the env's measured step (``OnlineConfig.threshold_units="step"``, issue 45).

The same agent on the maze and on the maze with every state and goal multiplied by 10 must take the same decisions:
replan on drift, replan on arrival, end a training segment on deviation and label a failed step. In the env's own
state units (the default, the original's) it does not, which is the control that shows these tests can fail.
"""

from __future__ import annotations

import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium import spaces

import envs  # noqa: F401
from baselines.action_ff import ActionFFAgent
from ebm_agent import EBMPlannerAgent
from ebm_agent.base import Segment
from ebm_agent.config import OnlineConfig

SMALL = {
    "planner_config": {"num_samples": 16, "iterations": 2},
    "energy": {"hidden_dim": 16, "num_hidden_layers": 2},
    "image_log_interval": 0,
    "device": "cpu",
}
"""A cheap agent: these tests check decisions, not the planning."""

STEP = {"threshold_units": "step", "replan_threshold": 1.0, "arrival_threshold": 0.5, "arrival_at": "aim"}
"""The maze's following thresholds (0.05 drift, 0.025 arrival) in units of its 0.05 step."""

STATE = {"replan_threshold": 0.05, "arrival_threshold": 0.025, "arrival_at": "aim"}
"""The same thresholds in the maze's own state units (eval/presets/maze_follow.yaml)."""


class ScaledGoalEnv(gym.Wrapper):
    """A goal env whose states and goals are those of ``env`` times ``scale``: the same env in other units.

    :param env: a goal env of :mod:`envs` (``state_low``, ``state_high``, ``goal_indices``, ``inverse_dynamics``).
    :param scale: the factor.
    """

    def __init__(self, env: gym.Env, scale: float) -> None:
        super().__init__(env)
        self.scale = float(scale)
        base: Any = env.unwrapped
        self.observation_space = spaces.Dict(
            {
                key: spaces.Box(box.low * self.scale, box.high * self.scale, dtype=np.float32)
                for key, box in env.observation_space.spaces.items()  # type: ignore[attr-defined]
            }
        )
        self.state_low, self.state_high = base.state_low * self.scale, base.state_high * self.scale
        self.goal_indices = base.goal_indices

    def _scaled(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {key: (value * self.scale).astype(np.float32) for key, value in obs.items()}

    def reset(self, **kwargs: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        return self._scaled(obs), info

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._scaled(obs), float(reward), terminated, truncated, info

    def inverse_dynamics(self, states: np.ndarray, next_states: np.ndarray) -> np.ndarray:
        """The wrapped env's inverse dynamics in the scaled units ([B, D], [B, D] -> [B, A])."""
        base: Any = self.env.unwrapped
        return base.inverse_dynamics(states / self.scale, next_states / self.scale)


def _agent(scale: float, online: dict, cls: type = EBMPlannerAgent, **kwargs: Any) -> Any:
    torch.set_num_threads(1)
    env = ScaledGoalEnv(gym.make("ebm/Maze-v0"), scale)
    if cls is ActionFFAgent:
        return cls("MultiInputPolicy", env, seed=0, online=online, device="cpu", **kwargs)
    return cls("MultiInputPolicy", env, seed=0, online=online, **SMALL, **kwargs)


def _real_moves(scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Real maze transitions in the open, the largest move exactly one 0.05 step per dim, times ``scale``."""
    states = np.array([[0.0, 0.6], [0.1, 0.6], [0.2, 0.6]], dtype=np.float32)  # [3, 2]
    moves = np.array([[0.05, -0.05], [0.02, 0.01], [-0.03, 0.05]], dtype=np.float32)  # [3, 2]
    return states * scale, (states + moves) * scale


def _replanned(agent: Any, scale: float) -> list[int]:
    """Which of six envs with a plan in flight ``predict`` replans, from crafted drifts and aims (maze units x scale).

    Envs 0-3 drift from their plan by 0.5, 0.9, 1.1 and 2 steps per dim (the replan threshold is 1 step, mean over
    dims); envs 4-5 do not drift and sit 0.3 and 0.7 steps from their aim (the arrival threshold is 0.5 step).
    """
    horizon = agent.horizon
    states = np.tile(np.array([[0.0, 0.6]], dtype=np.float32), (6, 1))  # [6, 2]
    drift = np.array([0.5, 0.9, 1.1, 2.0, 0.0, 0.0], dtype=np.float32) * 0.05  # [6]
    plans = np.repeat(states[:, None, :], horizon + 1, axis=1)  # [6, T+1, 2]
    plans[:, 2, :] += drift[:, None]
    aims = np.full((6, 2), 0.9, dtype=np.float32)  # [6, 2] far: no arrival for envs 0-3
    aims[4], aims[5] = states[4] + 0.3 * 0.05, states[5] + 0.7 * 0.05
    steps = np.full(6, 2, dtype=np.int64)
    actions = np.full((6, horizon, 2), np.nan, dtype=np.float32)
    obs = {
        "observation": states * scale,
        "achieved_goal": states * scale,
        "desired_goal": np.full((6, 2), 0.9 * scale, dtype=np.float32),
    }
    _, (_, _, new_steps, _) = agent.predict(obs, state=(plans * scale, actions, steps, aims * scale), deterministic=True)
    return [int(i) for i in np.where(new_steps == 1)[0]]


def test_threshold_units_are_checked() -> None:
    assert OnlineConfig().threshold_units == "state"
    with pytest.raises(ValueError, match=r"threshold_units must be one of \('state', 'step'\)"):
        OnlineConfig(threshold_units="metres")


@pytest.mark.parametrize("cls", [EBMPlannerAgent, ActionFFAgent])
def test_predict_decisions_do_not_depend_on_the_env_scale(cls: type) -> None:
    decisions = {}
    for scale in (1.0, 10.0):
        agent = _agent(scale, STEP, cls)
        agent._record_real_moves(*_real_moves(scale))
        np.testing.assert_allclose(agent._threshold_unit(), [0.05 * scale, 0.05 * scale], rtol=1e-5)
        decisions[scale] = _replanned(agent, scale)
    assert decisions[1.0] == [2, 3, 4]  # drifted more than a step, or within half a step of the aim
    assert decisions[10.0] == decisions[1.0]


def test_state_units_take_other_decisions_on_the_scaled_env() -> None:
    same_maze = _agent(1.0, STATE)
    same_maze._record_real_moves(*_real_moves(1.0))
    assert _replanned(same_maze, 1.0) == [2, 3, 4]  # the absolute thresholds were tuned on this maze
    scaled = _agent(10.0, STATE)
    scaled._record_real_moves(*_real_moves(10.0))
    assert _replanned(scaled, 10.0) == [0, 1, 2, 3]  # every drift exceeds 0.05 and no aim is within 0.025


def _segment(states: np.ndarray, planned_next: np.ndarray, real_next: np.ndarray) -> Segment:
    planned = np.concatenate([states[:1], planned_next]).astype(np.float32)  # [k + 1, 2]
    return Segment(planned, states.astype(np.float32), real_next.astype(np.float32), np.zeros((len(states), 2), np.float32))


@pytest.mark.parametrize("units, expected", [("step", (2, 2)), ("state", (2, 3))])
def test_failed_steps_scale_with_the_env(units: str, expected: tuple[int, int]) -> None:
    failed = []
    for scale in (1.0, 10.0):
        threshold = 0.2 if units == "step" else 0.01  # a fifth of the maze's step, in either unit
        training = {"hard_negatives": True, "hard_negative_threshold": threshold}
        agent = _agent(scale, {"threshold_units": units}, training=training)
        states, real_next = _real_moves(scale)
        # misses of 0.1, 0.3 and 0.5 maze steps (0.005, 0.015, 0.025 in its units) in x
        planned_next = real_next + np.array([[0.005], [0.015], [0.025]], dtype=np.float32) * np.array([[scale, 0.0]])
        agent._record_real_moves(states, real_next)
        failed.append(agent._hard_negatives([_segment(states, planned_next.astype(np.float32), real_next)])[1])
    assert tuple(failed) == expected


@pytest.mark.parametrize("cls", [EBMPlannerAgent, ActionFFAgent])
def test_learn_records_every_learnt_transition(cls: type) -> None:
    agent = _agent(1.0, {"threshold_units": "step"}, cls, horizon=5)
    assert agent._moves is None
    agent.learn(30)
    assert agent.real_moves.count == len(agent.pos_buffer) > 0  # the moves of exactly the transitions learnt from
    assert np.all(agent.real_moves.largest <= 0.05 + 1e-6)  # the maze moves at most one step per dim


def test_no_measured_step_warns_once_and_lets_plans_run() -> None:
    agent = _agent(1.0, STEP)
    with pytest.warns(UserWarning, match="no real move was recorded yet"):
        assert _replanned(agent, 1.0) == []
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _replanned(agent, 1.0) == []


def test_the_measured_step_is_saved_with_the_agent(tmp_path: Any) -> None:
    agent = _agent(10.0, STEP)
    agent._record_real_moves(*_real_moves(10.0))
    agent.save(tmp_path / "agent.zip")
    loaded = EBMPlannerAgent.load(tmp_path / "agent.zip", env=ScaledGoalEnv(gym.make("ebm/Maze-v0"), 10.0), device="cpu")
    np.testing.assert_array_equal(loaded.real_moves.largest, agent.real_moves.largest)
    assert loaded.real_moves.count == 3
    assert _replanned(loaded, 10.0) == [2, 3, 4]


@pytest.mark.parametrize("units", ["state", "step"])
def test_a_zero_threshold_replans_at_every_step(units: str) -> None:
    every = _agent(1.0, {"threshold_units": units, "replan_threshold": 0.0})
    every._record_real_moves(*_real_moves(1.0))
    assert _replanned(every, 1.0) == [0, 1, 2, 3, 4, 5]  # the envs that did not drift too (the control: [2, 3, 4] above)
    learner = _agent(1.0, {"threshold_units": units, "deviation_threshold": 0.0}, horizon=5)
    learner.learn(40)
    assert learner.num_plans >= 40  # every segment is one step: a new plan from the real state at every step
    control = _agent(1.0, {"threshold_units": units}, horizon=5)
    control.learn(40)
    assert control.num_plans < 30  # the default deviation lets plans run for several steps
    with pytest.raises(ValueError, match=r"replan_threshold must be >= 0 \(0: a new plan at every step\)"):
        OnlineConfig(replan_threshold=-1.0)
