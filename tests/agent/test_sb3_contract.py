"""Where a user expects Stable-Baselines3's behaviour: clear refusals, warnings that name the fix, and the goal dims
that the agent infers shown and overridable (issue 45)."""

from __future__ import annotations

import warnings
from typing import ClassVar

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from stable_baselines3.common.env_util import make_vec_env

import envs  # noqa: F401
from baselines.action_ff import ActionFFAgent
from ebm_agent import EBMPlannerAgent
from ebm_agent.base import LEARNED_INVERSE_DYNAMICS
from ebm_agent.inverse_dynamics import GroundTruthInverseDynamics, RLSInverseDynamics

TINY = {"planner_config": {"num_samples": 8, "iterations": 2}, "horizon": 4}


class PointGoalEnv(gym.Env):
    """A 2-D point with a goal that declares nothing: no inverse dynamics, no goal_indices (a user's own env)."""

    metadata: ClassVar[dict] = {"render_modes": []}

    def __init__(self) -> None:
        self.observation_space = spaces.Dict(
            {
                "observation": spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32),  # [speed, x, y]
                "achieved_goal": spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32),
                "desired_goal": spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32),
            }
        )
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self._state = np.zeros(3, dtype=np.float32)

    def _obs(self) -> dict:
        return {
            "observation": self._state.copy(),
            "achieved_goal": self._state[1:].copy(),
            "desired_goal": np.array([0.5, 0.5], dtype=np.float32),
        }

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self._state = np.array([0.0, *self.np_random.uniform(-0.9, 0.9, size=2)], dtype=np.float32)
        return self._obs(), {}

    def step(self, action):
        move = 0.05 * np.clip(action, -1, 1)
        self._state[1:] = np.clip(self._state[1:] + move, -1, 1)
        self._state[0] = float(np.abs(move).sum())
        distance = float(np.abs(self._state[1:] - 0.5).sum())
        return self._obs(), -distance, False, False, {"is_success": distance < 0.05}

    def compute_reward(self, achieved_goal, desired_goal, info):
        return -np.abs(achieved_goal - desired_goal).sum(axis=-1)


def test_ground_truth_inverse_dynamics_on_an_env_without_them_fail_at_construction():
    with pytest.raises(ValueError, match=r"has no `inverse_dynamics.*'rls'.*'mlp'"):
        EBMPlannerAgent("MultiInputPolicy", PointGoalEnv(), inverse_dynamics="ground_truth", **TINY)


@pytest.mark.parametrize("agent_class", [EBMPlannerAgent, ActionFFAgent])
def test_the_default_picks_the_learned_inverse_model_and_says_so(agent_class):
    with pytest.warns(UserWarning, match=f"has no `inverse_dynamics`.*{LEARNED_INVERSE_DYNAMICS!r}"):
        agent = agent_class("MultiInputPolicy", PointGoalEnv(), seed=0, horizon=4)
    assert isinstance(agent.inverse_model, RLSInverseDynamics)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an env with its own inverse dynamics uses them, silently
        own = agent_class("MultiInputPolicy", gym.make("ebm/Particle-v0"), seed=0, horizon=4)
    assert isinstance(own.inverse_model, GroundTruthInverseDynamics)


def test_mlp_policy_is_refused_naming_the_policy_it_takes():
    with pytest.raises(ValueError, match="takes policy 'MultiInputPolicy'"):
        EBMPlannerAgent("MlpPolicy", gym.make("ebm/Particle-v0"), **TINY)


def test_cuda_without_cuda_warns_and_runs_on_the_cpu(monkeypatch):
    monkeypatch.setattr("torch.cuda.is_available", lambda: False)
    with pytest.warns(UserWarning, match="CUDA is not available"):
        agent = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Particle-v0"), device="cuda", **TINY)
    assert agent.device.type == "cpu"


def test_a_budget_that_is_not_a_multiple_of_n_envs_is_rounded_down_with_a_warning():
    agent = EBMPlannerAgent("MultiInputPolicy", make_vec_env("ebm/Particle-v0", n_envs=2, seed=0), seed=0, **TINY)
    with pytest.warns(UserWarning, match="learn consumes 6"):
        agent.learn(7)
    assert agent.num_timesteps == 6


def test_learn_after_load_warns_that_the_buffers_start_empty(tmp_path):
    agent = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Particle-v0"), seed=0, **TINY)
    agent.learn(4)
    agent.save(tmp_path / "model.zip")
    loaded = EBMPlannerAgent.load(tmp_path / "model.zip", env=gym.make("ebm/Particle-v0"))
    with pytest.warns(UserWarning, match="replay buffers start empty.*load_checkpoint"):
        loaded.learn(2, reset_num_timesteps=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        agent.learn(2, reset_num_timesteps=False)  # its own buffers are full: no warning


def test_inferred_goal_dims_are_printed_and_can_be_overridden(capsys):
    with pytest.warns(UserWarning):  # the learned inverse model
        agent = EBMPlannerAgent("MultiInputPolicy", PointGoalEnv(), seed=0, verbose=1, **TINY)
    assert agent.goal_spec.goal_indices.tolist() == [1, 2] and agent.goal_spec.goal_indices_inferred
    assert "goal dims inferred from a reset observation: observation[1, 2] == achieved_goal" in capsys.readouterr().out
    with pytest.warns(UserWarning):
        given = EBMPlannerAgent("MultiInputPolicy", PointGoalEnv(), seed=0, goal_indices=[2, 1], **TINY)
    assert given.goal_spec.goal_indices.tolist() == [2, 1] and not given.goal_spec.goal_indices_inferred
    with pytest.raises(ValueError, match="must name 2 observation dims"):
        EBMPlannerAgent("MultiInputPolicy", PointGoalEnv(), goal_indices=[0, 5], **TINY)
