"""Learned action inference on an env without inverse dynamics: the damped point mass of tests/agent/point_mass.py,
whose state holds velocities. The default agent there must reach goals that zero torque, random torques and the
one-step RLS solve do not (issue 46)."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import pytest
import torch
from gymnasium.wrappers import TimeLimit
from point_mass import PointMassEnv  # tests/agent is on sys.path

from ebm_agent import EBMPlannerAgent
from ebm_agent.base import LEARNED_INVERSE_DYNAMICS
from ebm_agent.inverse_dynamics import RLSInverseDynamics

# Cheap planning (the fast preset's budgets, fewer fresh iterations) so that a run learns in a few seconds.
CHEAP: dict[str, Any] = {"planner_config": {"iterations": 20, "warm_iterations": 3, "train_iterations": 10}}
BUDGET = 1000
EPISODES = 10


def _env() -> TimeLimit:
    return TimeLimit(PointMassEnv(), max_episode_steps=100)


def _reach_rate(act: Any) -> float:
    """Fraction of evaluation episodes (reset seeds 100..) that reach the goal; ``act(obs, state, start)``."""
    env, reached = _env(), []
    for episode in range(EPISODES):
        obs, _ = env.reset(seed=100 + episode)
        state, start, info = None, True, {"is_success": 0.0}
        for _ in range(100):
            action, state = act(obs, state, start)
            start = False
            obs, _reward, _terminated, _truncated, info = env.step(action)
            if info["is_success"]:
                break
        reached.append(info["is_success"])
    return float(np.mean(reached))


def _trained(**kwargs: Any) -> EBMPlannerAgent:
    torch.set_num_threads(1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the learned-default notice, tested below
        agent = EBMPlannerAgent("MultiInputPolicy", _env(), seed=0, **{**CHEAP, **kwargs})
    agent.learn(BUDGET)
    return agent


def _policy(agent: EBMPlannerAgent) -> Any:
    def act(obs: dict, state: Any, start: bool) -> tuple[np.ndarray, Any]:
        return agent.predict(obs, state=state, episode_start=np.array([start]), deterministic=True)

    return act


def test_the_default_on_an_env_without_inverse_dynamics_follows_its_plans_and_says_so() -> None:
    with pytest.warns(UserWarning, match=f"has no `inverse_dynamics`.*{LEARNED_INVERSE_DYNAMICS!r}"):
        agent = EBMPlannerAgent("MultiInputPolicy", _env(), seed=0, **CHEAP)
    assert LEARNED_INVERSE_DYNAMICS == "rls_tracking"
    assert isinstance(agent.inverse_model, RLSInverseDynamics) and agent.inverse_model.track_steps is None


def test_the_learned_default_reaches_goals_that_zero_random_and_one_step_actions_do_not() -> None:
    rng = np.random.default_rng(0)
    default = _reach_rate(_policy(_trained()))
    one_step = _reach_rate(_policy(_trained(inverse_dynamics="rls")))
    zero = _reach_rate(lambda obs, state, start: (np.zeros(2, dtype=np.float32), None))
    random = _reach_rate(lambda obs, state, start: (rng.uniform(-1, 1, 2).astype(np.float32), None))
    assert default >= 0.8, default
    # Controls: the same agent solving for the next planned state alone (1000 transitions, seed 0, 10 episodes: 0.3),
    # and no model at all.
    assert one_step <= 0.5 and default > one_step, (default, one_step)
    assert zero <= 0.2 and random <= 0.2, (zero, random)


def test_planner_noise_in_steps_scales_each_dim_by_its_largest_real_move() -> None:
    agent = _trained(planner_config={**CHEAP["planner_config"], "noise_units": "step", "noise_scale": 3e-4})
    agent.predict(_env().reset(seed=0)[0], deterministic=True)
    np.testing.assert_allclose(agent.planner.noise_unit.numpy(), agent.real_moves.largest, rtol=1e-6)
