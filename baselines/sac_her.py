"""SAC + HER baseline: Stable-Baselines3's SAC with ``HerReplayBuffer`` (goal relabelling) on the GoalEnv dicts.

``make_sac_her("particle", seed=0).learn(20_000)`` is the whole recipe; the per-env hyperparameters are data,
``baselines/sac_her.yaml`` (rl-zoo3 style, a ``default`` entry; its comments say where each value comes from). An
entry's ``normalize`` (rl-zoo3's key; the Fetch entries set it, as rl-zoo3 does) wraps the training env in
``VecNormalize``; the statistics belong to the model (``model.get_vec_normalize_env()``), and the harness evaluates
through a frozen copy of them (``baselines.hyperparams.normalized_like``) on the same raw env as every other agent.

HER relabels a stored transition with a goal achieved later in its episode (``future``) and asks the env for the
new reward through ``compute_reward(next achieved_goal, new desired_goal, info)``, vectorised over the batch. Every
``ebm/`` env has it, and its ``step`` reward is that same function, so relabelled rewards are exact. SB3 does not
recompute ``terminated`` for a relabelled goal (it keeps the stored flag): a relabelled transition that reaches its
new goal is not marked terminal. Since the reward is ~0 at the goal, this only delays, not biases, the value there.

Step accounting: with 1 env and ``train_freq=1`` (every table entry), SB3's off-policy loop stops at exactly
``total_timesteps``. :func:`off_policy_budget_callback` keeps it exact for overrides (more envs, a larger
``train_freq``) and still lets the transition at the budget be stored and trained on when it ends a train step.
"""

from __future__ import annotations

import inspect
from typing import Any

import gymnasium as gym
from gymnasium import spaces
from stable_baselines3 import SAC, HerReplayBuffer
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.type_aliases import TrainFreq, TrainFrequencyUnit
from stable_baselines3.common.vec_env import VecEnv

from baselines.hyperparams import (
    TABLE_DIR,
    env_id_of,
    load_table,
    normalize_kwargs,
    normalized,
    policy_kwargs,
    schedule,
    table_entry,
    training_env,
)
from baselines.ppo import ExactBudgetCallback
from envs import resolve_env_id

SAC_HER_HYPERPARAMS_FILE = TABLE_DIR / "sac_her.yaml"
"""The SAC + HER table."""

SAC_HER_HYPERPARAMS: dict[str, dict[str, Any]] = load_table("sac_her")
"""SAC + HER hyperparameters per Gymnasium id; ``default`` fills in whatever an entry leaves out."""

GOAL_KEYS = ("observation", "achieved_goal", "desired_goal")
"""The keys of a GoalEnv observation, which HER needs."""

# Arguments make_sac_her sets itself (the replay buffer is always HER); the rest of SAC's constructor is settable.
_OWN_ARGUMENTS = {"self", "policy", "env", "seed", "tensorboard_log", "verbose", "device", "_init_setup_model"}
VALID_HYPERPARAMS: frozenset[str] = frozenset(
    {"n_envs", "policy", "normalize"}
    | (set(inspect.signature(SAC.__init__).parameters) - _OWN_ARGUMENTS - {"replay_buffer_class"})
)
"""Keys a table entry or a ``make_sac_her`` override may set: ``n_envs``, ``policy``, ``normalize`` (rl-zoo3's: true,
false or ``VecNormalize`` arguments) and SAC's constructor arguments (``replay_buffer_class`` excepted)."""

_BUFFER_OWN_ARGUMENTS = {"self", "buffer_size", "observation_space", "action_space", "env", "device", "n_envs"}
VALID_REPLAY_BUFFER_KWARGS: frozenset[str] = frozenset(
    set(inspect.signature(HerReplayBuffer.__init__).parameters) - _BUFFER_OWN_ARGUMENTS
)
"""Keys of ``replay_buffer_kwargs``: ``HerReplayBuffer``'s own settings (``n_sampled_goal``, ``goal_selection_strategy``,
...)."""


def sac_her_hyperparams(env_id: str) -> dict[str, Any]:
    """Return the SAC + HER hyperparameters used for an env: its table entry merged over ``default``.

    The result is plain data (numbers, strings, dicts), safe to print or store beside results. An id without an
    entry gets ``default`` alone.

    :param env_id: a registered id (``ebm/Particle-v0``) or a short name (``particle``).
    :return: a fresh dict (mutating it does not change the table).
    :raises ValueError: when the table's entry (or ``default``) holds a key SAC does not take.
    """
    env_id = resolve_env_id(env_id)
    for name in ("default", env_id):
        _check_keys(SAC_HER_HYPERPARAMS.get(name, {}), f"{SAC_HER_HYPERPARAMS_FILE.name} entry {name!r}", ValueError)
    return table_entry(SAC_HER_HYPERPARAMS, env_id, nested=("policy_kwargs", "replay_buffer_kwargs"))


def make_sac_her(
    env: str | gym.Env | VecEnv,
    seed: int | None = None,
    tensorboard_log: str | None = None,
    verbose: int = 0,
    device: str = "auto",
    env_kwargs: dict[str, Any] | None = None,
    **overrides: Any,
) -> SAC:
    """Build an SB3 SAC with a ``HerReplayBuffer`` and the tuned hyperparameters for ``env``.

    :param env: a short name or Gymnasium id (a ``VecEnv`` of the table's ``n_envs`` is built with
        ``make_vec_env``), or a goal env / VecEnv to use as is (the hyperparameters are then looked up by
        ``env.spec.id`` when it has one). Its observations must be a ``Dict`` with ``observation``,
        ``achieved_goal`` and ``desired_goal``, and it must have a vectorised ``compute_reward``.
    :param seed: seed of SAC and of the envs it builds (``make_vec_env`` seeds env ``i`` with ``seed + i``).
    :param tensorboard_log: TensorBoard folder (``None``: no TensorBoard).
    :param verbose: 0 silent, 1 training info, 2 debug.
    :param device: torch device for the networks (``"auto"``: CUDA when available). Small MLPs are usually
        fastest on the CPU.
    :param env_kwargs: keyword arguments of the env constructor; only with ``env`` given by name.
    :param overrides: hyperparameters replacing the table's (``learning_rate``, ``gamma``, ``learning_starts``,
        ``policy_kwargs`` / ``replay_buffer_kwargs`` (each replaces the whole dict), ...). See
        :data:`VALID_HYPERPARAMS` and :data:`VALID_REPLAY_BUFFER_KWARGS`.
    :return: an untrained ``stable_baselines3.SAC``.
    :raises TypeError: for an unknown hyperparameter or replay-buffer setting.
    :raises ValueError: for a non-goal env, or ``learning_starts`` shorter than the env's time limit.
    """
    _check_keys(overrides, "make_sac_her()", TypeError)
    env_id = env_id_of(env)
    params = sac_her_hyperparams(env_id) if env_id is not None else sac_her_hyperparams("default")
    params.update(overrides)
    n_envs = int(params.pop("n_envs"))
    # Turn the table's plain data into what SAC takes, before any env is built, so bad values fail fast.
    if isinstance(params.get("learning_rate"), str):
        params["learning_rate"] = schedule("learning_rate", params["learning_rate"])
    if isinstance(params.get("train_freq"), list):  # YAML has no tuples: [1, "episode"] -> (1, "episode")
        params["train_freq"] = tuple(params["train_freq"])
    params["policy_kwargs"] = policy_kwargs(params.get("policy_kwargs") or {})
    params["replay_buffer_kwargs"] = dict(params.get("replay_buffer_kwargs") or {})
    normalization = normalize_kwargs(params.pop("normalize", False), params.get("gamma", 0.99))
    vec_env = training_env(env, n_envs, seed, env_kwargs, "the SAC + HER settings")
    _check_goal_env(vec_env, int(params.get("learning_starts", 100)))
    vec_env = normalized(vec_env, normalization)

    policy = params.pop("policy", None) or "MultiInputPolicy"
    return SAC(
        policy,
        vec_env,
        replay_buffer_class=HerReplayBuffer,
        seed=seed,
        tensorboard_log=tensorboard_log,
        verbose=verbose,
        device=device,
        **params,
    )


def off_policy_budget_callback(total_timesteps: int, verbose: int = 0) -> BaseCallback:
    """Return a callback that stops an off-policy algorithm (SAC) after exactly ``total_timesteps`` transitions.

    Pass it to ``learn`` with the same budget. Like ``baselines.ppo.exact_budget_callback`` it stops at the first
    vectorised step at or past the budget (exact when the budget is a multiple of ``n_envs``); when that step ends
    a train step (``train_freq`` counted in steps) it lets SB3 store the transition and train on it, and SB3's own
    loop then stops. With 1 env and ``train_freq=1`` it never has to stop anything.

    :param total_timesteps: the budget in transitions (env steps summed over envs).
    :param verbose: 1 prints a line when it stops training.
    :return: the callback.
    """
    return OffPolicyBudgetCallback(total_timesteps, verbose=verbose)


class OffPolicyBudgetCallback(ExactBudgetCallback):
    """Stop an off-policy algorithm once ``num_timesteps`` reaches a budget (see :func:`off_policy_budget_callback`).

    :param total_timesteps: the budget in transitions.
    :param verbose: 1 prints a line when it stops training.
    """

    def _on_step(self) -> bool:
        if self.num_timesteps == self.total_timesteps and self._step_ends_train_step():
            return True
        return super()._on_step()

    def _step_ends_train_step(self) -> bool:
        # Locals of OffPolicyAlgorithm.collect_rollouts: `num_collected_steps` already counts this step.
        train_freq, collected = self.locals.get("train_freq"), self.locals.get("num_collected_steps")
        if not isinstance(train_freq, TrainFreq) or not isinstance(collected, int):
            return False
        return train_freq.unit == TrainFrequencyUnit.STEP and collected >= train_freq.frequency


def _check_keys(settings: dict[str, Any], where: str, error: type[Exception]) -> None:
    unknown = sorted(set(settings) - VALID_HYPERPARAMS)
    if unknown:
        raise error(
            f"{where} got unknown hyperparameter(s) {unknown}; valid keys are {sorted(VALID_HYPERPARAMS)}. "
            "Pass SAC constructor arguments, n_envs or policy (the replay buffer is always HerReplayBuffer)."
        )
    buffer_kwargs = settings.get("replay_buffer_kwargs") or {}
    unknown = sorted(set(buffer_kwargs) - VALID_REPLAY_BUFFER_KWARGS)
    if unknown:
        raise error(
            f"{where} got unknown replay_buffer_kwargs {unknown}; HerReplayBuffer takes {sorted(VALID_REPLAY_BUFFER_KWARGS)}."
        )


def _check_goal_env(env: VecEnv | gym.Env, learning_starts: int) -> None:
    """HER needs GoalEnv dicts, and a finished episode before its first sample: ``learning_starts`` counts
    transitions over all envs, so each env has run ``learning_starts / n_envs`` steps by then."""
    space = env.observation_space
    if not isinstance(space, spaces.Dict) or not set(GOAL_KEYS) <= set(space.spaces):
        raise ValueError(f"SAC + HER needs a goal env whose observations are a Dict with keys {list(GOAL_KEYS)}, got {space}.")
    if isinstance(env, VecEnv):
        spec, n_envs = env.get_attr("spec", indices=[0])[0], env.num_envs
    else:
        spec, n_envs = env.spec, 1
    max_episode_steps = getattr(spec, "max_episode_steps", None)
    if max_episode_steps is not None and learning_starts < max_episode_steps * n_envs:
        raise ValueError(
            f"learning_starts={learning_starts} transitions over {n_envs} env(s) is shorter than an episode "
            f"({max_episode_steps} steps): HerReplayBuffer samples only finished episodes and would fail at the "
            f"first gradient step. Set learning_starts >= {max_episode_steps * n_envs}."
        )


__all__ = [
    "GOAL_KEYS",
    "SAC_HER_HYPERPARAMS",
    "SAC_HER_HYPERPARAMS_FILE",
    "VALID_HYPERPARAMS",
    "VALID_REPLAY_BUFFER_KWARGS",
    "OffPolicyBudgetCallback",
    "make_sac_her",
    "off_policy_budget_callback",
    "sac_her_hyperparams",
]
