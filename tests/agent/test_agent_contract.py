"""SB3 contract tests for the planning agents (sb3-contrib's test_run / test_save_load style), parametrised over agents."""

from __future__ import annotations

import glob
import os

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback, EvalCallback
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv

import envs  # noqa: F401  (registers the ids)
from baselines.action_ff import ActionFFAgent
from ebm_agent import EBMPlannerAgent

# Tiny planners keep every test to a second or two; the behaviour under test does not depend on their size.
FAST_KWARGS = {
    EBMPlannerAgent: {
        "horizon": 5,
        "planner_config": {"num_samples": 16, "iterations": 4},
        "online": {"pos_buffer_size": 10_000},
        "image_log_interval": 0,
    },
    ActionFFAgent: {
        "horizon": 5,
        "planner_config": {"num_samples": 16, "iterations": 4},
        "online": {"pos_buffer_size": 10_000},
    },
}
AGENTS = list(FAST_KWARGS)


def make_agent(agent_class, env, **kwargs):
    """An agent of ``agent_class`` with the fast settings."""
    return agent_class("MultiInputPolicy", env, seed=0, **{**FAST_KWARGS[agent_class], **kwargs})


class CountingCallback(BaseCallback):
    """Counts on_step calls."""

    def __init__(self) -> None:
        super().__init__()
        self.calls = 0

    def _on_step(self) -> bool:
        self.calls += 1
        return True


class StopAfter(BaseCallback):
    """Stops training after ``n`` steps."""

    def __init__(self, n: int) -> None:
        super().__init__()
        self.n = n

    def _on_step(self) -> bool:
        return self.n_calls < self.n


@pytest.mark.parametrize("agent_class", AGENTS)
@pytest.mark.parametrize("budget", [1, 37, 120])
def test_exact_step_budget_and_one_callback_per_transition(agent_class, budget):
    agent = make_agent(agent_class, gym.make("ebm/Particle-v0"))
    counter = CountingCallback()
    agent.learn(budget, callback=counter)
    assert agent.num_timesteps == budget
    assert counter.calls == budget


@pytest.mark.parametrize("agent_class", AGENTS)
def test_exact_budget_with_several_envs_and_a_non_multiple_rounded_down(agent_class):
    vec = DummyVecEnv([lambda: gym.make("ebm/Particle-v0")] * 3)
    agent = make_agent(agent_class, vec)
    agent.learn(60)
    assert agent.num_timesteps == 60
    with pytest.warns(UserWarning, match="multiple of n_envs=3.*learn consumes 60"):
        agent.learn(61)  # never more transitions than the budget
    assert agent.num_timesteps == 60


@pytest.mark.parametrize("agent_class", AGENTS)
def test_learn_continues_counter_and_callback_can_stop(agent_class):
    agent = make_agent(agent_class, gym.make("ebm/Particle-v0"))
    agent.learn(30)
    agent.learn(20, reset_num_timesteps=False)
    assert agent.num_timesteps == 50
    agent.learn(100, callback=StopAfter(7))
    assert agent.num_timesteps == 7


@pytest.mark.parametrize("agent_class", AGENTS)
def test_save_load_gives_identical_deterministic_predict(agent_class, tmp_path):
    env = gym.make("ebm/Particle-v0")
    agent = make_agent(agent_class, env)
    agent.learn(60)
    obs, _ = env.reset(seed=3)
    action, _state = agent.predict(obs, deterministic=True)
    again, _ = agent.predict(obs, deterministic=True)
    np.testing.assert_array_equal(action, again)
    assert action.shape == env.action_space.shape
    path = tmp_path / "agent.zip"
    agent.save(path)
    loaded = agent_class.load(path, env=gym.make("ebm/Particle-v0"))
    loaded_action, _ = loaded.predict(obs, deterministic=True)
    np.testing.assert_array_equal(action, loaded_action)
    assert loaded.num_timesteps == agent.num_timesteps
    for (name, p1), (_, p2) in zip(agent.policy.state_dict().items(), loaded.policy.state_dict().items()):
        assert np.array_equal(p1.cpu().numpy(), p2.cpu().numpy()), name
    with pytest.warns(UserWarning, match="replay buffers start empty"):
        loaded.learn(10)  # a loaded agent keeps learning, from empty buffers


@pytest.mark.parametrize("agent_class", AGENTS)
def test_set_env_and_mismatched_env_rejected(agent_class, tmp_path):
    agent = make_agent(agent_class, gym.make("ebm/Particle-v0"))
    agent.set_env(gym.make("ebm/Particle-v0", goal=(-0.5, 0.2)))
    agent.learn(10)
    agent.save(tmp_path / "a.zip")
    with pytest.raises((ValueError, AssertionError)):
        agent_class.load(tmp_path / "a.zip", env=gym.make("ebm/Reacher-v0"))


@pytest.mark.parametrize("agent_class", AGENTS)
def test_batched_predict_and_state_carry(agent_class):
    vec = DummyVecEnv([lambda: gym.make("ebm/Particle-v0")] * 3)
    agent = make_agent(agent_class, vec)
    obs = vec.reset()
    actions, state = agent.predict(obs, deterministic=True)
    assert actions.shape == (3, 2)
    assert np.all(np.abs(actions) <= 1.0)
    plans, _, steps, aims = state
    assert plans.shape == (3, agent.horizon + 1, 2) and np.array_equal(aims, obs["desired_goal"])
    np.testing.assert_allclose(plans[:, 0], obs["observation"], atol=1e-6)  # the start is pinned
    assert np.all(steps == 1)
    _, state = agent.predict(obs, state=state, episode_start=np.zeros(3, dtype=bool), deterministic=True)
    assert np.all(state[2] == 2)  # followed the same plan


@pytest.mark.parametrize("agent_class", AGENTS)
def test_arrival_threshold_replans_a_plan_that_has_arrived(agent_class):
    vec = DummyVecEnv([lambda: gym.make("ebm/Particle-v0")] * 2)
    obs = vec.reset()
    keep = np.zeros(2, dtype=bool)
    for threshold, expected in ((None, [2, 2]), (0.01, [1, 2])):
        agent = make_agent(agent_class, vec, online={**FAST_KWARGS[agent_class]["online"], "arrival_threshold": threshold})
        _, (plans, actions, steps, aims) = agent.predict(obs, deterministic=True)
        plans[0, -1] = obs["observation"][0]  # env 0's plan ends where it already is: nothing left but hovering
        plans[1, -1] = obs["observation"][1] + 0.5  # env 1's plan still has somewhere to go
        _, state = agent.predict(obs, state=(plans, actions, steps, aims), episode_start=keep, deterministic=True)
        assert state[2].tolist() == expected  # a new plan restarts at step 1; a followed one goes on to step 2
        # A state of three arrays (before predict kept the aims) is followed as before.
        _, state = agent.predict(obs, state=(plans, actions, steps), episode_start=keep, deterministic=True)
        assert state[2].tolist() == expected


@pytest.mark.parametrize("agent_class", AGENTS)
def test_arrival_at_the_aim_replans_a_plan_whose_aim_is_reached(agent_class):
    vec = DummyVecEnv([lambda: gym.make("ebm/Particle-v0")] * 2)
    obs = vec.reset()
    keep = np.zeros(2, dtype=bool)
    for arrival_at, expected in (("plan_end", [2, 2]), ("aim", [1, 2])):
        online = {**FAST_KWARGS[agent_class]["online"], "arrival_threshold": 0.01, "arrival_at": arrival_at}
        agent = make_agent(agent_class, vec, online=online)
        _, (plans, actions, steps, aims) = agent.predict(obs, deterministic=True)
        assert np.array_equal(aims, obs["desired_goal"])  # no subgoals: each plan aims at its goal
        plans[:, -1] = obs["observation"] + 0.5  # neither plan ends where its env is
        aims[0] = obs["observation"][0]  # env 0 already stands at its plan's aim: the plan has done its job
        _, state = agent.predict(obs, state=(plans, actions, steps, aims), episode_start=keep, deterministic=True)
        assert state[2].tolist() == expected
    with pytest.raises(ValueError, match="arrival_at must be one of"):
        make_agent(agent_class, vec, online={"arrival_at": "goal"})


def test_arrival_threshold_rejects_bad_values():
    env = gym.make("ebm/Particle-v0")
    with pytest.raises(ValueError, match="arrival_threshold must be None"):
        make_agent(EBMPlannerAgent, env, online={"arrival_threshold": -0.1})
    with pytest.raises(TypeError, match="arrival_threshold"):
        make_agent(EBMPlannerAgent, env, online={"arrival_threshold": "near"})


@pytest.mark.parametrize("agent_class", AGENTS)
def test_evaluate_policy_and_sb3_callbacks(agent_class, tmp_path):
    agent = make_agent(agent_class, gym.make("ebm/Particle-v0"))
    eval_env = Monitor(gym.make("ebm/Particle-v0", start=(0.0, 0.0), goal=(0.5, 0.5)))
    eval_cb = EvalCallback(eval_env, n_eval_episodes=1, eval_freq=40, log_path=str(tmp_path), verbose=0)
    ckpt_cb = CheckpointCallback(save_freq=40, save_path=str(tmp_path / "ckpt"))
    agent.learn(80, callback=[eval_cb, ckpt_cb])
    data = np.load(tmp_path / "evaluations.npz")
    assert list(data["timesteps"]) == [40, 80]
    assert sorted(os.listdir(tmp_path / "ckpt")) == ["rl_model_40_steps.zip", "rl_model_80_steps.zip"]
    rewards, _lengths = evaluate_policy(agent, eval_env, n_eval_episodes=2, return_episode_rewards=True)
    assert len(rewards) == 2 and all(np.isfinite(rewards))


@pytest.mark.parametrize("agent_class", AGENTS)
def test_tensorboard_keys(agent_class, tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    agent = make_agent(agent_class, gym.make("ebm/Particle-v0"), tensorboard_log=str(tmp_path))
    agent.learn(250)  # > 2 episodes of 100 steps, so rollout/* is logged
    runs = glob.glob(str(tmp_path / "*"))
    assert len(runs) == 1
    accumulator = EventAccumulator(runs[0])
    accumulator.Reload()
    tags = set(accumulator.Tags()["scalars"])
    for key in ("rollout/ep_rew_mean", "time/fps", "train/loss", "plan/ms", "plan/goal_dist"):
        assert key in tags, (key, tags)


@pytest.mark.parametrize("agent_class", AGENTS)
def test_seeded_runs_are_reproducible(agent_class):
    def run(seed):
        agent = agent_class("MultiInputPolicy", gym.make("ebm/Particle-v0"), seed=seed, **FAST_KWARGS[agent_class])
        agent.learn(40)
        obs, _ = gym.make("ebm/Particle-v0", start=(0.0, 0.0)).reset(seed=0)
        return agent.predict(obs, deterministic=True)[0]

    np.testing.assert_array_equal(run(1), run(1))
    assert not np.array_equal(run(1), run(2))


class NoGoalEnv(gym.Env):
    """A Box-observation env (no goal keys)."""

    observation_space = spaces.Box(-1, 1, (2,), np.float32)
    action_space = spaces.Box(-1, 1, (2,), np.float32)

    def reset(self, *, seed=None, options=None):
        return np.zeros(2, np.float32), {}

    def step(self, action):
        return np.zeros(2, np.float32), 0.0, False, False, {}


class DiscreteGoalEnv(NoGoalEnv):
    """A goal env with Discrete actions."""

    observation_space = spaces.Dict(
        {k: spaces.Box(-1, 1, (2,), np.float32) for k in ("observation", "achieved_goal", "desired_goal")}
    )
    action_space = spaces.Discrete(4)


@pytest.mark.parametrize("agent_class", AGENTS)
def test_bad_spaces_and_inputs_give_clear_errors(agent_class):
    with pytest.raises(TypeError, match="goal-conditioned Dict observation"):
        agent_class("MultiInputPolicy", NoGoalEnv())
    with pytest.raises(TypeError, match="Box action space"):
        agent_class("MultiInputPolicy", DiscreteGoalEnv())
    env = gym.make("ebm/Particle-v0")
    agent = make_agent(agent_class, env)
    obs, info = env.reset(seed=0)
    with pytest.raises(ValueError, match=r"\(obs, info\) tuple"):
        agent.predict((obs, info))
    bad = {k: v.copy() for k, v in obs.items()}
    bad["observation"][0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        agent.predict(bad)
    wrong = {k: np.zeros(5, np.float32) for k in obs}
    with pytest.raises(ValueError, match="built for D=2"):
        agent.predict(wrong)
    with pytest.raises(ValueError, match="total_timesteps"):
        agent.learn(-5)


def test_tensorboard_plan_image_for_2d_states(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    kwargs = {**FAST_KWARGS[EBMPlannerAgent], "image_log_interval": 2}
    agent = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Particle-v0"), seed=0, tensorboard_log=str(tmp_path), **kwargs)
    agent.learn(40)
    accumulator = EventAccumulator(glob.glob(str(tmp_path / "*"))[0])
    accumulator.Reload()
    assert "plan/energy_map" in accumulator.Tags()["images"]


@pytest.mark.parametrize("agent_class", AGENTS)
def test_train_every_plan_false_fills_the_buffer_and_leaves_the_model_as_initialised(agent_class):
    """The untrained control of an online configuration: the same loop, no gradient step on the model."""
    import torch

    def weights(agent):
        return [p.detach().clone() for p in agent.policy.parameters()]

    frozen = make_agent(
        agent_class, gym.make("ebm/Particle-v0"), online={**FAST_KWARGS[agent_class]["online"], "train_every_plan": False}
    )
    trained = make_agent(agent_class, gym.make("ebm/Particle-v0"))
    before = weights(frozen)
    assert all(torch.equal(a, b) for a, b in zip(before, weights(trained)))  # same seed: same initial model
    frozen.learn(60)
    trained.learn(60)
    assert len(frozen.pos_buffer) == len(trained.pos_buffer) > 0
    assert all(torch.equal(a, b) for a, b in zip(before, weights(frozen)))
    assert not all(torch.equal(a, b) for a, b in zip(before, weights(trained)))
