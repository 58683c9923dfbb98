"""The agents the harness can train, by name: how to build each one and which extra callbacks it needs."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import gymnasium as gym
from stable_baselines3 import PPO, SAC, HerReplayBuffer
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env

from baselines.action_ff import ActionFFAgent
from baselines.ppo import exact_budget_callback, make_ppo, ppo_hyperparams
from baselines.random_agent import RandomAgent
from baselines.sac_her import make_sac_her, off_policy_budget_callback, sac_her_hyperparams
from ebm_agent.agent import EBMPlannerAgent
from ebm_agent.presets import preset_settings
from eval.digest import class_defaults, env_inverse_dynamics_defaults


class AgentFactory(Protocol):
    """Builds an untrained SB3-style model for one run."""

    def __call__(
        self,
        env_id: str,
        env_kwargs: dict[str, Any],
        seed: int,
        tensorboard_log: str | None,
        device: str,
        hyperparams: dict[str, Any],
        verbose: int,
    ) -> BaseAlgorithm:
        """Build the model.

        :param env_id: registered Gymnasium id of the training env.
        :param env_kwargs: keyword arguments for ``gym.make``.
        :param seed: seed of the model and of its training env.
        :param tensorboard_log: TensorBoard root folder (the run subfolder comes from ``tb_log_name``).
        :param device: torch device ("auto", "cpu", "cuda", ...).
        :param hyperparams: agent keyword arguments (a private copy: the factory may pop from it).
        :param verbose: SB3 verbosity level.
        :return: the model, ready for ``learn``.
        """
        ...


@dataclass(frozen=True)
class AgentSpec:
    """How the harness builds and trains one kind of agent.

    :param factory: builds the model (see ``AgentFactory``).
    :param tb_log_name: the agent's own name, used as its label in tables and plots.
    :param callbacks: extra callbacks for ``learn`` given the budget (e.g. PPO's exact-budget stop), or None.
    :param description: one line for ``ebm-eval --help``.
    :param defaults: ``defaults(env_id, preset) -> dict``: the agent's settings for that env under an agent preset
        (``ebm_agent.presets``; ``""``: the library's defaults), JSON-able, whose digest every finished run stores, so
        that a change of a library default retires the runs made before it (``eval.digest``); None: not tracked.
    :param class_name: the agent's class name, by which ``ebm_agent.presets.PRESETS`` names its settings (None: no
        preset changes this agent).
    """

    factory: Callable[..., BaseAlgorithm]
    tb_log_name: str
    callbacks: Callable[[int], list[BaseCallback]] | None = None
    description: str = ""
    defaults: Callable[[str, str], dict[str, Any]] | None = None
    class_name: str | None = None


def _class_defaults_of(agent_class: type, env_inverse_dynamics: bool = False) -> Callable[[str, str], dict[str, Any]]:
    def defaults(env_id: str, preset: str = "") -> dict[str, Any]:
        settings = class_defaults(agent_class, preset_settings(preset, agent_class.__name__))
        if env_inverse_dynamics:
            changed = env_inverse_dynamics_defaults(env_id)
            if changed:  # only then: the digests of runs on other envs stay as they were
                settings["env:inverse_dynamics"] = changed
        return settings

    return defaults


def ppo_defaults(env_id: str, preset: str = "") -> dict[str, Any]:
    """PPO's settings for an env: the tuned table's entry and SB3's PPO defaults.

    :param env_id: the env.
    :return: ``{"table": ..., "PPO": ...}``.
    """

    return {"table": ppo_hyperparams(env_id), "PPO": class_defaults(PPO)}


def sac_her_defaults(env_id: str, preset: str = "") -> dict[str, Any]:
    """SAC + HER's settings for an env: the table's entry and SB3's SAC and ``HerReplayBuffer`` defaults.

    :param env_id: the env.
    :return: ``{"table": ..., "SAC": ..., "HerReplayBuffer": ...}``.
    """

    return {
        "table": sac_her_hyperparams(env_id),
        "SAC": class_defaults(SAC),
        "HerReplayBuffer": class_defaults(HerReplayBuffer),
    }


def _policy_for(env_id: str, env_kwargs: dict[str, Any]) -> str:
    """``MultiInputPolicy`` for Dict observations (the ``ebm/`` goal envs), ``MlpPolicy`` otherwise."""

    env = gym.make(env_id, **env_kwargs)
    try:
        return "MultiInputPolicy" if isinstance(env.observation_space, gym.spaces.Dict) else "MlpPolicy"
    finally:
        env.close()


def _class_maker(agent_class: type) -> Callable[..., BaseAlgorithm]:
    """``make(env_id, seed=..., ..., env_kwargs=None, **hyperparams)`` for an agent class with SB3's constructor
    ``Agent(policy, env, seed=..., ...)``, on a Monitor-wrapped ``VecEnv`` of ``hyperparams.pop("n_envs", 1)`` envs."""

    def make(
        env_id: str,
        seed: int,
        tensorboard_log: str | None,
        verbose: int,
        device: str,
        env_kwargs: dict[str, Any] | None = None,
        **hyperparams: Any,
    ) -> BaseAlgorithm:
        env_kwargs = env_kwargs or {}
        env = make_vec_env(env_id, n_envs=int(hyperparams.pop("n_envs", 1)), seed=seed, env_kwargs=env_kwargs)
        policy = _policy_for(env_id, env_kwargs)
        return agent_class(
            policy, env, seed=seed, tensorboard_log=tensorboard_log, device=device, verbose=verbose, **hyperparams
        )

    make.__name__ = f"make_{agent_class.__name__}"
    return make


def _factory(make: Callable[..., BaseAlgorithm], description: str) -> AgentFactory:
    """The harness's factory (``AgentFactory``) of an agent built by ``make(env_id, seed=..., tensorboard_log=...,
    verbose=..., device=..., env_kwargs=..., **hyperparams)``: a class (:func:`_class_maker`) or a baseline built
    from its per-env table (``baselines.ppo.make_ppo``, ``baselines.sac_her.make_sac_her``, which build their own
    VecEnv with the table's ``n_envs``).

    :param make: the builder.
    :param description: the factory's docstring.
    :return: the factory.
    """

    def factory(
        env_id: str,
        env_kwargs: dict[str, Any],
        seed: int,
        tensorboard_log: str | None,
        device: str,
        hyperparams: dict[str, Any],
        verbose: int = 0,
    ) -> BaseAlgorithm:
        return make(
            env_id,
            seed=seed,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            device=device,
            env_kwargs=env_kwargs or None,
            **hyperparams,
        )

    factory.__doc__ = description
    factory.__name__ = f"{make.__name__}_factory"
    return factory


make_ebm = _factory(_class_maker(EBMPlannerAgent), "Build the EBM planning agent (single env unless ``n_envs`` is given).")
make_action_ff = _factory(
    _class_maker(ActionFFAgent), "Build the action-conditioned feed-forward baseline (same API as the EBM agent)."
)
make_random = _factory(_class_maker(RandomAgent), "Build the uniform random-exploration agent.")


make_ppo_agent = _factory(make_ppo, "Build SB3's PPO with the tuned per-env hyperparameters of ``baselines.ppo``.")
make_sac_her_agent = _factory(
    make_sac_her, "Build SB3's SAC with a ``HerReplayBuffer`` and the per-env hyperparameters of ``baselines.sac_her``."
)


def ppo_callbacks(total_timesteps: int) -> list[BaseCallback]:
    """PPO collects whole rollouts, so it needs a callback to stop at exactly the budget.

    :param total_timesteps: the transition budget.
    :return: ``[baselines.ppo.exact_budget_callback(total_timesteps)]``.
    """

    return [exact_budget_callback(total_timesteps)]


def sac_her_callbacks(total_timesteps: int) -> list[BaseCallback]:
    """With its table's 1 env and ``train_freq=1`` SAC stops at the budget by itself; this guard keeps it exact
    when ``n_envs`` or ``train_freq`` are overridden.

    :param total_timesteps: the transition budget.
    :return: ``[baselines.sac_her.off_policy_budget_callback(total_timesteps)]``.
    """

    return [off_policy_budget_callback(total_timesteps)]


AGENTS: dict[str, AgentSpec] = {
    "ebm": AgentSpec(
        make_ebm,
        "EBM",
        description="energy-based planner (the agent under test)",
        defaults=_class_defaults_of(EBMPlannerAgent, env_inverse_dynamics=True),
        class_name="EBMPlannerAgent",
    ),
    "ppo": AgentSpec(
        make_ppo_agent,
        "PPO",
        ppo_callbacks,
        description="SB3 PPO with tuned per-env hyperparameters",
        defaults=ppo_defaults,
    ),
    "action-ff": AgentSpec(
        make_action_ff,
        "ActionFF",
        description="action-conditioned feed-forward model + MPPI",
        defaults=_class_defaults_of(ActionFFAgent),
        class_name="ActionFFAgent",
    ),
    "sac-her": AgentSpec(
        make_sac_her_agent,
        "SAC_HER",
        sac_her_callbacks,
        description="SB3 SAC + HER replay (goal relabelling)",
        defaults=sac_her_defaults,
    ),
    "random": AgentSpec(
        make_random,
        "Random",
        description="uniform random actions (exploration baseline)",
        defaults=_class_defaults_of(RandomAgent),
    ),
}
"""Agent names accepted by ``--agents`` / ``--baseline``, mapped to their specs. Tests may register more."""


def register_agent(name: str, spec: AgentSpec, overwrite: bool = False) -> None:
    """Add an agent to ``AGENTS`` (in this process: a spawned worker sees only the built-in ones).

    :param name: the name used on the command line and in run folders.
    :param spec: how to build and train it.
    :param overwrite: replace an existing entry instead of raising.
    """
    if not isinstance(spec, AgentSpec):
        raise TypeError(f"spec must be an AgentSpec, got {type(spec).__name__}")
    if name in AGENTS and not overwrite:
        raise ValueError(f"agent {name!r} is already registered; pass overwrite=True to replace it")
    AGENTS[name] = spec


def get_agent(name: str) -> AgentSpec:
    """Look an agent up by name.

    :param name: a key of ``AGENTS``.
    :return: its spec.
    """
    try:
        return AGENTS[name]
    except KeyError:
        raise ValueError(f"unknown agent {name!r}; choose one of: {', '.join(sorted(AGENTS))}") from None


__all__ = [
    "AGENTS",
    "AgentFactory",
    "AgentSpec",
    "get_agent",
    "ppo_defaults",
    "register_agent",
    "sac_her_defaults",
]
