"""PPO baseline: Stable-Baselines3's PPO with the per-env tuned hyperparameters of :mod:`baselines.hyperparams`.

``make_ppo("particle", seed=0).learn(50_000, callback=exact_budget_callback(50_000))`` is the whole recipe. An
entry's ``normalize`` (rl-zoo3's key) wraps the training env in ``VecNormalize``, whose statistics the harness copies
onto its raw evaluation env (``baselines.hyperparams.normalized_like``).

Step accounting: SB3 counts ``num_timesteps`` in transitions (``n_envs`` per vectorised step) and only checks the
budget between rollouts of ``n_envs * n_steps`` transitions, so ``learn(total)`` overshoots unless ``total`` is a
multiple of the rollout size. :func:`exact_budget_callback` stops at the first vectorised step at or past ``total``:
exactly ``total`` when it is a multiple of ``n_envs``, otherwise fewer than ``n_envs`` transitions more.
"""

from __future__ import annotations

import inspect
import numbers
from typing import Any

import gymnasium as gym
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv

from baselines.hyperparams import (
    PPO_HYPERPARAMS,
    env_id_of,
    normalize_kwargs,
    normalized,
    policy_kwargs,
    schedule,
    table_entry,
    training_env,
)

# Arguments make_ppo sets itself; everything else in PPO's constructor may come from the table or an override.
_OWN_ARGUMENTS = {"self", "policy", "env", "seed", "tensorboard_log", "verbose", "device", "_init_setup_model"}
VALID_HYPERPARAMS: frozenset[str] = frozenset(
    {"n_envs", "policy", "normalize"} | (set(inspect.signature(PPO.__init__).parameters) - _OWN_ARGUMENTS)
)
"""Keys a table entry or a ``make_ppo`` override may set: ``n_envs``, ``policy``, ``normalize`` (rl-zoo3's: true,
false or ``VecNormalize`` arguments) and PPO's constructor arguments."""


def ppo_hyperparams(env_id: str) -> dict[str, Any]:
    """Return the PPO hyperparameters used for an env: its table entry merged over ``default``.

    The result is plain data (numbers, strings, dicts), safe to print or store beside results. An id without an
    entry gets ``default`` alone.

    :param env_id: a registered id (``ebm/Particle-v0``) or a short name (``particle``).
    :return: a fresh dict (mutating it does not change the table).
    """
    return table_entry(PPO_HYPERPARAMS, env_id)


def make_ppo(
    env: str | gym.Env | VecEnv,
    seed: int | None = None,
    tensorboard_log: str | None = None,
    verbose: int = 0,
    device: str = "auto",
    env_kwargs: dict[str, Any] | None = None,
    **overrides: Any,
) -> PPO:
    """Build an SB3 PPO with the tuned hyperparameters for ``env`` (``MultiInputPolicy`` for Dict observations).

    :param env: a short name or Gymnasium id (a ``VecEnv`` of the table's ``n_envs`` is built with
        ``make_vec_env``), or an env / VecEnv to use as is (a warning is issued when its number of envs differs
        from the table's ``n_envs``; the hyperparameters are then looked up by ``env.spec.id`` when it has one).
    :param seed: seed of PPO and of the envs it builds (``make_vec_env`` seeds env ``i`` with ``seed + i``).
    :param tensorboard_log: TensorBoard folder (``None``: no TensorBoard).
    :param verbose: 0 silent, 1 training info, 2 debug.
    :param device: torch device for the networks (``"auto"``: CUDA when available). Small MLP policies are
        usually fastest on the CPU.
    :param env_kwargs: keyword arguments of the env constructor; only with ``env`` given by name.
    :param overrides: hyperparameters replacing the table's (``n_envs``, ``n_steps``, ``learning_rate``,
        ``policy_kwargs`` (replaces the whole dict), ...). See :data:`VALID_HYPERPARAMS`.
    :return: an untrained ``stable_baselines3.PPO``.
    """
    unknown = sorted(set(overrides) - VALID_HYPERPARAMS)
    if unknown:
        raise TypeError(
            f"make_ppo() got unknown hyperparameter(s) {unknown}; valid keys are {sorted(VALID_HYPERPARAMS)}. "
            "Pass PPO constructor arguments, n_envs or policy."
        )
    env_id = env_id_of(env)
    params = ppo_hyperparams(env_id) if env_id is not None else ppo_hyperparams("default")
    params.update(overrides)
    n_envs = int(params.pop("n_envs"))
    # Turn the table's plain data into what PPO takes, before any env is built, so bad values fail fast.
    for key in ("learning_rate", "clip_range", "clip_range_vf"):
        if isinstance(params.get(key), str):
            params[key] = schedule(key, params[key])
    params["policy_kwargs"] = policy_kwargs(params.get("policy_kwargs") or {})
    normalization = normalize_kwargs(params.pop("normalize", False), params.get("gamma", 0.99))
    vec_env = normalized(training_env(env, n_envs, seed, env_kwargs, "the tuned PPO settings"), normalization)

    policy = params.pop("policy", None) or _default_policy(vec_env.observation_space)
    return PPO(policy, vec_env, seed=seed, tensorboard_log=tensorboard_log, verbose=verbose, device=device, **params)


def exact_budget_callback(total_timesteps: int, verbose: int = 0) -> BaseCallback:
    """Return a callback that stops training after exactly ``total_timesteps`` transitions.

    Pass it to ``learn`` with the same budget: ``model.learn(n, callback=exact_budget_callback(n))``. It works for
    any SB3-style algorithm that calls ``on_step`` once per vectorised step (PPO, SAC, the agents of this project).
    With ``n_envs`` envs a step adds ``n_envs`` transitions, so a budget that is not a multiple of ``n_envs``
    overshoots by fewer than ``n_envs``. For on-policy algorithms the transitions of an unfinished last rollout are
    consumed but not trained on (SB3 trains on full rollouts only); a rollout that ends exactly on the budget is
    still trained on.

    :param total_timesteps: the budget in transitions (env steps summed over envs).
    :param verbose: 1 prints a line when it stops training.
    :return: the callback.
    """
    return ExactBudgetCallback(total_timesteps, verbose=verbose)


class ExactBudgetCallback(BaseCallback):
    """Stop training once ``num_timesteps`` reaches a budget (see :func:`exact_budget_callback`).

    :param total_timesteps: the budget in transitions.
    :param verbose: 1 prints a line when it stops training.
    """

    def __init__(self, total_timesteps: int, verbose: int = 0) -> None:
        super().__init__(verbose=verbose)
        if isinstance(total_timesteps, bool) or not isinstance(total_timesteps, numbers.Integral) or total_timesteps < 1:
            raise ValueError(f"total_timesteps must be a positive int, got {total_timesteps!r}.")
        self.total_timesteps: int = int(total_timesteps)

    def _on_step(self) -> bool:
        if self.num_timesteps < self.total_timesteps:
            return True
        # The step that completes an on-policy rollout: let SB3 train on it; its own loop then stops at the budget.
        # (`n_steps` counts the steps before this one inside OnPolicyAlgorithm.collect_rollouts.)
        n_steps, n_rollout_steps = self.locals.get("n_steps"), self.locals.get("n_rollout_steps")
        completes_rollout = isinstance(n_steps, int) and n_steps + 1 == n_rollout_steps
        if completes_rollout and self.num_timesteps == self.total_timesteps:
            return True
        if self.verbose >= 1:
            print(f"Stopping training at {self.num_timesteps} transitions (budget {self.total_timesteps}).")
        return False


def _default_policy(observation_space: spaces.Space) -> str:
    return "MultiInputPolicy" if isinstance(observation_space, spaces.Dict) else "MlpPolicy"


__all__ = ["VALID_HYPERPARAMS", "ExactBudgetCallback", "exact_budget_callback", "make_ppo", "ppo_hyperparams"]
