"""Contract tests for the random-exploration agent: SB3 surface, exact budgets, visited states and occupancy."""

from __future__ import annotations

import csv
import os

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.logger import configure
from stable_baselines3.common.monitor import Monitor

import envs  # noqa: F401  (registers the ebm/ ids)
from baselines.ppo import exact_budget_callback
from baselines.random_agent import RandomAgent, RandomPolicy, count_occupied_cells

EBM_ENV_IDS = ["ebm/Particle-v0", "ebm/Maze-v0", "ebm/Reacher-v0", "ebm/SawyerReach-v0"]


class DotGoalEnv(gym.Env):
    """A stand-in goal env: a dot in [-1, 1]^2 moved by 0.1 x action, 20-step episodes, success within 0.05."""

    metadata: dict = {"render_modes": []}  # noqa: RUF012

    def __init__(self, episode_steps: int = 20) -> None:
        box = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.observation_space = spaces.Dict({"observation": box, "achieved_goal": box, "desired_goal": box})
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.episode_steps = episode_steps
        self.goal = np.array([0.5, 0.5], np.float32)

    def _obs(self) -> dict[str, np.ndarray]:
        return {"observation": self.pos.copy(), "achieved_goal": self.pos.copy(), "desired_goal": self.goal.copy()}

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.pos = self.np_random.uniform(-1, 1, 2).astype(np.float32)
        self.t = 0
        return self._obs(), {}

    def step(self, action):
        self.pos = np.clip(self.pos + 0.1 * np.asarray(action, np.float32), -1, 1).astype(np.float32)
        self.t += 1
        distance = float(np.abs(self.pos - self.goal).sum())
        success = distance < 0.05
        return self._obs(), -distance, success, self.t >= self.episode_steps, {"is_success": success}


class SamplerDotGoalEnv(DotGoalEnv):
    """The stand-in env with an exploration sampler that only ever pushes right (so its use is visible)."""

    def __init__(self) -> None:
        super().__init__()
        self.sampler_calls = 0

    def sample_exploration_action(self) -> np.ndarray:
        self.sampler_calls += 1
        return np.array([1.0, 0.0], np.float32)


class CountingCallback(BaseCallback):
    def __init__(self) -> None:
        super().__init__()
        self.timesteps_seen: list[int] = []

    def _on_step(self) -> bool:
        self.timesteps_seen.append(self.num_timesteps)
        return True


def make_dot_vec_env(n_envs: int = 1, seed: int = 0, env_class: type[gym.Env] = DotGoalEnv):
    return make_vec_env(env_class, n_envs=n_envs, seed=seed)


@pytest.mark.parametrize("n_envs", [1, 4])
def test_learn_consumes_exact_budget_and_calls_back_once_per_step(n_envs: int) -> None:
    agent = RandomAgent("MultiInputPolicy", make_dot_vec_env(n_envs), seed=0)
    counter = CountingCallback()
    agent.learn(total_timesteps=200, callback=counter)
    assert agent.num_timesteps == 200
    assert counter.n_calls == 200 // n_envs
    assert counter.timesteps_seen == list(range(n_envs, 201, n_envs))


def test_budget_not_multiple_of_n_envs_overshoots_by_less_than_n_envs() -> None:
    agent = RandomAgent("MultiInputPolicy", make_dot_vec_env(4), seed=0)
    agent.learn(total_timesteps=10)
    assert agent.num_timesteps == 12


def test_callback_returning_false_stops_learning() -> None:
    agent = RandomAgent("MultiInputPolicy", make_dot_vec_env(4), seed=0)
    agent.learn(total_timesteps=400, callback=exact_budget_callback(40))
    assert agent.num_timesteps == 40


def test_episode_statistics_and_logged_keys(tmp_path) -> None:
    agent = RandomAgent("MultiInputPolicy", make_dot_vec_env(2), seed=0)
    agent.set_logger(configure(str(tmp_path), ["csv"]))
    agent.learn(total_timesteps=200, log_interval=4)
    assert agent.ep_info_buffer is not None and len(agent.ep_info_buffer) == 10  # 2 envs x 100 steps / 20
    assert all(info["l"] == 20 for info in agent.ep_info_buffer)
    assert agent.ep_success_buffer is not None and len(agent.ep_success_buffer) == 10
    with open(tmp_path / "progress.csv") as file:
        rows = list(csv.DictReader(file))
    assert len(rows) >= 2
    for key in ("rollout/ep_rew_mean", "rollout/ep_len_mean", "rollout/success_rate", "time/fps"):
        assert key in rows[-1] and rows[-1][key] != ""
    assert float(rows[-1]["rollout/ep_len_mean"]) == 20.0
    assert int(rows[-1]["time/total_timesteps"]) == 200


def test_episode_statistics_without_monitor_wrapper() -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    agent = RandomAgent("MultiInputPolicy", DummyVecEnv([DotGoalEnv, DotGoalEnv]), seed=0)
    agent.learn(total_timesteps=80)
    assert agent.ep_info_buffer is not None and len(agent.ep_info_buffer) == 4
    assert all(info["l"] == 20 and info["r"] < 0 for info in agent.ep_info_buffer)


def test_tensorboard_run_folder_is_named_random(tmp_path) -> None:
    agent = RandomAgent("MultiInputPolicy", DotGoalEnv(), seed=0, tensorboard_log=str(tmp_path))
    agent.learn(total_timesteps=40)
    agent.learn(total_timesteps=40)
    assert sorted(os.listdir(tmp_path)) == ["Random_1", "Random_2"]


def test_visited_states_cover_resets_steps_and_terminal_observations() -> None:
    agent = RandomAgent("MultiInputPolicy", make_dot_vec_env(1), seed=0)
    agent.learn(total_timesteps=100)
    visited = agent.visited_states
    # 1 first reset + 100 steps + 5 real last observations of the 5 finished 20-step episodes
    assert visited.shape == (106, 2)
    assert np.all(np.abs(visited) <= 1.0)
    assert agent.visited_timesteps.shape == (106,)
    assert agent.visited_timesteps[0] == 0 and agent.visited_timesteps[-1] == 100
    agent.learn(total_timesteps=10)  # reset_num_timesteps=True starts a new record
    assert agent.visited_states.shape == (11, 2)
    agent.learn(total_timesteps=10, reset_num_timesteps=False)  # continues the episode: 10 steps + 1 last obs at t=20
    assert agent.visited_states.shape == (22, 2)


def test_occupancy_counts_cells_and_grows_with_time() -> None:
    states = np.array([[0.05, 0.05], [0.06, 0.07], [0.95, -0.95], [1.0, 1.0], [1.5, 0.0], [-1.0, -1.0]])
    # [-1, 1]^2 in 10 x 10 cells: the first two share a cell, (1, 1) lands in the last cell, (1.5, 0) is outside.
    assert count_occupied_cells(states, 10, -1.0, 1.0) == 4
    assert count_occupied_cells(states, (1, 1), -1.0, 1.0) == 1
    assert count_occupied_cells(states[:0], 10, -1.0, 1.0) == 0
    with pytest.raises(ValueError, match="bins"):
        count_occupied_cells(states, 0, -1.0, 1.0)
    with pytest.raises(ValueError, match="high must exceed low"):
        count_occupied_cells(states, 10, 1.0, -1.0)

    agent = RandomAgent("MultiInputPolicy", make_dot_vec_env(2), seed=0)
    agent.learn(total_timesteps=400)
    curve = [agent.occupancy(20, -1.0, 1.0, until_timestep=t) for t in (0, 50, 200, 400)]
    assert curve[0] == 2  # the two first observations
    assert curve == sorted(curve) and curve[-1] > curve[1]
    assert agent.occupancy(20, -1.0, 1.0) == curve[-1]
    assert agent.occupancy(20, -1.0, 1.0) == count_occupied_cells(agent.visited_states, 20, -1.0, 1.0)


def test_seeded_runs_are_reproducible() -> None:
    def run(seed: int) -> np.ndarray:
        agent = RandomAgent("MultiInputPolicy", make_dot_vec_env(2, seed=seed), seed=seed)
        agent.learn(total_timesteps=100)
        return agent.visited_states

    np.testing.assert_array_equal(run(3), run(3))
    assert not np.array_equal(run(3), run(4))


def test_predict_shapes_bounds_and_determinism() -> None:
    env = DotGoalEnv()
    agent = RandomAgent("MultiInputPolicy", env, seed=0)
    obs, _ = env.reset(seed=0)
    action, state = agent.predict(obs)
    assert action.shape == (2,) and state is None
    batch = {key: np.stack([value, value + 0.1]) for key, value in obs.items()}
    actions, _ = agent.predict(batch, deterministic=True)
    assert actions.shape == (2, 2) and np.all(np.abs(actions) <= 1.0)
    # deterministic: a function of the observation (same obs -> same action, different obs -> different action)
    np.testing.assert_array_equal(agent.predict(obs, deterministic=True)[0], actions[0])
    assert not np.array_equal(actions[0], actions[1])
    stochastic = np.stack([agent.predict(obs)[0] for _ in range(20)])
    assert len(np.unique(stochastic[:, 0])) == 20
    assert np.all(stochastic >= -1.0) and np.all(stochastic <= 1.0)
    assert abs(stochastic.mean()) < 0.5


def test_discrete_actions() -> None:
    policy = RandomPolicy(spaces.Box(-1, 1, (3,)), spaces.Discrete(5, start=2), seed=0)
    draws = policy.sample_actions(500)
    assert set(np.unique(draws)) == {2, 3, 4, 5, 6}


def test_env_sampler_is_used_when_present_and_enabled() -> None:
    vec_env = make_dot_vec_env(1, env_class=SamplerDotGoalEnv)
    agent = RandomAgent("MultiInputPolicy", vec_env, seed=0)
    agent.learn(total_timesteps=40)
    assert sum(vec_env.get_attr("sampler_calls")) == 40
    # Rows 0..20: first obs, 19 steps, real last obs. The sampler pushes right by 0.1 (or sits at the wall): x never
    # decreases and y never changes within the episode.
    first_episode = agent.visited_states[:21]
    assert np.all(np.diff(first_episode[:, 0]) >= 0) and np.ptp(first_episode[:, 1]) == 0

    vec_env = make_dot_vec_env(2, env_class=SamplerDotGoalEnv)
    agent = RandomAgent("MultiInputPolicy", vec_env, seed=0, use_env_sampler=False)
    agent.learn(total_timesteps=40)
    assert sum(vec_env.get_attr("sampler_calls")) == 0


def test_save_load_round_trip(tmp_path) -> None:
    agent = RandomAgent("MultiInputPolicy", make_dot_vec_env(2), seed=7, use_env_sampler=False)
    agent.learn(total_timesteps=40)
    obs = agent.get_env().reset()
    path = tmp_path / "random.zip"
    agent.save(path)
    loaded = RandomAgent.load(path, env=make_dot_vec_env(2))
    assert loaded.seed == 7 and loaded.use_env_sampler is False and loaded.num_timesteps == 40
    np.testing.assert_array_equal(loaded.predict(obs, deterministic=True)[0], agent.predict(obs, deterministic=True)[0])
    loaded.learn(total_timesteps=20)
    assert loaded.num_timesteps == 20
    # Loading without an env is enough to predict.
    assert RandomAgent.load(path).predict(obs, deterministic=True)[0].shape == (2, 2)


def test_set_env_checks_spaces_and_n_envs() -> None:
    agent = RandomAgent("MultiInputPolicy", make_dot_vec_env(2), seed=0)
    agent.set_env(make_dot_vec_env(2, seed=5))
    agent.learn(total_timesteps=20)
    assert agent.num_timesteps == 20
    with pytest.raises(AssertionError, match="number of environments"):
        agent.set_env(make_dot_vec_env(3))


def test_mlp_policy_on_dict_observations_is_rejected() -> None:
    with pytest.raises(ValueError, match="MultiInputPolicy"):
        RandomAgent("MlpPolicy", DotGoalEnv())


def test_box_observations_record_the_whole_observation() -> None:
    agent = RandomAgent("MlpPolicy", "Pendulum-v1", seed=0)
    agent.learn(total_timesteps=10)
    assert agent.visited_states.shape == (11, 3)


def test_eval_callback_writes_evaluations(tmp_path) -> None:
    agent = RandomAgent("MultiInputPolicy", make_dot_vec_env(2), seed=0)
    callback = EvalCallback(make_dot_vec_env(1, seed=100), n_eval_episodes=2, eval_freq=20, log_path=str(tmp_path), verbose=0)
    agent.learn(total_timesteps=80, callback=callback)
    data = np.load(tmp_path / "evaluations.npz")
    assert list(data["timesteps"]) == [40, 80]
    assert data["results"].shape == (2, 2)


def _make_or_skip(env_id: str) -> gym.Env:
    try:
        return gym.make(env_id)
    except (ImportError, AttributeError) as error:
        pytest.skip(f"{env_id} is not available yet: {error}")


@pytest.mark.parametrize("env_id", EBM_ENV_IDS)
def test_evaluate_policy_on_ebm_envs(env_id: str) -> None:
    env = _make_or_skip(env_id)
    agent = RandomAgent("MultiInputPolicy", env, seed=0)
    agent.learn(total_timesteps=100)
    assert agent.num_timesteps == 100
    assert agent.visited_states.shape[1] == env.observation_space["achieved_goal"].shape[0]
    eval_env = Monitor(gym.make(env_id, max_episode_steps=50))  # short episodes keep the 1000-step envs fast
    rewards, lengths = evaluate_policy(agent, eval_env, n_eval_episodes=2, return_episode_rewards=True)
    assert len(rewards) == 2 and all(np.isfinite(rewards)) and all(length >= 1 for length in lengths)
