"""Per-environment hyperparameter tables of the SB3 baselines, rl-zoo3 style, and what turns them into SB3 arguments.

Each table is data, ``baselines/<algo>.yaml`` keyed by Gymnasium id with a ``default`` entry (the files' comments
say how each entry was chosen): ``ppo.yaml`` (:mod:`baselines.ppo`) and ``sac_her.yaml`` (:mod:`baselines.sac_her`).
"""

from __future__ import annotations

import copy
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import torch.nn as nn
import yaml
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.utils import LinearSchedule
from stable_baselines3.common.vec_env import VecEnv

from envs import resolve_env_id

TABLE_DIR = Path(__file__).resolve().parent
"""The folder of the tables."""


def load_table(name: str) -> dict[str, dict[str, Any]]:
    """Read a table: ``baselines/<name>.yaml``.

    :param name: ``"ppo"`` or ``"sac_her"``.
    :return: Gymnasium id (or ``"default"``) -> hyperparameters.
    """
    return yaml.safe_load((TABLE_DIR / f"{name}.yaml").read_text())


PPO_HYPERPARAMS_FILE = TABLE_DIR / "ppo.yaml"
"""The PPO table."""

PPO_HYPERPARAMS: dict[str, dict[str, Any]] = load_table("ppo")
"""PPO hyperparameters per Gymnasium id; ``default`` fills in whatever an entry leaves out."""

_ACTIVATIONS: dict[str, type[nn.Module]] = {
    "tanh": nn.Tanh,
    "relu": nn.ReLU,
    "elu": nn.ELU,
    "leaky_relu": nn.LeakyReLU,
    "gelu": nn.GELU,
    "silu": nn.SiLU,
}


def table_entry(table: dict[str, dict[str, Any]], env_id: str, nested: Sequence[str] = ("policy_kwargs",)) -> dict[str, Any]:
    """An env's entry merged over ``default``; the ``nested`` dicts merge key by key, so that an entry can change one
    of their keys (say ``log_std_init``) and keep the rest.

    :param table: a table of :func:`load_table`.
    :param env_id: a registered id (``ebm/Particle-v0``) or a short name (``particle``); an id without an entry gets
        ``default`` alone.
    :param nested: the keys whose dicts merge key by key.
    :return: a fresh dict of plain data (mutating it does not change the table).
    """
    params = copy.deepcopy(table["default"])
    entry = copy.deepcopy(table.get(resolve_env_id(env_id), {}))
    for key in nested:
        params[key] = {**params.get(key, {}), **entry.pop(key, {})}
    params.update(entry)
    return params


def env_id_of(env: str | gym.Env | VecEnv) -> str | None:
    """The Gymnasium id of an env given by name, as an env or as a VecEnv (None when it has no spec)."""
    if isinstance(env, str):
        return resolve_env_id(env)
    spec = (env.get_attr("spec", indices=[0]) or [None])[0] if isinstance(env, VecEnv) else env.spec
    return spec.id if spec is not None else None


def schedule(key: str, value: str) -> LinearSchedule:
    """rl-zoo3's ``"lin_<start>"``: a value that decays linearly from ``start`` to 0 over the whole of ``learn``.

    :raises ValueError: for another string.
    """
    if not value.startswith("lin_"):
        raise ValueError(f"{key}={value!r}: a string schedule must look like 'lin_3e-4' (linear decay to 0).")
    try:
        start = float(value[len("lin_") :])
    except ValueError as error:
        raise ValueError(f"{key}={value!r}: cannot read the number after 'lin_'.") from error
    return LinearSchedule(start=start, end=0.0, end_fraction=1.0)


def policy_kwargs(settings: dict[str, Any]) -> dict[str, Any]:
    """The table's ``policy_kwargs`` with ``activation_fn`` given by name (``"tanh"``) turned into its ``torch.nn``
    class.

    :raises ValueError: for an unknown activation name.
    """
    settings = dict(settings)
    activation = settings.get("activation_fn")
    if isinstance(activation, str):
        if activation.lower() not in _ACTIVATIONS:
            raise ValueError(f"activation_fn={activation!r} is not one of {sorted(_ACTIVATIONS)}; or pass a torch.nn class.")
        settings["activation_fn"] = _ACTIVATIONS[activation.lower()]
    return settings


def training_env(
    env: str | gym.Env | VecEnv, n_envs: int, seed: int | None, env_kwargs: dict[str, Any] | None, settings_name: str
) -> gym.Env | VecEnv:
    """The env a baseline trains on: a ``VecEnv`` of the table's ``n_envs`` for an env given by name, else the env
    itself (with a warning when its number of envs differs from the table's).

    :param env: a short name or Gymnasium id, or an env / VecEnv.
    :param n_envs: the table's number of envs.
    :param seed: seed of the envs built (``make_vec_env`` seeds env ``i`` with ``seed + i``).
    :param env_kwargs: keyword arguments of the env constructor; only with ``env`` given by name.
    :param settings_name: what the table's settings are called, for the warning ("the tuned PPO settings").
    :return: the training env.
    :raises ValueError: for ``n_envs < 1``, or ``env_kwargs`` with an env object.
    """
    if isinstance(env, str):
        if n_envs < 1:
            raise ValueError(f"n_envs must be >= 1, got {n_envs}.")
        return make_vec_env(resolve_env_id(env), n_envs=n_envs, seed=seed, env_kwargs=env_kwargs)
    if env_kwargs is not None:
        raise ValueError("env_kwargs only applies when env is given by name; build the env with them instead.")
    given = env.num_envs if isinstance(env, VecEnv) else 1
    if given != n_envs:
        warnings.warn(
            f"The given env has {given} env(s) but {settings_name} for {env_id_of(env) or 'default'} use n_envs={n_envs}. "
            "Pass the env by name to get the table's number of envs.",
            stacklevel=3,
        )
    return env


__all__ = [
    "PPO_HYPERPARAMS",
    "PPO_HYPERPARAMS_FILE",
    "TABLE_DIR",
    "env_id_of",
    "load_table",
    "policy_kwargs",
    "schedule",
    "table_entry",
    "training_env",
]
