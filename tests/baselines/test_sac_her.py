"""Tests of the SAC + HER factory: the table, overrides, exact budgets, the envs' relabelling rewards, the registry."""

from __future__ import annotations

import json
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch.nn as nn
from stable_baselines3 import SAC, HerReplayBuffer
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.utils import LinearSchedule

import envs
from baselines import sac_her
from baselines.random_agent import RandomAgent
from baselines.sac_her import (
    SAC_HER_HYPERPARAMS,
    VALID_HYPERPARAMS,
    VALID_REPLAY_BUFFER_KWARGS,
    make_sac_her,
    off_policy_budget_callback,
    sac_her_hyperparams,
)
from eval.provenance import agent_defaults_digest
from eval.registry import AGENTS

EBM_ENV_IDS = sorted(envs.ENV_IDS.values())
# Tiny settings so a test trains a few hundred steps in about a second on one thread (particle episodes <= 100 steps).
SMALL: dict[str, Any] = {
    "buffer_size": 10_000,
    "learning_starts": 100,
    "batch_size": 32,
    "policy_kwargs": {"net_arch": [16, 16]},
}


# ---------------------------------------------------------------------------------------------------- the table
@pytest.mark.parametrize("env_id", EBM_ENV_IDS)
def test_table_entries_are_valid_exact_and_start_after_an_episode(env_id: str) -> None:
    params = sac_her_hyperparams(env_id)
    assert set(params) <= VALID_HYPERPARAMS
    assert set(params["replay_buffer_kwargs"]) <= VALID_REPLAY_BUFFER_KWARGS
    assert params["replay_buffer_kwargs"] == {"n_sampled_goal": 4, "goal_selection_strategy": "future"}
    # 1 env and a gradient step per transition: SB3 stops at exactly the budget by itself.
    assert params["n_envs"] == 1 and params["train_freq"] == 1 and params["gradient_steps"] == 1
    # HerReplayBuffer samples only finished episodes.
    assert params["learning_starts"] >= gym.spec(env_id).max_episode_steps
    # Never overwrites a transition of the project's largest budget.
    assert params["buffer_size"] >= 500_000


def test_lookup_by_short_name_merges_nested_kwargs_and_returns_a_copy() -> None:
    assert sac_her_hyperparams("maze") == sac_her_hyperparams("ebm/Maze-v0")
    assert sac_her_hyperparams("SomethingElse-v0") == sac_her_hyperparams("default")
    maze = sac_her_hyperparams("maze")
    assert maze["gamma"] == SAC_HER_HYPERPARAMS["ebm/Maze-v0"]["gamma"]
    assert maze["batch_size"] == SAC_HER_HYPERPARAMS["default"]["batch_size"]  # left out of the entry
    # An entry changing one policy kwarg keeps the others; the HER settings come from default.
    sawyer = sac_her_hyperparams("sawyer")
    assert sawyer["policy_kwargs"]["log_std_init"] == -2.0 and sawyer["policy_kwargs"]["net_arch"] == [256, 256]
    assert sawyer["replay_buffer_kwargs"] == SAC_HER_HYPERPARAMS["default"]["replay_buffer_kwargs"]
    params = sac_her_hyperparams("particle")
    params["policy_kwargs"]["net_arch"].append(999)
    params["replay_buffer_kwargs"]["n_sampled_goal"] = 0
    assert 999 not in sac_her_hyperparams("particle")["policy_kwargs"]["net_arch"]
    assert sac_her_hyperparams("particle")["replay_buffer_kwargs"]["n_sampled_goal"] == 4


# ---------------------------------------------------------------------------------------------- make_sac_her
def test_make_sac_her_builds_sac_with_her_and_the_table_settings() -> None:
    model = make_sac_her("particle", seed=0, device="cpu", buffer_size=10_000)  # the table's 500k takes seconds
    table = sac_her_hyperparams("particle")
    assert isinstance(model, SAC) and isinstance(model.replay_buffer, HerReplayBuffer)
    assert model.replay_buffer.n_sampled_goal == 4 and model.replay_buffer.goal_selection_strategy.name == "FUTURE"
    assert model.n_envs == 1 and model.gamma == table["gamma"] and model.learning_starts == table["learning_starts"]
    assert model.learning_rate == table["learning_rate"] and model.buffer_size == 10_000
    assert model.policy.actor.latent_pi[0].out_features == table["policy_kwargs"]["net_arch"][0]


def test_overrides_replace_table_entries() -> None:
    model = make_sac_her(
        "particle",
        seed=0,
        device="cpu",
        buffer_size=10_000,
        gamma=0.5,
        learning_rate="lin_1e-3",
        train_freq=[2, "step"],
        replay_buffer_kwargs={"n_sampled_goal": 2, "goal_selection_strategy": "final"},
        policy_kwargs={"net_arch": [8], "activation_fn": "tanh"},
    )
    assert model.gamma == 0.5 and model.train_freq.frequency == 2
    assert isinstance(model.learning_rate, LinearSchedule) and model.lr_schedule(0.5) == pytest.approx(5e-4)
    assert model.replay_buffer.n_sampled_goal == 2 and model.replay_buffer.goal_selection_strategy.name == "FINAL"
    assert isinstance(model.policy.actor.latent_pi[1], nn.Tanh)


def test_bad_keys_are_clear_errors(monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(TypeError, match=r"unknown hyperparameter\(s\) \['learning_strats'\].*'learning_starts'"):
        make_sac_her("particle", learning_strats=100)
    with pytest.raises(TypeError, match=r"unknown hyperparameter\(s\) \['replay_buffer_class'\]"):
        make_sac_her("particle", replay_buffer_class=HerReplayBuffer)
    with pytest.raises(TypeError, match=r"unknown replay_buffer_kwargs \['n_sampled_goals'\].*'n_sampled_goal'"):
        make_sac_her("particle", replay_buffer_kwargs={"n_sampled_goals": 4})
    monkeypatch.setitem(SAC_HER_HYPERPARAMS, "ebm/Particle-v0", {"gama": 0.9})
    with pytest.raises(ValueError, match=r"sac_her.yaml entry 'ebm/Particle-v0' got unknown hyperparameter\(s\) \['gama'\]"):
        sac_her_hyperparams("particle")


def test_non_goal_envs_and_too_early_learning_starts_are_value_errors() -> None:
    with pytest.raises(ValueError, match="goal env"):
        make_sac_her("Pendulum-v1")
    with pytest.raises(ValueError, match=r"learning_starts=100 transitions over 1 env\(s\) is shorter than an episode"):
        make_sac_her("maze", learning_starts=100)
    with pytest.raises(ValueError, match=r"Set learning_starts >= 200"):
        make_sac_her("particle", n_envs=2, learning_starts=100)
    with pytest.raises(ValueError, match="env_kwargs"):
        make_sac_her(gym.make("ebm/Particle-v0"), env_kwargs={"goal": (0.0, 0.0)})


def test_given_env_is_used_as_is() -> None:
    vec_env = make_vec_env("ebm/Particle-v0", n_envs=1, seed=0)
    model = make_sac_her(vec_env, seed=0, device="cpu", **SMALL)
    assert model.get_env() is vec_env and model.gamma == sac_her_hyperparams("particle")["gamma"]


# ------------------------------------------------------------------------------------------- exact budgets
@pytest.mark.parametrize(
    ("n_envs", "train_freq", "budget", "with_callback", "expected"),
    [
        (1, 1, 300, False, 300),  # the table's setting: exact by itself
        (1, 1, 300, True, 300),
        (1, 4, 302, False, 304),  # SB3 alone runs on to the end of its train step
        (1, 4, 302, True, 302),
        (2, 1, 301, True, 302),  # a budget not a multiple of n_envs: fewer than n_envs more
    ],
)
def test_budget_is_exact(n_envs: int, train_freq: int, budget: int, with_callback: bool, expected: int) -> None:
    settings = {**SMALL, "learning_starts": SMALL["learning_starts"] * n_envs}
    model = make_sac_her("particle", seed=0, device="cpu", n_envs=n_envs, train_freq=train_freq, **settings)
    model.learn(budget, callback=off_policy_budget_callback(budget) if with_callback else None)
    assert model.num_timesteps == expected
    if n_envs == 1 and train_freq == 1:
        # The transition at the budget is stored and trained on too (the callback let SB3's loop stop there).
        assert model.replay_buffer.size() == budget
        assert model._n_updates == budget - SMALL["learning_starts"]


# ------------------------------------------------------------------ the envs' rewards, as HER recomputes them
@pytest.mark.parametrize("env_id", EBM_ENV_IDS)
def test_compute_reward_reproduces_step_rewards_batched_and_single(env_id: str) -> None:
    """HER calls ``env_method("compute_reward", next achieved_goal, desired_goal, infos)`` on the wrapped VecEnv."""
    vec_env = make_vec_env(env_id, n_envs=1, seed=0)
    vec_env.action_space.seed(0)
    obs = vec_env.reset()
    achieved, desired, rewards, infos = [], [], [], []
    for _ in range(30):
        obs, reward, done, info = vec_env.step(np.array([vec_env.action_space.sample()]))
        next_obs = info[0]["terminal_observation"] if done[0] else {key: value[0] for key, value in obs.items()}
        achieved.append(next_obs["achieved_goal"])
        desired.append(next_obs["desired_goal"])
        rewards.append(reward[0])
        infos.append(info[0])
    rewards_array = np.array(rewards, dtype=np.float32)  # VecEnv rewards are float32
    batched = vec_env.env_method("compute_reward", np.stack(achieved), np.stack(desired), infos, indices=[0])[0]
    assert np.shape(batched) == (len(rewards),)
    np.testing.assert_allclose(batched, rewards_array, rtol=1e-6, atol=1e-6)
    single = vec_env.env_method("compute_reward", achieved[3], desired[3], infos[3], indices=[0])[0]
    assert np.shape(single) == () and float(single) == pytest.approx(rewards[3], rel=1e-6, abs=1e-6)
    # A relabelled goal: the reward of reaching it exactly is the best reward, 0.
    relabelled = vec_env.env_method("compute_reward", np.stack(achieved), np.stack(achieved), infos, indices=[0])[0]
    np.testing.assert_allclose(relabelled, 0.0, atol=1e-12)
    vec_env.close()


# ---------------------------------------------------------------------------------------------- the registry
def test_registry_entry_builds_and_learns_a_few_hundred_steps_exactly(tmp_path) -> None:
    spec = AGENTS["sac-her"]
    assert spec.description == "SB3 SAC + HER replay (goal relabelling)" and spec.callbacks is not None
    model = spec.factory(
        env_id="ebm/Particle-v0",
        env_kwargs={},
        seed=0,
        tensorboard_log=str(tmp_path),
        device="cpu",
        hyperparams=dict(SMALL),
        verbose=0,
    )
    assert isinstance(model, SAC) and isinstance(model.replay_buffer, HerReplayBuffer)
    model.learn(300, callback=spec.callbacks(300), tb_log_name=spec.tb_log_name)
    assert model.num_timesteps == 300
    assert (tmp_path / f"{spec.tb_log_name}_1").is_dir()
    rewards, _ = evaluate_policy(model, model.get_env(), n_eval_episodes=2, return_episode_rewards=True)
    assert np.all(np.isfinite(rewards))


def test_registry_defaults_are_json_and_digested() -> None:
    assert AGENTS["sac-her"].defaults is not None
    settings = AGENTS["sac-her"].defaults("ebm/Maze-v0", "")
    assert settings["table"] == sac_her_hyperparams("maze") and settings["HerReplayBuffer"]["n_sampled_goal"] == 4
    json.dumps(settings)
    digest = agent_defaults_digest("sac-her", "ebm/Maze-v0")
    assert digest is not None and digest != agent_defaults_digest("sac-her", "ebm/Particle-v0")


def test_table_file_is_the_module_data() -> None:
    assert sac_her.SAC_HER_HYPERPARAMS_FILE.name == "sac_her.yaml" and "default" in SAC_HER_HYPERPARAMS


# ------------------------------------------------------------------------------------------------ learning
@pytest.mark.slow
def test_sac_her_beats_random_on_particle() -> None:
    """SAC + HER learns the particle reach at a modest budget (numbers in docs/baselines.md)."""
    budget = 10_000
    model = make_sac_her("particle", seed=0, device="cpu")
    model.learn(budget, callback=off_policy_budget_callback(budget))
    assert model.num_timesteps == budget
    eval_env = Monitor(gym.make("ebm/Particle-v0", start=(0.0, 0.0)))
    eval_env.reset(seed=1000)
    score, _ = evaluate_policy(model, eval_env, n_eval_episodes=10, deterministic=True)
    random_score, _ = evaluate_policy(RandomAgent("MultiInputPolicy", eval_env, seed=0), eval_env, n_eval_episodes=10)
    # From (0, 0) to (0.5, 0.5): optimum -4.5; standing still -100; random about -100.
    assert random_score < -50
    assert score > -15, f"SAC + HER scored {score:.1f} (random {random_score:.1f})"
