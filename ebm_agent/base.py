"""The online plan-execute-train loop (Algorithm 1) and the SB3 surface shared by the planning agents.

A subclass supplies the model-specific parts: how to plan (:meth:`PlannerAgentBase._plan`) and how to take a
gradient step on a finished plan segment (:meth:`PlannerAgentBase._train_on_segments`). Everything else, the
step budget, per-env deviation handling, warm starts, replay of real transitions, callbacks, logging, ``predict``
with the plan carried in ``state``, lives here so the EBM agent and the Action FF baseline behave identically.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, ConvertCallback
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback
from stable_baselines3.common.utils import configure_logger, safe_mean

from ebm_agent.buffers import TransitionBatch, TransitionBuffer
from ebm_agent.checkpoint import CheckpointMixin
from ebm_agent.config import OnlineConfig, learn_budgets, make_config
from ebm_agent.datasets import TransitionDataset, iterate_minibatches
from ebm_agent.goal_spec import GoalSpec, check_finite_observation, check_spaces, env_inverse_dynamics, read_goal_spec
from ebm_agent.inverse_dynamics import InverseDynamics, PlanFollower, make_inverse_dynamics
from ebm_agent.moves import MoveStatistics, state_periods
from ebm_agent.planner import shift_plan
from ebm_agent.policy import PlanningPolicy
from ebm_agent.subgoals import (
    ExploreConfig,
    FrontierRebuild,
    FrontierSubgoals,
    GraphSubgoals,
    SubgoalGraphConfig,
    check_long_horizon,
    long_horizon_configs,
    subgoal_settings,
)

SelfPlannerAgent = TypeVar("SelfPlannerAgent", bound="PlannerAgentBase")

PlanState = tuple[np.ndarray, np.ndarray, np.ndarray]
"""``predict``'s recurrent state: (plans [N, T+1, D], planned actions [N, T, A] (NaN when actions come from
inverse dynamics), steps executed [N])."""


@dataclass
class Segment:
    """A finished stretch of one plan's execution: the training data of one Algorithm-1 iteration.

    :param planned: [k+1, D] the planned states that were attempted (start, then one per executed step).
    :param real_states: [k, D] real states before each executed step.
    :param real_next_states: [k, D] real states after each executed step.
    :param actions: [k, A] executed actions.
    """

    planned: np.ndarray
    real_states: np.ndarray
    real_next_states: np.ndarray
    actions: np.ndarray


@dataclass
class OnlineLoopState:
    """Where the online loop (Algorithm 1) stands between two env steps, kept on the agent between ``learn`` calls.

    It is part of the saved agent, so that a run resumed from a checkpoint (``load_checkpoint(..., force_reset=False)``
    on the env as it was, then ``learn(..., reset_num_timesteps=False)``) goes on with the plans in flight and the
    partly executed segments, exactly as if it had not stopped. A ``learn`` that resets the env starts a fresh one.

    :param plans: [n, T+1, D] each env's current plan.
    :param planned_actions: [n, T, A] its actions (NaN: from inverse dynamics).
    :param plan_cost: [n] the plan's cost when it was made.
    :param steps: [n] steps of the current plan executed so far.
    :param need: [n] envs waiting for a new plan.
    :param warm: [n] ...that warm-start it from their previous plan, shifted by ``shift``.
    :param shift: [n] that shift.
    :param executed: per env, the (s, s', a) executed since its plan began.
    :param episodes_at_dump: the episode count at the last log dump.
    """

    plans: np.ndarray
    planned_actions: np.ndarray
    plan_cost: np.ndarray
    steps: np.ndarray
    need: np.ndarray
    warm: np.ndarray
    shift: np.ndarray
    executed: list[list[tuple[np.ndarray, np.ndarray, np.ndarray]]]
    episodes_at_dump: int

    @classmethod
    def fresh(cls, num_envs: int, horizon: int, state_dim: int, action_dim: int, episodes: int) -> OnlineLoopState:
        """The state before the first plan: every env needs one.

        :param num_envs: n.
        :param horizon: T.
        :param state_dim: D.
        :param action_dim: A.
        :param episodes: the episode count now.
        :return: the state.
        """
        return cls(
            plans=np.zeros((num_envs, horizon + 1, state_dim), dtype=np.float32),
            planned_actions=np.full((num_envs, horizon, action_dim), np.nan, dtype=np.float32),
            plan_cost=np.zeros(num_envs, dtype=np.float32),
            steps=np.zeros(num_envs, dtype=np.int64),
            need=np.ones(num_envs, dtype=bool),
            warm=np.zeros(num_envs, dtype=bool),
            shift=np.zeros(num_envs, dtype=np.int64),
            executed=[[] for _ in range(num_envs)],
            episodes_at_dump=episodes,
        )

    def fits(self, num_envs: int, horizon: int, state_dim: int, action_dim: int) -> bool:
        """Whether the state belongs to a loop of these sizes (one saved with other settings does not).

        :return: True when ``plans`` and ``planned_actions`` have the shapes the sizes give.
        """
        return self.plans.shape == (num_envs, horizon + 1, state_dim) and self.planned_actions.shape == (
            num_envs,
            horizon,
            action_dim,
        )


LEARNED_INVERSE_DYNAMICS = "rls_tracking"
"""The inverse model an agent with ``inverse_dynamics=None`` learns on an env without its own: recursive least squares
following the rest of the plan (issue 46; PointMaze_UMaze-v3 after 3,000 transitions, fast preset, 10 episodes: success
0.80 on each of seeds 0-2, against 0.30, 0.20, 0.10 with the one-step ``"rls"``; the MLP failed FetchReach-v4 outright)."""


def _env_name(env: Any) -> str:
    """The env's registered id (or its class) for messages."""
    try:
        spec = env.get_attr("spec", indices=[0])[0]
    except (AttributeError, IndexError):
        spec = None
    if spec is not None and getattr(spec, "id", None):
        return f"the env {spec.id!r}"
    try:
        return f"the env {type(env.get_attr('unwrapped', indices=[0])[0]).__name__}"
    except (AttributeError, IndexError):
        return "the env"


class PlannerAgentBase(CheckpointMixin, BaseAlgorithm):
    """Base class of agents that plan a state trajectory, act along it and learn their model online.

    :param policy: ``"MultiInputPolicy"`` (the only alias; the networks are built by the subclass).
    :param env: a goal-conditioned env (Dict observation with observation/achieved_goal/desired_goal), its id, or a
        VecEnv of several.
    :param learning_rate: learning rate of the model's optimiser.
    :param horizon: T, number of planned transitions: the planner's, which the subclass reads from it.
    :param online: :class:`OnlineConfig` (or a dict of its fields).
    :param inverse_dynamics: ``"ground_truth"`` (the env's ``inverse_dynamics``; an env without it is refused at
        construction), ``"rls_tracking"`` (a linear model fitted by recursive least squares, the first action of the
        action sequence that best follows the rest of the plan through it), ``"rls"`` (the same model solved for the
        next planned state alone), ``"mlp"`` (a learned MLP from s, s' to a), an
        :class:`~ebm_agent.inverse_dynamics.InverseDynamics` instance, or None (the default): the env's where it
        has them, else ``LEARNED_INVERSE_DYNAMICS``, with a warning that says so.
    :param subgoal_graph: long-horizon goal reaching (issue #36): a :class:`~ebm_agent.subgoals.SubgoalGraphConfig`
        or a dict of its fields, the keywords of :meth:`~ebm_agent.subgoals.GraphSubgoals.from_transitions` (``{}``
        for its defaults), with which the agent
        builds a graph over the real transitions it learned from at the end of ``learn_offline`` (the dataset's) and
        of ``learn`` (its replay buffer's), and then aims each plan at a subgoal along the graph's shortest path to
        the goal (``self.subgoals``). Its edges come from the learned energy (``"edges": "energy"``, the default; the
        EBM agent), from the moves the agent made (``"real"``; any agent) or both. None (the default, the paper's):
        plans aim at the goal. The graph is not saved with the agent: after ``load``, call :meth:`build_subgoals`.
    :param explore: frontier exploration during ``learn`` (issue #36): an :class:`~ebm_agent.subgoals.ExploreConfig`
        or a dict of its fields, ``every`` (transitions between rebuilds of the graph over the replay buffer, 1000),
        ``goal_heuristic`` (1.0; 0 explores without regard to the goal) and ``revisit_cost`` (1.0) of
        :class:`~ebm_agent.subgoals.FrontierSubgoals`: the plans aim along the
        graph to the goal once it has been seen, else at the cheapest frontier of the visited states. The graph uses
        ``subgoal_graph``'s settings. After ``learn``, plans aim as ``subgoal_graph`` says (subgoals along the final
        graph, or the goal when it is None). None (the default, the paper's): no frontier exploration.
    :param subgoal_class: the subgoal provider the agent builds, as SB3's off-policy algorithms take a
        ``replay_buffer_class`` with its ``replay_buffer_kwargs`` (here ``subgoal_graph``): None (the default) is
        :class:`~ebm_agent.subgoals.GraphSubgoals`. Any class with a classmethod ``from_transitions(states [M, D],
        next_states [M, D], *, goal_indices, lookahead, energy, period, **subgoal_graph)`` whose result has
        ``subgoals(states [N, D], goals [N, G]) -> [N, G]`` can stand in; the agent hands it the real transitions,
        its goal dims, its horizon, its learned energy (None for Action FF) and the periods of its state dims, never
        itself. Given without ``subgoal_graph``, it is built with no keywords. ``explore`` needs a
        :class:`~ebm_agent.subgoals.GraphSubgoals` (or a subclass).
    :param goal_indices: the observation dims that ``achieved_goal`` copies (None: the env's ``goal_indices``, else
        inferred from a reset observation and printed with ``verbose >= 1``; ``goal_spec.goal_indices`` holds them).
    :param stats_window_size: episodes averaged for ``rollout/*`` logs.
    :param tensorboard_log: folder of TensorBoard runs (None: no TensorBoard).
    :param verbose: 0 silent, 1 info, 2 debug.
    :param seed: seed of numpy, torch, the env, the buffers and the planner's noise.
    :param device: ``"auto"``, ``"cpu"`` or ``"cuda"``.
    :param _init_setup_model: build the networks now (``load`` passes False).
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {"MultiInputPolicy": PlanningPolicy}
    default_tb_log_name: ClassVar[str] = "Planner"
    policy: PlanningPolicy

    def __init__(
        self,
        policy: str | type[PlanningPolicy],
        env: GymEnv | str | None,
        learning_rate: float = 1e-3,
        horizon: int = 10,
        online: OnlineConfig | dict[str, Any] | None = None,
        inverse_dynamics: str | InverseDynamics | None = None,
        subgoal_graph: SubgoalGraphConfig | dict[str, Any] | None = None,
        explore: ExploreConfig | dict[str, Any] | None = None,
        subgoal_class: type | None = None,
        goal_indices: Sequence[int] | None = None,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: torch.device | str = "auto",
        _init_setup_model: bool = True,
    ) -> None:
        graph_config = subgoal_settings(subgoal_class, subgoal_graph)
        explore_config = long_horizon_configs(None, explore)[1]
        has_energy = hasattr(type(self), "energy_model")  # the class's: the model is built later
        check_long_horizon(graph_config, explore_config, subgoal_class, has_energy, type(self).__name__)
        if isinstance(policy, str) and policy not in self.policy_aliases:
            raise ValueError(
                f"{type(self).__name__} takes policy 'MultiInputPolicy' (its networks plan over the Dict observation "
                f"of a goal-conditioned env), got {policy!r}. Pass 'MultiInputPolicy'."
            )
        if str(device).startswith("cuda") and not torch.cuda.is_available():
            warnings.warn(
                f"{type(self).__name__}: device={device!r} but CUDA is not available here; the agent runs on the CPU.",
                stacklevel=2,
            )
        if env is not None and not isinstance(env, str):
            check_spaces(env.observation_space, env.action_space, owner=type(self).__name__)
        super().__init__(
            policy=policy,
            env=env,
            learning_rate=learning_rate,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            device=device,
            support_multi_env=True,
            monitor_wrapper=True,
            seed=seed,
            supported_action_spaces=(spaces.Box,),
        )
        if not isinstance(horizon, int) or horizon < 1:
            raise ValueError(f"horizon must be a positive int (number of planned transitions), got {horizon!r}.")
        self.horizon = horizon
        self.online = make_config(OnlineConfig, online, "online")
        self.inverse_dynamics_kind = inverse_dynamics
        self.goal_spec: GoalSpec | None = None
        self.num_plans = 0
        self._n_updates = 0
        self._online_loop: OnlineLoopState | None = None
        # The real moves s' - s of every transition learnt from (online segments, offline datasets), periodic dims
        # wrapped: the measured step of online.threshold_units="step", the EBM's reach box, hard-negative clip and
        # move normalisation all read their scale here. Saved with the agent, so a loaded one keeps its step.
        self._moves: MoveStatistics | None = None
        self._warned_no_step = False
        self.subgoals: Any = None  # e.g. ebm_agent.subgoals.GraphSubgoals: aims each plan at subgoals(states, goals)
        self.explorer: Any = None  # e.g. ebm_agent.subgoals.FrontierSubgoals: aims the plans made while learning
        self.subgoal_class = subgoal_class
        self.subgoal_graph = graph_config
        self.explore = explore_config
        self.goal_indices = None if goal_indices is None else [int(index) for index in goal_indices]
        if _init_setup_model:
            self._setup_model()

    # ------------------------------------------------------------------ setup
    def _setup_model(self) -> None:
        """Build the networks, planner, buffers and inverse dynamics from the (possibly loaded) attributes."""
        self._setup_lr_schedule()
        self.set_random_seed(self.seed)
        self._upgrade_saved_settings()
        # A model saved before these were typed holds them as dicts (and no subgoal_class).
        self.subgoal_class = getattr(self, "subgoal_class", None)
        self.subgoal_graph = subgoal_settings(self.subgoal_class, self.subgoal_graph)
        self.explore = long_horizon_configs(None, self.explore)[1]
        if self.goal_spec is None:
            if self.env is None:
                raise ValueError(f"{type(self).__name__} needs an env to read the state/goal layout from.")
            self.goal_spec = read_goal_spec(self.env, getattr(self, "goal_indices", None))
            if self.goal_spec.goal_indices_inferred and self.verbose >= 1:
                print(
                    f"{type(self).__name__}: goal dims inferred from a reset observation: observation"
                    f"{self.goal_spec.goal_indices.tolist()} == achieved_goal (pass goal_indices=[...] to override)"
                )
        spec = self.goal_spec
        self._generator = torch.Generator(device=self.device)
        self._generator.manual_seed(self._base_seed())
        self.pos_buffer = TransitionBuffer(
            self.online.pos_buffer_size, spec.state_dim, spec.action_dim, seed=self._base_seed() + 1
        )
        self._build_model()
        self._build_inverse_dynamics()

    def _upgrade_saved_settings(self) -> dict[str, Any]:
        """Bring the settings of a model saved by an earlier version to today's configs (``load`` restores the saved
        attributes as they were pickled): ``online`` keeps only today's :class:`OnlineConfig` fields.

        :return: the saved ``online``'s fields that :class:`OnlineConfig` no longer has (moved elsewhere or
            removed), for a subclass to carry over.
        """
        if not isinstance(self.online, OnlineConfig):
            return {}
        known = {field.name for field in dataclasses.fields(OnlineConfig)}
        saved = vars(self.online)
        legacy = {name: value for name, value in saved.items() if name not in known}
        if legacy:
            self.online = OnlineConfig(**{name: getattr(self.online, name) for name in known})
        return legacy

    def _base_seed(self) -> int:
        return 0 if self.seed is None else int(self.seed)

    def _build_model(self) -> None:
        """Create ``self.policy`` (networks + optimiser) and the planner. Implemented by subclasses."""
        raise NotImplementedError

    def _build_inverse_dynamics(self) -> None:
        spec = self.goal_spec
        assert spec is not None
        kind = self._inverse_dynamics_choice()
        if kind is not None and not isinstance(kind, str):
            self.inverse_model: InverseDynamics | None = kind
            return
        fn = env_inverse_dynamics(self.env) if (kind == "ground_truth" and self.env is not None) else None
        if kind is None or (kind == "ground_truth" and fn is None):
            # No env (a model loaded for prediction only) or an env without ground truth: resolved at first use.
            self.inverse_model = None
            return
        # Learned models never see the target dims (like the energy), and start from the agent's seed.
        options: dict[str, Any] = {
            "ground_truth": {},
            "mlp": {"device": self.device, "seed": self._base_seed() + 2, "masked_dims": spec.target_indices.tolist()},
            # A small ridge: the original's 0.3 swamps systems with small action gains (the particle moves 1/20 per
            # unit action), pulling every solved action toward zero. Its random warm-up draws from the agent's seed.
            "rls": {"state_dims": spec.model_dims.tolist(), "ridge": 1e-6, "seed": self._base_seed() + 2},
            "rls_tracking": {"state_dims": spec.model_dims.tolist(), "ridge": 1e-6, "seed": self._base_seed() + 2},
        }.get(kind, {})
        self.inverse_model = make_inverse_dynamics(
            kind,
            action_low=spec.action_low,
            action_high=spec.action_high,
            state_dim=spec.state_dim,
            action_dim=spec.action_dim,
            fn=fn,
            **options,
        )

    def _inverse_dynamics_choice(self) -> str | InverseDynamics | None:
        """What ``inverse_dynamics`` stands for on the current env (None: no env yet, resolved once one is set).

        :raises ValueError: for ``"ground_truth"`` on an env that has no ``inverse_dynamics``, naming the env and
            the options.
        """
        kind = self.inverse_dynamics_kind
        if self.env is None or not (kind is None or kind == "ground_truth"):
            return kind
        if env_inverse_dynamics(self.env) is not None:
            return "ground_truth"
        name = _env_name(self.env)
        if kind == "ground_truth":
            raise ValueError(
                f"inverse_dynamics='ground_truth' takes the env's own inverse dynamics, but {name} has no "
                "`inverse_dynamics(states, next_states)` method. Choose a learned model: inverse_dynamics="
                "'rls_tracking' (recursive least squares following the plan), 'rls' or 'mlp', or leave it out (None) "
                "to get the learned default "
                f"({LEARNED_INVERSE_DYNAMICS!r})."
            )
        warnings.warn(
            f"{type(self).__name__}: {name} has no `inverse_dynamics`, so planned states become actions through a "
            f"learned inverse model: inverse_dynamics={LEARNED_INVERSE_DYNAMICS!r} (pass 'mlp' or an "
            "InverseDynamics instance to choose another).",
            stacklevel=3,
        )
        return LEARNED_INVERSE_DYNAMICS

    def _require_inverse_dynamics(self) -> InverseDynamics:
        if self.inverse_model is None:
            raise RuntimeError(
                f"{type(self).__name__} uses ground-truth inverse dynamics, which come from the env, but it has none "
                "(or the env has no `inverse_dynamics`). Pass the env: `Agent.load(path, env=env)` or "
                "`agent.set_env(env)`, or choose a learned model: inverse_dynamics='rls_tracking', 'rls' or 'mlp'."
            )
        return self.inverse_model

    def set_env(self, env: GymEnv, force_reset: bool = True) -> None:
        """Set a new env (same spaces and number of envs); re-binds ground-truth inverse dynamics to it.

        :param env: the env.
        :param force_reset: reset it before the next ``learn``.
        """
        check_spaces(env.observation_space, env.action_space, owner=type(self).__name__)
        super().set_env(env, force_reset=force_reset)
        if force_reset:
            self._online_loop = None  # the plans in flight belong to the states of the env before the reset
        if self.inverse_dynamics_kind is None or self.inverse_dynamics_kind == "ground_truth":
            self._build_inverse_dynamics()

    def _excluded_save_params(self) -> list[str]:
        return [
            *super()._excluded_save_params(),
            "pos_buffer",
            "inverse_model",
            "planner",
            "_generator",
            "subgoals",
            "explorer",
        ]

    # --------------------------------------------------------- model hooks
    def _plan(
        self,
        states: np.ndarray,
        goals: np.ndarray,
        init_plans: np.ndarray | None,
        generator: torch.Generator,
        training: bool,
        init_actions: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """Plan for a batch of envs. Implemented by subclasses.

        :param states: [n, D] current real states.
        :param goals: [n, G] desired goals.
        :param init_plans: [n, T+1, D] warm starts, or None to start from the current states.
        :param generator: the noise source.
        :param training: True inside ``learn`` (the goal/prior warm-up applies).
        :param init_actions: [n, T, A] the previous planned actions shifted alongside ``init_plans`` (NaN rows: no
            warm start or no planned actions), or None; for models that plan actions.
        :return: (plans [n, T+1, D], planned actions [n, T, A] or None (use inverse dynamics),
            mean model cost per transition [n]).
        """
        raise NotImplementedError

    def _train_on_segments(self, segments: list[Segment]) -> dict[str, float]:
        """One gradient step on finished plan segments. Implemented by subclasses.

        :param segments: the segments that ended at this env step.
        :return: scalars to log under ``train/``.
        """
        raise NotImplementedError

    # ---------------------------------------------------------------- acting
    @property
    def deterministic_episodes_repeat(self) -> bool:
        """Whether ``predict(deterministic=True)`` depends on nothing but the episode's observations.

        The planner's noise is re-seeded at each deterministic call, so it does, unless a subgoal provider is set:
        the graph's stall bookkeeping and edge penalties carry over from one episode to the next. An evaluation of
        such an agent on an env that draws no random number runs one episode for all of them
        (``eval.evaluation.repeats_exactly``).
        """
        return self.subgoals is None

    def _actions(self, states: np.ndarray, plans: np.ndarray, planned_actions: np.ndarray, steps: np.ndarray) -> np.ndarray:
        """Actions for step ``steps`` of each env's plan: planned ones, or inverse dynamics toward the next state.

        :param states: [N, D] real states.
        :param plans: [N, T+1, D].
        :param planned_actions: [N, T, A] (NaN rows where the model plans states only).
        :param steps: [N] index of the step to take.
        :return: [N, A] actions clipped to the action bounds.
        :raises ValueError: where an action is not finite (the model overflowed, e.g. on a state far outside the box).
        """
        spec = self.goal_spec
        assert spec is not None
        rows = np.arange(len(states))
        actions = planned_actions[rows, steps].copy()
        missing = np.isnan(actions).any(axis=1)
        if missing.any():
            inverse = self._require_inverse_dynamics()
            origin = states if self.online.closed_loop else plans[rows, steps]
            if isinstance(inverse, PlanFollower):  # aims at the rest of the plan, not only its next state
                ahead = [plans[row, steps[row] + 1 :] for row in rows[missing]]
                actions[missing] = inverse.follow(origin[missing], ahead)
            else:
                actions[missing] = inverse(origin[missing], plans[rows, steps + 1][missing])
        if not np.all(np.isfinite(actions)):
            raise ValueError(
                f"the actions for states {states[~np.isfinite(actions).all(axis=1)][:3].tolist()} are not finite: the "
                "model overflowed on them. Are the observations far outside the env's state box (state_low/state_high)?"
            )
        return np.clip(actions, spec.action_low, spec.action_high).astype(np.float32)

    def _explore(self, actions: np.ndarray) -> np.ndarray:
        """Replace each env's action by a uniform random one in the action bounds with probability
        ``online.random_action_prob`` (its own seeded stream, so the planner's noise is unchanged).

        :param actions: [N, A] planned actions.
        :return: [N, A] actions to take.
        """
        spec = self.goal_spec
        assert spec is not None
        rng = getattr(self, "_explore_rng", None)
        if rng is None:
            rng = self._explore_rng = np.random.default_rng(self._base_seed() + 7)
        replace = rng.random(len(actions)) < self.online.random_action_prob  # [N]
        random = rng.uniform(spec.action_low, spec.action_high, size=actions.shape).astype(actions.dtype)  # [N, A]
        return np.where(replace[:, None], random, actions)

    def _align_periodic(self, plans: np.ndarray, states: np.ndarray) -> None:
        """Move warm-start plans by whole periods of their periodic dims so that each starts next to its env's state.

        A plan may run past the wrap (0.98 -> 1.03 for a normalised angle) while the env reports the state wrapped
        (-0.97): shifted by one period the warm start stays a smooth continuation of the real state, as the
        velocity and acceleration priors expect. In place.

        :param plans: [n, T+1, D] warm starts.
        :param states: [n, D] the envs' current states.
        """
        spec = self.goal_spec
        assert spec is not None
        if spec.goal_period is None:
            return
        dims, period = spec.goal_indices, spec.goal_period
        turns = np.round((states[:, dims] - plans[:, 0, dims]) / period)  # [n, G] whole periods
        plans[:, :, dims] += (turns * period)[:, None, :].astype(plans.dtype)

    def _deviation(self, real: np.ndarray, planned: np.ndarray, reduce: str) -> np.ndarray:
        """Distance between real and planned states over the model dims (target dims excluded), in the unit of
        ``online.threshold_units`` (each dim's gap divided by its measured step with ``"step"``).

        :param real: [N, D].
        :param planned: [N, D].
        :param reduce: "max" (training rule) or "mean" (evaluation rule).
        :return: [N]; NaN with ``"step"`` units before a real move was recorded (no comparison holds).
        """
        spec = self.goal_spec
        assert spec is not None
        gap = np.abs(real - planned)  # [N, D]
        dims = spec.goal_indices
        gap[:, dims] = self._goal_gaps(real[:, dims], planned[:, dims])
        gap = (gap / self._threshold_unit())[:, spec.model_dims]
        return gap.max(axis=1) if reduce == "max" else gap.mean(axis=1)

    def _threshold_unit(self) -> np.ndarray | float:
        """What the state gaps compared with the ``online`` thresholds are divided by, per state dim.

        :return: 1.0 with ``online.threshold_units="state"``; with ``"step"``, [D] the largest real |s' - s| per dim
            recorded so far (:attr:`real_moves`; a dim that never moved takes a thousandth of the largest dim's
            step, so that moving it counts as far), or NaN before any was recorded.
        """
        if self.online.threshold_units == "state":
            return 1.0
        step = self._measured_step()
        return float("nan") if step is None else step

    def _measured_step(self) -> np.ndarray | None:
        """[D] the largest real |s' - s| per dim recorded so far (a dim that never moved takes a thousandth of the
        largest dim's step), or None before any was recorded: the unit of ``"step"`` thresholds and planner noise."""
        if self._moves is None or self._moves.count == 0:
            return None
        step = self._moves.largest.astype(np.float64)  # [D]
        floor = 1e-3 * float(step.max()) if step.max() > 0 else 1.0
        return np.maximum(step, floor)

    def _goal_gaps(self, points: np.ndarray, goals: np.ndarray) -> np.ndarray:
        """|points - goals| per goal dim; periodic goal dims (Reacher's normalised angles) the short way round the
        circle: a state that wraps from 0.99 to -0.99 has moved by 0.02, not 1.98.

        :param points: [N, G] points in the goal dims.
        :param goals: [N, G].
        :return: [N, G].
        """
        spec = self.goal_spec
        assert spec is not None
        gap = np.abs(points - goals)  # [N, G]
        if spec.goal_period is not None:
            wrapped = np.mod(gap, spec.goal_period)
            gap = np.minimum(wrapped, spec.goal_period - wrapped)
        return gap

    def _as_batch(self, observation: Any) -> tuple[dict[str, np.ndarray], bool]:
        if isinstance(observation, tuple) and len(observation) == 2 and isinstance(observation[1], dict):
            raise ValueError(
                "predict got an (obs, info) tuple: you passed the result of gymnasium's env.reset() directly. "
                "Use `obs, info = env.reset()` and pass `obs`."
            )
        if not isinstance(observation, dict) or "observation" not in observation or "desired_goal" not in observation:
            raise ValueError(
                "predict expects a goal-conditioned Dict observation with keys 'observation' and 'desired_goal' "
                f"(got {type(observation).__name__}). Wrap your env so it returns the GoalEnv dict."
            )
        spec = self.goal_spec
        assert spec is not None
        arrays = {}
        for key, dim in (("observation", spec.state_dim), ("desired_goal", spec.goal_dim)):
            raw = np.asarray(observation[key])
            if raw.dtype.kind not in "biuf":
                raise TypeError(
                    f"predict: observation[{key!r}] has dtype {raw.dtype}; pass real numbers (float32, as the env returns)."
                )
            if raw.ndim not in (1, 2):
                raise ValueError(
                    f"predict: observation[{key!r}] has shape {raw.shape}; pass one observation [{dim}] or a batch [N, {dim}]."
                )
            arrays[key] = raw.astype(np.float32)
        state, goal = arrays["observation"], arrays["desired_goal"]
        vectorized = state.ndim == 2
        state, goal = state.reshape(-1, state.shape[-1]), goal.reshape(-1, goal.shape[-1])
        if state.shape[1] != spec.state_dim or goal.shape[1] != spec.goal_dim or len(state) != len(goal):
            raise ValueError(
                f"predict: observation has shape {state.shape} and desired_goal {goal.shape}, but this model was built "
                f"for D={spec.state_dim}, G={spec.goal_dim}. Is this the env the model was trained on?"
            )
        batch = {"observation": state, "desired_goal": goal}
        check_finite_observation(batch, f"{type(self).__name__}.predict")
        self._check_goal_bounds(goal, "predict")
        return batch, vectorized

    def _check_goal_bounds(self, goal: np.ndarray, where: str) -> None:
        """Reject goals outside the state bounds that plans are clipped to: no plan could reach them.

        :param goal: [N, G] goals.
        :param where: caller name for the message.
        :raises ValueError: naming the goal and the bounds.
        """
        spec = self.goal_spec
        assert spec is not None
        if spec.state_low is None or spec.state_high is None or spec.goal_period is not None:
            return
        low, high = spec.state_low[spec.goal_indices], spec.state_high[spec.goal_indices]
        outside = ((goal < low - 1e-6) | (goal > high + 1e-6)).any(axis=1)
        if outside.any():
            raise ValueError(
                f"{where}: desired_goal {goal[outside][0].tolist()} lies outside the state bounds "
                f"[{low.tolist()}, {high.tolist()}] that plans are clipped to, so no plan can reach it. "
                "Set a goal inside the bounds."
            )

    def _fresh_generator(self, deterministic: bool) -> torch.Generator:
        if not deterministic:
            return self._generator
        # A deterministic call re-seeds the planner's noise, so the same model and observation give the same action.
        generator = torch.Generator(device=self.device)
        generator.manual_seed(self._base_seed())
        return generator

    def predict(
        self,
        observation: np.ndarray | dict[str, np.ndarray],
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """Plan (or follow the current plan) and return actions, as SB3's recurrent policies do.

        The plan is carried in ``state``: pass back the returned state on the next call and set ``episode_start``
        when an episode begins. A new plan is made for an env when it has none, its episode starts, its plan ran
        out, or the real state drifted from the plan by more than ``online.replan_threshold`` (mean over dims), or
        (with ``online.arrival_threshold``) it already reached the plan's final state (``online.arrival_at="plan_end"``)
        or the goal or subgoal the plan aimed at (``"aim"``).

        :param observation: a Dict observation, single or batched ([N, ...]).
        :param state: the state returned by the previous call (None: plan from scratch).
        :param episode_start: [N] flags for envs whose episode just began.
        :param deterministic: re-seed the planner's noise so the same model and observation give the same action.
        :return: (actions [N, A] or [A] for a single observation, the new state).
        """
        batch, vectorized = self._as_batch(observation)
        spec = self.goal_spec
        assert spec is not None
        states, goals = batch["observation"], batch["desired_goal"]
        n, horizon = len(states), self.horizon
        if state is not None and len(state) in (3, 4) and state[0].shape[:2] == (n, horizon + 1):
            plans, planned_actions, steps = (np.array(s, copy=True) for s in state[:3])
            steps = steps.astype(np.int64)
            # A state from before the aims were kept (three arrays) has none: its plans count as aimed at the goals.
            aims = np.array(state[3], dtype=np.float32, copy=True) if len(state) == 4 else goals.astype(np.float32)
        else:
            plans = np.zeros((n, horizon + 1, spec.state_dim), dtype=np.float32)
            planned_actions = np.full((n, horizon, spec.action_dim), np.nan, dtype=np.float32)
            steps = np.full(n, horizon, dtype=np.int64)
            aims = goals.astype(np.float32)  # [N, G] the goal or subgoal each plan was made for
        need = steps >= horizon
        if episode_start is not None:
            need |= np.asarray(episode_start, dtype=bool).reshape(-1)
        has_plan = ~need
        if has_plan.any() and self.online.threshold_units == "step" and self._moves is None and not self._warned_no_step:
            self._warned_no_step = True
            warnings.warn(
                f"{type(self).__name__}.predict: online.threshold_units='step' but no real move was recorded yet (the "
                "agent learnt nothing), so there is no measured step: plans run their course without the drift and "
                "arrival replans. learn() or learn_offline() measures it.",
                stacklevel=2,
            )
        if has_plan.any():
            idx = np.where(has_plan)[0]
            drift = self._deviation(states[idx], plans[idx, steps[idx]], reduce="mean")
            # replan_threshold 0: a new plan at every step (receding-horizon MPC), whatever the drift
            need[idx[(drift > self.online.replan_threshold) | (self.online.replan_threshold == 0)]] = True
            if self.online.arrival_threshold is not None:  # arrived: the rest of the plan would only hover
                if self.online.arrival_at == "aim":
                    unit = np.broadcast_to(self._threshold_unit(), (spec.state_dim,))[spec.goal_indices]  # [G]
                    left = (self._goal_gaps(states[idx][:, spec.goal_indices], aims[idx]) / unit).max(axis=1)  # [K]
                else:
                    left = self._deviation(states[idx], plans[idx, horizon], reduce="max")  # [K]
                need[idx[left <= self.online.arrival_threshold]] = True
        if need.any():
            aims[need] = self._plan_goals(states[need], goals[need])
            new_plans, new_actions, _ = self._plan(
                states[need], aims[need], None, self._fresh_generator(deterministic), training=False
            )
            plans[need] = new_plans
            planned_actions[need] = np.nan if new_actions is None else new_actions
            steps[need] = 0
        actions = self._actions(states, plans, planned_actions, steps)
        new_state = (plans, planned_actions, steps + 1, aims)
        return (actions if vectorized else actions[0]), new_state

    # -------------------------------------------------------------- learning
    def learn(
        self: SelfPlannerAgent,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 10,
        tb_log_name: str | None = None,
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfPlannerAgent:
        """Learn the model online (Algorithm 1): plan, act until the real states deviate, train, repeat.

        Stops at exactly ``total_timesteps`` transitions (summed over envs); a budget that is not a multiple of
        ``n_envs`` is rounded down to one, with a warning.

        :param total_timesteps: number of environment transitions to consume.
        :param callback: SB3 callback(s), called once per (vectorised) env step.
        :param log_interval: finished episodes between log dumps.
        :param tb_log_name: TensorBoard run name (default: the agent's name).
        :param reset_num_timesteps: restart the step counter (False continues the TensorBoard curve).
        :param progress_bar: show SB3's progress bar.
        :return: self.

        With ``explore``, the plans made while learning explore the frontier of a graph over the replay buffer, rebuilt
        every ``explore["every"]`` transitions; with ``subgoal_graph``, the graph over the replay buffer aims the
        plans of ``predict`` afterwards (:meth:`build_subgoals`).
        """
        if not isinstance(total_timesteps, (int, np.integer)) or total_timesteps < 0:
            raise ValueError(f"total_timesteps must be a non-negative int, got {total_timesteps!r}.")
        if self.env is None:
            raise ValueError("learn() needs an env: pass it to the constructor, to load(path, env=...), or set_env().")
        if total_timesteps % self.n_envs != 0:
            kept = int(total_timesteps) - int(total_timesteps) % self.n_envs
            warnings.warn(
                f"total_timesteps={total_timesteps} is not a multiple of n_envs={self.n_envs}: every env step consumes "
                f"{self.n_envs} transitions, so learn consumes {kept}, the largest multiple not above the budget "
                "(never more than it).",
                stacklevel=2,
            )
            total_timesteps = kept
        if self.num_timesteps > 0 and len(self.pos_buffer) == 0:
            warnings.warn(
                f"{type(self).__name__}.learn after load(): the agent has learned {self.num_timesteps} transitions but "
                "its replay buffers start empty (a saved model keeps the networks, not the data). To go on exactly "
                "where training stopped, save with save_checkpoint(path) and resume with load_checkpoint(path, env=...).",
                stacklevel=2,
            )
        if reset_num_timesteps or self._last_obs is None:
            self._online_loop = None  # SB3 resets the env: no plan in flight survives that
        if self.explore is not None:
            others = [] if callback is None else list(callback) if isinstance(callback, list) else [callback]
            rebuild = FrontierRebuild(self.explore.every)
            callback = CallbackList([rebuild, *(c if isinstance(c, BaseCallback) else ConvertCallback(c) for c in others)])
        total, callback = self._setup_learn(
            int(total_timesteps), callback, reset_num_timesteps, tb_log_name or self.default_tb_log_name, progress_bar
        )
        try:
            callback.on_training_start(locals(), globals())
            self._run_online(total, callback, log_interval)
            callback.on_training_end()
        finally:
            self.explorer = None  # exploring ends with learn
        if self.subgoal_graph is not None and len(self.pos_buffer) > 0:
            real = self.pos_buffer.contents()
            self.build_subgoals(real.states, real.next_states)
        return self

    def build_frontier(self) -> FrontierSubgoals | None:
        """Rebuild the graph over the replay buffer and explore its frontier (``explore``'s settings) in the plans made
        while learning; the counts of plans per cell carry over from the previous frontier. With ``subgoal_graph``,
        the same graph also aims the plans of ``predict`` (the evaluations made during ``learn``).

        :return: the frontier, also ``self.explorer``; None while the buffer is empty.
        """
        if len(self.pos_buffer) == 0:
            return None
        settings = self.explore or ExploreConfig()
        real = self.pos_buffer.contents()
        graph = self._make_subgoals(real.states, real.next_states)
        assert isinstance(graph, GraphSubgoals)  # explore needs a graph (checked at construction)
        counts = self.explorer.plan_counts if isinstance(self.explorer, FrontierSubgoals) else {}
        self.explorer = FrontierSubgoals(
            graph, float(settings.goal_heuristic), float(settings.revisit_cost), plan_counts=counts
        )
        if self.subgoal_graph is not None:
            self.subgoals = graph
        self.logger.record("explore/frontiers", self.explorer.num_frontiers)
        self.logger.record("explore/graph_nodes", len(graph.nodes))
        return self.explorer

    def build_subgoals(self, states: np.ndarray, next_states: np.ndarray) -> Any:
        """Build the subgoals (``subgoal_class`` with ``subgoal_graph``'s settings, or the defaults) over real
        transitions and use them.

        :param states: [M, D] real states.
        :param next_states: [M, D] their real next states.
        :return: the subgoal provider (a :class:`~ebm_agent.subgoals.GraphSubgoals` by default), also
            ``self.subgoals``.
        """
        self.subgoals = self._make_subgoals(states, next_states)
        return self.subgoals

    def _make_subgoals(self, states: np.ndarray, next_states: np.ndarray) -> Any:
        """``subgoal_class.from_transitions`` over real transitions, from what the agent learned: its goal dims,
        horizon (the default lookahead), energy (``energy_model``, None for an agent without one) and state periods,
        never the agent itself."""
        assert self.goal_spec is not None
        settings = self.subgoal_graph
        kwargs = {} if settings is None else settings.kwargs() if isinstance(settings, SubgoalGraphConfig) else dict(settings)
        if kwargs.get("lookahead") is None:
            kwargs["lookahead"] = self.horizon
        builder: Any = GraphSubgoals if self.subgoal_class is None else self.subgoal_class
        states = np.asarray(states, dtype=np.float32)  # [M, D]
        return builder.from_transitions(
            states,
            np.asarray(next_states, dtype=np.float32),
            goal_indices=list(self.goal_spec.goal_indices),
            energy=getattr(self, "energy_model", None),
            period=state_periods(self.goal_spec, states.shape[1]),
            **kwargs,
        )

    def _run_online(self, total_timesteps: int, callback: BaseCallback, log_interval: int) -> None:
        env = self.env
        spec = self.goal_spec
        assert env is not None and spec is not None and self._last_obs is not None
        n, horizon = env.num_envs, self.horizon
        loop = getattr(self, "_online_loop", None)  # a model saved before the loop state existed has none
        if loop is None or not loop.fits(n, horizon, spec.state_dim, spec.action_dim):
            loop = OnlineLoopState.fresh(n, horizon, spec.state_dim, spec.action_dim, self._episode_num)
        self._online_loop = loop
        # The loop updates these arrays and lists in place, so the agent always holds where it stands.
        plans, planned_actions, plan_cost, steps = loop.plans, loop.planned_actions, loop.plan_cost, loop.steps
        need, warm, shift, executed = loop.need, loop.warm, loop.shift, loop.executed
        while self.num_timesteps < total_timesteps:
            obs = self._last_obs
            assert isinstance(obs, dict)
            check_finite_observation(obs, f"{type(self).__name__}.learn")
            states = np.asarray(obs["observation"], dtype=np.float32)
            goals = np.asarray(obs["desired_goal"], dtype=np.float32)
            self._check_goal_bounds(goals, f"{type(self).__name__}.learn")
            if need.any():
                self._plan_needed(np.where(need)[0], states, goals, loop)
                idx = np.where(need)[0]
                goal_gap = self._goal_gaps(plans[idx, -1][:, spec.goal_indices], goals[idx]).sum(axis=1)  # [n]
                self.logger.record_mean("plan/goal_dist", float(goal_gap.mean()))
                steps[idx], need[idx] = 0, False
                self.num_plans += len(idx)
            actions = self._actions(states, plans, planned_actions, steps)
            if self.online.random_action_prob > 0:
                actions = self._explore(actions)
            new_obs, rewards, dones, infos = env.step(actions)
            self.num_timesteps += n
            real_next = np.asarray(new_obs["observation"], dtype=np.float32).copy()  # type: ignore[call-overload,index]
            for i in np.where(dones)[0]:
                # The VecEnv already reset this env: the true last state is in terminal_observation, never the
                # next episode's first state (that pair would teach the model a teleport).
                real_next[i] = infos[i]["terminal_observation"]["observation"]
            rows = np.arange(n)
            deviation = self._deviation(real_next, plans[rows, steps + 1], reduce="max")
            for i in range(n):
                executed[i].append((states[i], real_next[i], actions[i]))
            steps += 1
            # deviation_threshold 0: every segment is one step (a new plan from the real state at every step)
            ended = (steps >= horizon) | dones | (deviation > self.online.deviation_threshold)
            ended |= self.online.deviation_threshold == 0
            segments = []
            for i in np.where(ended)[0]:
                seg_states, seg_next, seg_actions = (np.stack(col) for col in zip(*executed[i]))
                segments.append(Segment(plans[i, : steps[i] + 1].copy(), seg_states, seg_next, seg_actions))
                executed[i] = []
                # Warm-start the next plan from this one unless the episode ended or the plan looked poor to the
                # model (the original's re-initialisation rule, train.py:583-591).
                warm[i] = (not dones[i]) and plan_cost[i] <= self.online.reinit_energy
                shift[i], need[i] = steps[i], True
            if segments:
                fresh = self._fresh_positives(segments)  # before training: the hard-negative clip reads their moves
                self._record_real_moves(fresh.states, fresh.next_states)
                stats = self._train_on_segments(segments)
                self._n_updates += 1
                for key, value in stats.items():
                    self.logger.record_mean(f"train/{key}", value)
            self._update_info_buffer(infos, dones)
            self._episode_num += int(np.sum(dones))
            self._last_obs = new_obs  # type: ignore[assignment]
            self._last_episode_starts = dones
            self._update_current_progress_remaining(self.num_timesteps, total_timesteps)
            callback.update_locals(locals())
            if not callback.on_step():
                break
            if log_interval and self._episode_num - loop.episodes_at_dump >= log_interval:
                loop.episodes_at_dump = self._episode_num
                self.dump_logs()
        self.dump_logs()

    def _plan_needed(self, idx: np.ndarray, states: np.ndarray, goals: np.ndarray, loop: OnlineLoopState) -> None:
        """Make new plans for the envs ``idx`` during ``learn``, warm-started where the loop says so; in place.

        Warm starts are the previous plans (and planned actions) shifted by the steps executed. When the model's
        planner spends a different budget on warm-started plans (:meth:`_warm_plans_apart`), the warm and the fresh
        envs are planned in two calls, so that each gets its own budget; otherwise in one call, as the original.

        :param idx: [m] the envs that need a plan.
        :param states: [N, D] all envs' current states.
        :param goals: [N, G] their goals.
        :param loop: the loop state whose ``plans``, ``planned_actions`` and ``plan_cost`` receive the new plans.
        """
        warm = loop.warm[idx]
        groups = [idx[warm], idx[~warm]] if (self._warm_plans_apart() and warm.any() and not warm.all()) else [idx]
        for group in groups:
            init = init_actions = None
            if loop.warm[group].any():
                cold = ~loop.warm[group]
                shift = torch.from_numpy(loop.shift[group])
                init = shift_plan(torch.from_numpy(loop.plans[group]), shift).numpy()  # [m, T+1, D]
                init[cold] = states[group][cold, None, :]
                self._align_periodic(init, states[group])
                init_actions = shift_plan(torch.from_numpy(loop.planned_actions[group]), shift).numpy()  # [m, T, A]
                init_actions[cold] = np.nan
            start = time.perf_counter()
            new_plans, new_actions, cost = self._plan(
                states[group],
                self._plan_goals(states[group], goals[group], training=True),
                init,
                self._generator,
                training=True,
                init_actions=init_actions,
            )
            self.logger.record_mean("plan/ms", 1000.0 * (time.perf_counter() - start) / len(group))
            loop.plans[group], loop.plan_cost[group] = new_plans, cost
            loop.planned_actions[group] = np.nan if new_actions is None else new_actions

    def _plan_goals(self, states: np.ndarray, goals: np.ndarray, training: bool = False) -> np.ndarray:
        """The goals the plans aim at: ``subgoals.subgoals(states, goals)`` where a subgoal provider is set (long-horizon
        goal reaching, :mod:`ebm_agent.subgoals`), else the goals themselves; while learning, the ``explorer``'s where
        one is set (exploration, e.g. :class:`~ebm_agent.subgoals.FrontierSubgoals`).

        :param states: [n, D] current states.
        :param goals: [n, G] their goals.
        :param training: True for the plans made inside ``learn`` (not those of ``predict``, evaluations included).
        :return: [n, G].
        """
        provider = self.explorer if (training and self.explorer is not None) else self.subgoals
        return goals if provider is None else provider.subgoals(states, goals)

    def _warm_plans_apart(self) -> bool:
        """Whether warm-started and fresh plans get different planning budgets (then they are planned apart).

        :return: True when the model's ``planner_config`` sets a warm-start budget other than its fresh one.
        """
        config: Any = getattr(self, "planner_config", None)
        fresh, warm = learn_budgets(config)
        return warm is not None and warm != (config.iterations if fresh is None else fresh)

    def dump_logs(self) -> None:
        """Write SB3's ``rollout/*`` and ``time/*`` keys plus the agent's own, then dump the logger."""
        elapsed = max((time.time_ns() - self.start_time) / 1e9, 1e-9)
        fps = int((self.num_timesteps - self._num_timesteps_at_start) / elapsed)
        if self.ep_info_buffer:
            self.logger.record("rollout/ep_rew_mean", safe_mean([ep["r"] for ep in self.ep_info_buffer]))
            self.logger.record("rollout/ep_len_mean", safe_mean([ep["l"] for ep in self.ep_info_buffer]))
        if self.ep_success_buffer:
            self.logger.record("rollout/success_rate", safe_mean(self.ep_success_buffer))
        self.logger.record("time/fps", fps)
        self.logger.record("time/episodes", self._episode_num, exclude="tensorboard")
        self.logger.record("time/time_elapsed", int(elapsed), exclude="tensorboard")
        self.logger.record("time/total_timesteps", self.num_timesteps, exclude="tensorboard")
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("plan/num_plans", self.num_plans)
        self.logger.dump(step=self.num_timesteps)

    def learn_offline(
        self: SelfPlannerAgent,
        dataset: TransitionDataset,
        epochs: int = 10,
        batch_size: int = 256,
        sequential: bool = False,
        log_interval: int = 1,
        tb_log_name: str | None = None,
    ) -> SelfPlannerAgent:
        """Pretrain the model on a fixed dataset of transitions (the paper's "pretrained" setting, Sec. 4.2).

        :param dataset: the transitions (e.g. from :func:`~ebm_agent.datasets.collect_random_transitions`).
        :param epochs: passes over the dataset (10 as the original).
        :param batch_size: transitions per gradient step (256).
        :param sequential: contiguous, correlated minibatches (the "directed + sequential" ablation).
        :param log_interval: epochs between log dumps.
        :param tb_log_name: TensorBoard run name (default: the agent's name + "_offline").
        :return: self.
        """
        spec = self.goal_spec
        assert spec is not None
        if len(dataset) == 0:
            raise ValueError("learn_offline got an empty dataset.")
        if dataset.states.shape[1] != spec.state_dim or dataset.actions.shape[1] != spec.action_dim:
            raise ValueError(
                f"The dataset has states of {dataset.states.shape[1]} dims and actions of {dataset.actions.shape[1]}, "
                f"the model expects D={spec.state_dim}, A={spec.action_dim}: was it collected on another env?"
            )
        if not self._custom_logger:
            name = tb_log_name or f"{self.default_tb_log_name}_offline"
            self._logger = configure_logger(self.verbose, self.tensorboard_log, name, True)
        self._record_real_moves(dataset.states, dataset.next_states)
        rng = np.random.default_rng(self._base_seed())
        start = time.perf_counter()
        for epoch in range(epochs):
            for index in iterate_minibatches(dataset, batch_size, rng, sequential=sequential):
                stats = self._offline_step(dataset.states[index], dataset.next_states[index], dataset.actions[index])
                self._n_updates += 1
                for key, value in stats.items():
                    self.logger.record_mean(f"train/{key}", value)
            if log_interval and (epoch + 1) % log_interval == 0:
                self.logger.record("train/epoch", epoch + 1)
                self.logger.record("time/time_elapsed", int(time.perf_counter() - start), exclude="tensorboard")
                self.logger.dump(step=self._n_updates)
        if self.subgoal_graph is not None:
            self.build_subgoals(dataset.states, dataset.next_states)
        return self

    @property
    def real_moves(self) -> MoveStatistics:
        """The statistics of the real moves s' - s of every transition learnt from (periodic dims wrapped).

        :raises RuntimeError: before any transition was learnt from.
        """
        if self._moves is None:
            raise RuntimeError("no real transition recorded yet: learn() or learn_offline() records them.")
        return self._moves

    def _record_real_moves(self, states: np.ndarray, next_states: np.ndarray) -> None:
        """Add real transitions ([P, D] each) to :attr:`real_moves`."""
        if self._moves is None:
            self._moves = MoveStatistics(state_periods(self.goal_spec, np.asarray(states).shape[1]))
        self._moves.update(states, next_states)

    def _offline_step(self, states: np.ndarray, next_states: np.ndarray, actions: np.ndarray) -> dict[str, float]:
        """One gradient step on a minibatch of dataset transitions ([B, D], [B, D], [B, A]). Implemented by subclasses."""
        raise NotImplementedError

    def _replay_positives(self, fresh: TransitionBatch) -> TransitionBatch:
        """Fresh real transitions plus as many replayed ones (the original's 50/50 positive batch), then store them.

        :param fresh: the real transitions of the finished segments.
        :return: the positive batch.
        """
        batch = fresh
        if self.online.replay_positives and len(self.pos_buffer) > len(fresh.states):
            replay = self.pos_buffer.sample(len(fresh.states))
            assert fresh.actions is not None and replay.actions is not None
            batch = TransitionBatch(
                np.concatenate([fresh.states, replay.states]),
                np.concatenate([fresh.next_states, replay.next_states]),
                np.concatenate([fresh.actions, replay.actions]),
            )
        self.pos_buffer.add(fresh.states, fresh.next_states, fresh.actions)
        return batch

    @staticmethod
    def _fresh_positives(segments: list[Segment]) -> TransitionBatch:
        return TransitionBatch(
            np.concatenate([s.real_states for s in segments]),
            np.concatenate([s.real_next_states for s in segments]),
            np.concatenate([s.actions for s in segments]),
        )
