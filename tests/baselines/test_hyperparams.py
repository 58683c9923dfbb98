"""baselines.hyperparams: the tables shared by PPO and SAC + HER and what turns them into SB3 arguments."""

from __future__ import annotations

import gymnasium as gym
import pytest
import torch.nn as nn

import envs  # noqa: F401  (registers the ids)
from baselines.hyperparams import load_table, policy_kwargs, schedule, table_entry, training_env


def test_an_entry_merges_over_default_and_its_nested_dicts_key_by_key():
    table = {
        "default": {"gamma": 0.99, "policy_kwargs": {"net_arch": [64], "log_std_init": 0.0}, "other": {"a": 1}},
        "ebm/Particle-v0": {"gamma": 0.9, "policy_kwargs": {"log_std_init": -1.0}, "other": {"b": 2}},
    }
    entry = table_entry(table, "particle")
    assert entry["gamma"] == 0.9 and entry["policy_kwargs"] == {"net_arch": [64], "log_std_init": -1.0}
    assert entry["other"] == {"b": 2}  # not nested: replaced whole
    assert table_entry(table, "particle", nested=("policy_kwargs", "other"))["other"] == {"a": 1, "b": 2}
    entry["policy_kwargs"]["net_arch"].append(1)
    assert table["default"]["policy_kwargs"]["net_arch"] == [64]  # a fresh copy
    assert table_entry(table, "SomethingElse-v0")["gamma"] == 0.99
    assert set(load_table("sac_her")) >= {"default"} and "ebm/Maze-v0" in load_table("ppo")


def test_plain_data_becomes_sb3_arguments_with_clear_errors():
    assert schedule("learning_rate", "lin_1e-3")(1.0) == pytest.approx(1e-3)
    with pytest.raises(ValueError, match="lin_3e-4"):
        schedule("learning_rate", "cosine")
    assert policy_kwargs({"activation_fn": "ReLU"})["activation_fn"] is nn.ReLU
    with pytest.raises(ValueError, match="not one of"):
        policy_kwargs({"activation_fn": "swish2"})


def test_the_training_env_is_built_by_name_or_used_as_given():
    assert training_env("particle", 2, 0, None, "x").num_envs == 2
    with pytest.raises(ValueError, match="n_envs must be >= 1"):
        training_env("particle", 0, 0, None, "x")
    env = gym.make("ebm/Particle-v0")
    with pytest.raises(ValueError, match="env_kwargs only applies"):
        training_env(env, 1, 0, {"start": None}, "x")
    with pytest.warns(UserWarning, match="use n_envs=4"):
        assert training_env(env, 4, 0, None, "the tuned settings") is env
