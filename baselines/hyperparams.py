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
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.utils import LinearSchedule
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecNormalize

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


def normalize_kwargs(setting: Any, gamma: float | None = None) -> dict[str, Any] | None:
    """rl-zoo3's ``normalize`` entry as ``VecNormalize`` keyword arguments.

    :param setting: ``False`` / None (no normalisation), ``True`` (``VecNormalize``'s defaults, observations and
        rewards, as rl-zoo3's ``normalize: true``) or a dict of ``VecNormalize`` keyword arguments (``norm_obs``,
        ``norm_reward``, ``clip_obs``, ...).
    :param gamma: the algorithm's discount; like rl-zoo3 it becomes the reward normaliser's ``gamma`` unless the dict
        sets one.
    :return: the keyword arguments, or None for no normalisation.
    :raises ValueError: for another value or an unknown key.
    """
    if setting is None or setting is False:
        return None
    if setting is True:
        setting = {}
    if not isinstance(setting, dict):
        raise ValueError(
            f"normalize={setting!r}: use true, false or a dict of VecNormalize arguments, e.g. "
            "{norm_obs: true, norm_reward: false}."
        )
    unknown = sorted(set(setting) - _VEC_NORMALIZE_KEYS)
    if unknown:
        raise ValueError(f"normalize: unknown VecNormalize argument(s) {unknown}; it takes {sorted(_VEC_NORMALIZE_KEYS)}.")
    kwargs = dict(setting)
    if gamma is not None:
        kwargs.setdefault("gamma", float(gamma))
    return kwargs


_VEC_NORMALIZE_KEYS = frozenset({"norm_obs", "norm_reward", "clip_obs", "clip_reward", "gamma", "epsilon", "norm_obs_keys"})
"""The ``VecNormalize`` arguments a table's ``normalize`` dict may set (its ``venv`` and ``training`` are not settings)."""


def normalized(env: gym.Env | VecEnv, kwargs: dict[str, Any] | None) -> gym.Env | VecEnv:
    """The training env wrapped in ``VecNormalize`` with ``kwargs`` (as is for None).

    The statistics are part of the model: SB3 stores the raw observations in its buffers and normalises them when it
    samples, and ``model.get_vec_normalize_env()`` returns the wrapper, which :func:`normalized_like` copies onto an
    evaluation env.

    :param env: an env or VecEnv.
    :param kwargs: from :func:`normalize_kwargs`.
    :return: the env to train on.
    """
    if kwargs is None:
        return env
    vec_env = env if isinstance(env, VecEnv) else DummyVecEnv([lambda: env])
    return VecNormalize(vec_env, **kwargs)


def normalized_like(model: BaseAlgorithm, env: VecEnv) -> VecEnv:
    """An evaluation env that sees what ``model`` was trained on: wrapped in a frozen ``VecNormalize`` that shares the
    model's observation statistics, when the model has one; else ``env`` itself.

    Rewards stay raw (``norm_reward=False``), so scores are in the env's units; the statistics object is shared, so
    evaluations during training see the current statistics (SB3's ``EvalCallback`` also syncs them).

    :param model: an SB3 model (this project's agents too; theirs is always None).
    :param env: the evaluation VecEnv.
    :return: the env to evaluate on.
    """
    normalizer = model.get_vec_normalize_env()
    if normalizer is None:
        return env
    wrapped = VecNormalize(
        env,
        training=False,
        norm_obs=normalizer.norm_obs,
        norm_reward=False,
        clip_obs=normalizer.clip_obs,
        epsilon=normalizer.epsilon,
        norm_obs_keys=normalizer.norm_obs_keys,
    )
    wrapped.obs_rms = normalizer.obs_rms
    return wrapped


__all__ = [
    "PPO_HYPERPARAMS",
    "PPO_HYPERPARAMS_FILE",
    "TABLE_DIR",
    "env_id_of",
    "load_table",
    "normalize_kwargs",
    "normalized",
    "normalized_like",
    "policy_kwargs",
    "schedule",
    "table_entry",
    "training_env",
]
