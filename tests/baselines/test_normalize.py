"""Tests of the tables' ``normalize`` (rl-zoo3's key): parsing, the training env it wraps, the evaluation env that
shares its statistics, and the third-party entries that set it."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize

import envs
from baselines.hyperparams import normalize_kwargs, normalized, normalized_like
from baselines.ppo import make_ppo
from baselines.sac_her import VALID_HYPERPARAMS, VALID_REPLAY_BUFFER_KWARGS, make_sac_her, sac_her_hyperparams

THIRD_PARTY_IDS = sorted(envs.THIRD_PARTY_ENV_IDS.values())
SMALL: dict[str, Any] = {"buffer_size": 5_000, "batch_size": 32, "policy_kwargs": {"net_arch": [16, 16]}}


# ------------------------------------------------------------------------------------------------ parsing
def test_normalize_setting_reads_like_rl_zoo3() -> None:
    assert normalize_kwargs(False) is None and normalize_kwargs(None) is None
    # true: VecNormalize's defaults, the reward normaliser discounting with the algorithm's gamma.
    assert normalize_kwargs(True, gamma=0.95) == {"gamma": 0.95}
    assert normalize_kwargs({"norm_reward": False}, gamma=0.95) == {"norm_reward": False, "gamma": 0.95}
    assert normalize_kwargs({"gamma": 0.9}, gamma=0.95) == {"gamma": 0.9}


@pytest.mark.parametrize("bad", ["yes", 1.0, ["norm_obs"]])
def test_a_normalize_value_of_another_type_is_refused_with_the_forms_it_takes(bad: Any) -> None:
    with pytest.raises(ValueError, match="true, false or a dict of VecNormalize arguments"):
        normalize_kwargs(bad)


def test_an_unknown_vec_normalize_argument_is_refused_by_name() -> None:
    with pytest.raises(ValueError, match=r"unknown VecNormalize argument\(s\) \['norm_observations'\]"):
        normalize_kwargs({"norm_observations": True})


# ------------------------------------------------------------------------------------------ the third-party table
@pytest.mark.parametrize("env_id", THIRD_PARTY_IDS)
def test_third_party_entries_are_valid_exact_and_start_after_an_episode(env_id: str) -> None:
    params = sac_her_hyperparams(env_id)
    assert set(params) <= VALID_HYPERPARAMS
    assert set(params["replay_buffer_kwargs"]) <= VALID_REPLAY_BUFFER_KWARGS
    assert params["n_envs"] == 1 and params["train_freq"] == 1 and params["gradient_steps"] == 1
    assert params["learning_starts"] >= gym.spec(env_id).max_episode_steps


def test_fetch_entries_normalise_observations_and_keep_rewards_raw() -> None:
    for env_id in ("FetchReach-v4", "FetchPush-v4"):
        assert sac_her_hyperparams(env_id)["normalize"] == {"norm_obs": True, "norm_reward": False}
    assert "normalize" not in sac_her_hyperparams("particle")  # the project's own envs: raw O(1) observations


# ------------------------------------------------------------------------------------------- training and evaluation
def test_make_sac_her_trains_on_normalised_observations_and_the_evaluation_env_shares_them() -> None:
    model = make_sac_her("fetch-reach", seed=0, learning_starts=50, **SMALL)
    normalizer = model.get_vec_normalize_env()
    assert isinstance(normalizer, VecNormalize) and normalizer.training
    assert normalizer.norm_obs and not normalizer.norm_reward
    model.learn(120)
    assert normalizer.obs_rms["observation"].count > 100  # the statistics learned from the 120 steps

    raw = make_vec_env("FetchReach-v4", n_envs=1, seed=7)
    evaluation = normalized_like(model, raw)
    assert isinstance(evaluation, VecNormalize) and not evaluation.training and not evaluation.norm_reward
    assert evaluation.obs_rms is normalizer.obs_rms  # shared: evaluations during training see the current ones
    seen = evaluation.reset()
    unwrapped = make_vec_env("FetchReach-v4", n_envs=1, seed=7).reset()
    expected = normalizer.normalize_obs(unwrapped)
    for key in ("observation", "achieved_goal", "desired_goal"):
        np.testing.assert_allclose(seen[key], expected[key], rtol=1e-6)
        assert not np.allclose(seen[key], unwrapped[key])  # it does change what the policy sees
    evaluation.close()


def test_models_without_normalisation_evaluate_on_the_env_as_it_is() -> None:
    model = make_sac_her("particle", seed=0, learning_starts=100, **SMALL)
    env = make_vec_env("ebm/Particle-v0", n_envs=1, seed=0)
    assert model.get_vec_normalize_env() is None and normalized_like(model, env) is env
    env.close()


def test_ppo_takes_the_same_setting() -> None:
    model = make_ppo("particle", seed=0, n_envs=1, n_steps=64, batch_size=32, normalize={"norm_reward": False})
    assert isinstance(model.get_vec_normalize_env(), VecNormalize)
    with pytest.raises(ValueError, match="normalize"):
        make_ppo("particle", seed=0, normalize="obs")


def test_normalized_wraps_a_plain_env() -> None:
    wrapped = normalized(gym.make("ebm/Particle-v0"), {"norm_reward": False})
    assert isinstance(wrapped, VecNormalize) and wrapped.num_envs == 1
    assert normalized(wrapped, None) is wrapped
    wrapped.close()
