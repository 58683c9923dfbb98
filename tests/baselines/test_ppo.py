"""Tests of the PPO factory: the hyperparameter table, overrides, exact budgets, and evaluation on every env."""

from __future__ import annotations

import warnings

import gymnasium as gym
import gymnasium_robotics
import numpy as np
import pytest
import torch.nn as nn
from stable_baselines3 import PPO
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.policies import ActorCriticPolicy, MultiInputActorCriticPolicy
from stable_baselines3.common.utils import LinearSchedule

import envs  # noqa: F401  (registers the ebm/ ids)
from baselines.hyperparams import PPO_HYPERPARAMS
from baselines.ppo import VALID_HYPERPARAMS, ExactBudgetCallback, exact_budget_callback, make_ppo, ppo_hyperparams
from baselines.random_agent import RandomAgent

gym.register_envs(gymnasium_robotics)

EBM_ENV_IDS = ["ebm/Particle-v0", "ebm/Maze-v0", "ebm/Reacher-v0", "ebm/SawyerReach-v0"]
STAND_IN_ID = "PointMaze_UMaze-v3"  # a Dict-observation goal env that builds in milliseconds
SMALL = {"n_steps": 16, "batch_size": 16, "n_epochs": 2}  # tiny rollouts so a test learns in well under a second


def stand_in_env(max_episode_steps: int = 50) -> gym.Env:
    return gym.make(STAND_IN_ID, max_episode_steps=max_episode_steps)


# ---------------------------------------------------------------------------------------------------- the table
@pytest.mark.parametrize("env_id", EBM_ENV_IDS)
def test_table_entries_are_complete_and_budget_aligned(env_id: str) -> None:
    params = ppo_hyperparams(env_id)
    assert set(params) <= VALID_HYPERPARAMS
    required = {"n_envs", "n_steps", "batch_size", "gamma", "gae_lambda", "learning_rate", "ent_coef", "clip_range"}
    assert required <= set(params)
    rollout = params["n_envs"] * params["n_steps"]
    # Rollout boundaries fall on the project's budgets, and minibatches split a rollout evenly.
    assert 10_000 % rollout == 0 and 50_000 % rollout == 0
    assert rollout % params["batch_size"] == 0
    assert {"net_arch", "activation_fn", "log_std_init", "ortho_init"} <= set(params["policy_kwargs"])


def test_every_table_key_is_a_valid_hyperparameter() -> None:
    for entry in PPO_HYPERPARAMS.values():
        assert set(entry) <= VALID_HYPERPARAMS


def test_lookup_by_short_name_and_default_fallback() -> None:
    assert ppo_hyperparams("reacher") == ppo_hyperparams("ebm/Reacher-v0")
    assert ppo_hyperparams("reacher")["gamma"] == PPO_HYPERPARAMS["ebm/Reacher-v0"]["gamma"]
    assert ppo_hyperparams("SomethingElse-v0") == ppo_hyperparams("default")
    # An entry overriding one policy kwarg keeps the others from default.
    sawyer = ppo_hyperparams("sawyer")["policy_kwargs"]
    assert sawyer["log_std_init"] == PPO_HYPERPARAMS["ebm/SawyerReach-v0"]["policy_kwargs"]["log_std_init"]
    # The result is a copy: editing it leaves the table alone.
    params = ppo_hyperparams("particle")
    params["policy_kwargs"]["net_arch"]["pi"].append(999)
    params["gamma"] = 0.0
    assert 999 not in ppo_hyperparams("particle")["policy_kwargs"]["net_arch"]["pi"]
    assert ppo_hyperparams("particle")["gamma"] > 0


# ------------------------------------------------------------------------------------------------- make_ppo
def test_make_ppo_by_id_builds_the_table_n_envs_and_settings() -> None:
    model = make_ppo(STAND_IN_ID, seed=0)
    default = ppo_hyperparams("default")
    assert isinstance(model, PPO)
    assert model.n_envs == default["n_envs"]
    assert model.n_steps == default["n_steps"] and model.batch_size == default["batch_size"]
    assert model.gamma == default["gamma"] and model.gae_lambda == default["gae_lambda"]
    assert isinstance(model.policy, MultiInputActorCriticPolicy)
    assert isinstance(model.policy.mlp_extractor.policy_net[1], nn.Tanh)


def test_make_ppo_uses_mlp_policy_for_box_observations() -> None:
    model = make_ppo("Pendulum-v1", seed=0, n_envs=1, batch_size=50)
    assert type(model.policy) is ActorCriticPolicy


def test_overrides_replace_table_entries() -> None:
    model = make_ppo(
        STAND_IN_ID,
        seed=0,
        n_envs=2,
        n_steps=32,
        batch_size=64,
        gamma=0.5,
        learning_rate="lin_1e-3",
        policy_kwargs={"net_arch": [8], "activation_fn": "relu", "log_std_init": -2.0},
    )
    assert model.n_envs == 2 and model.n_steps == 32 and model.gamma == 0.5
    assert isinstance(model.learning_rate, LinearSchedule)
    assert model.lr_schedule(1.0) == pytest.approx(1e-3) and model.lr_schedule(0.5) == pytest.approx(5e-4)
    assert isinstance(model.policy.mlp_extractor.policy_net[1], nn.ReLU)
    assert model.policy.log_std.detach().numpy() == pytest.approx([-2.0, -2.0])


def test_unknown_override_is_a_type_error_listing_valid_keys() -> None:
    with pytest.raises(TypeError, match=r"unknown hyperparameter\(s\) \['n_stpes'\].*valid keys are .*'n_steps'"):
        make_ppo(STAND_IN_ID, n_stpes=128)


def test_bad_schedule_string_and_activation_are_value_errors() -> None:
    with pytest.raises(ValueError, match="lin_3e-4"):
        make_ppo(STAND_IN_ID, learning_rate="cosine_1e-3")
    with pytest.raises(ValueError, match="activation_fn"):
        make_ppo(STAND_IN_ID, policy_kwargs={"activation_fn": "sigmoidal"})


def test_given_env_is_used_as_is_with_a_warning_on_n_envs_mismatch() -> None:
    env = stand_in_env()
    with pytest.warns(UserWarning, match="n_envs=4"):
        model = make_ppo(env, seed=0, batch_size=50)
    assert model.n_envs == 1
    vec_env = make_vec_env(STAND_IN_ID, n_envs=ppo_hyperparams("default")["n_envs"], seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # matches the table: no warning
        model = make_ppo(vec_env, seed=0)
    assert model.get_env() is vec_env
    with pytest.raises(ValueError, match="env_kwargs"):
        make_ppo(env, env_kwargs={"continuing_task": False})


def test_env_kwargs_reach_the_env_constructor() -> None:
    model = make_ppo(STAND_IN_ID, seed=0, n_envs=1, batch_size=50, env_kwargs={"max_episode_steps": 7})
    assert model.get_env().get_attr("spec")[0].max_episode_steps == 7


# ------------------------------------------------------------------------------------------- exact budgets
@pytest.mark.parametrize(("n_envs", "budget"), [(1, 50), (4, 200), (4, 128)])
def test_exact_budget_callback_stops_at_exactly_the_budget(n_envs: int, budget: int) -> None:
    model = make_ppo(STAND_IN_ID, seed=0, n_envs=n_envs, **SMALL)
    rollout = n_envs * SMALL["n_steps"]
    model.learn(budget, callback=exact_budget_callback(budget))
    assert model.num_timesteps == budget
    # Full rollouts are all trained on, the one that ends exactly on the budget included.
    assert model._n_updates == (budget // rollout) * SMALL["n_epochs"]


def test_without_the_callback_sb3_overshoots_to_a_rollout_boundary() -> None:
    model = make_ppo(STAND_IN_ID, seed=0, n_envs=4, **SMALL)
    model.learn(200)
    assert model.num_timesteps == 256


def test_budget_not_multiple_of_n_envs_overshoots_by_less_than_n_envs() -> None:
    model = make_ppo(STAND_IN_ID, seed=0, n_envs=4, **SMALL)
    model.learn(202, callback=exact_budget_callback(202))
    assert model.num_timesteps == 204


def test_exact_budget_callback_rejects_bad_budgets() -> None:
    for bad in (0, -5, 2.5, True):
        with pytest.raises(ValueError, match="positive int"):
            ExactBudgetCallback(bad)  # type: ignore[arg-type]
    assert ExactBudgetCallback(np.int64(64)).total_timesteps == 64


# ------------------------------------------------------------------------------------------- the ebm envs
def _make_or_skip(env_id: str) -> gym.Env:
    try:
        return Monitor(gym.make(env_id, max_episode_steps=50))  # short episodes keep the 1000-step envs fast
    except (ImportError, AttributeError) as error:
        pytest.skip(f"{env_id} is not available yet: {error}")


@pytest.mark.parametrize("env_id", EBM_ENV_IDS)
def test_evaluate_policy_on_ebm_envs(env_id: str) -> None:
    eval_env = _make_or_skip(env_id)
    model = make_ppo(env_id, seed=0, n_steps=16, batch_size=64, n_epochs=1)
    assert isinstance(model.policy, MultiInputActorCriticPolicy)
    assert model.n_envs == ppo_hyperparams(env_id)["n_envs"]
    model.learn(64, callback=exact_budget_callback(64))
    assert model.num_timesteps == 64
    for agent in (model, RandomAgent("MultiInputPolicy", eval_env, seed=0)):
        rewards, lengths = evaluate_policy(agent, eval_env, n_eval_episodes=2, return_episode_rewards=True)
        assert len(rewards) == 2 and np.all(np.isfinite(rewards)) and min(lengths) >= 1


# ------------------------------------------------------------------------------------------------ learning
@pytest.mark.slow
def test_ppo_beats_random_on_particle_at_50k() -> None:
    """The tuned PPO learns the particle task in the paper's online budget (numbers in docs/baselines.md)."""
    budget = 50_000
    model = make_ppo("particle", seed=0)
    model.learn(budget, callback=exact_budget_callback(budget))
    assert model.num_timesteps == budget
    eval_env = Monitor(gym.make("ebm/Particle-v0", start=(0.0, 0.0)))
    eval_env.reset(seed=1000)
    ppo_score, _ = evaluate_policy(model, eval_env, n_eval_episodes=10, deterministic=True)
    random_score, _ = evaluate_policy(RandomAgent("MultiInputPolicy", eval_env, seed=0), eval_env, n_eval_episodes=10)
    # From (0, 0) to (0.5, 0.5): optimum -4.5; standing still -100; random about -100.
    assert random_score < -50
    assert ppo_score > -15, f"PPO scored {ppo_score:.1f} (random {random_score:.1f})"
