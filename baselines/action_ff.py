"""Action FF: the paper's action-conditioned feed-forward baseline, with the same API and online loop as the EBM agent."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, ClassVar

import numpy as np
import torch
from stable_baselines3.common.type_aliases import GymEnv
from torch import Tensor, nn

from baselines.action_planner import ActionPlanner, ActionPlannerConfig
from ebm_agent.base import PlannerAgentBase, Segment
from ebm_agent.config import OnlineConfig, learn_budgets, make_config, planner_horizon
from ebm_agent.costs import wrap_difference
from ebm_agent.energy import EnergyConfig, PeriodicFeatures
from ebm_agent.fast_mlp import WorkspaceMLP
from ebm_agent.inverse_dynamics import InverseDynamics
from ebm_agent.networks import build_mlp
from ebm_agent.policy import PlanningPolicy
from ebm_agent.subgoals import ExploreConfig, SubgoalGraphConfig


class ForwardDynamicsModel(nn.Module):
    """Deterministic f(s, a) -> s' on the energy model's trunk (same width, depth and activation).

    :param state_dim: D.
    :param action_dim: A.
    :param config: the trunk's architecture (an :class:`~ebm_agent.energy.EnergyConfig`; its output options are
        ignored). With ``periodic_inputs`` the periodic dims enter as (sin, cos), as the energy's do.
    :param masked_dims: target dims: zeroed in the input and copied unchanged to the prediction.
    :param residual: predict s' = s + f(s, a) (True, the agent's default) or s' = f(s, a) as the original (False).
    :param periodic_dims: periodic state dims (angles); their prediction errors are measured the short way round
        (:meth:`error`).
    :param period: their period.
    :param standardize_outputs: the network predicts each dim of its target (the change s' - s, or s' without
        ``residual``) in units of that dim's running mean and std over the transitions trained on
        (:meth:`observe_transitions`, :meth:`output_scale`), and is trained on the standardized errors, so that dims
        whose changes are small are fitted as closely as those whose changes are large.
    """

    def __init__(
        self,
        state_dim: int,
        action_dim: int,
        config: EnergyConfig | None = None,
        masked_dims: Sequence[int] = (),
        residual: bool = True,
        periodic_dims: Sequence[int] = (),
        period: float = 2.0,
        standardize_outputs: bool = False,
    ) -> None:
        super().__init__()
        cfg = config or EnergyConfig()
        self.state_dim, self.action_dim, self.residual = state_dim, action_dim, residual
        self.periodic_dims, self.period = tuple(periodic_dims), float(period)
        periodic = self.periodic_dims if cfg.periodic_inputs else ()
        self.features = PeriodicFeatures(state_dim, periodic, period) if periodic else None
        feature_dim = state_dim if self.features is None else self.features.feature_dim
        self.net = build_mlp(
            feature_dim + action_dim,
            state_dim,
            hidden_dim=cfg.hidden_dim,
            num_hidden_layers=cfg.num_hidden_layers,
            activation=cfg.activation,
            spectral_norm=cfg.spectral_norm,
        )
        keep = torch.ones(state_dim)
        keep[list(masked_dims)] = 0.0
        self.keep: Tensor
        self.register_buffer("keep", keep)  # [D] 1 for modelled dims, 0 for target dims
        self.standardize_outputs = standardize_outputs
        if standardize_outputs:  # running count, mean and sum of squared deviations of the targets (float64)
            self.target_count: Tensor
            self.target_mean: Tensor
            self.target_m2: Tensor
            self.register_buffer("target_count", torch.zeros((), dtype=torch.float64))  # []
            self.register_buffer("target_mean", torch.zeros(state_dim, dtype=torch.float64))  # [D]
            self.register_buffer("target_m2", torch.zeros(state_dim, dtype=torch.float64))  # [D]

    def forward(self, states: Tensor, actions: Tensor) -> Tensor:
        """Predict next states.

        :param states: [..., D].
        :param actions: [..., A].
        :return: [..., D].
        """
        output = self.net(torch.cat([self._inputs(states), actions], dim=-1))
        if self.standardize_outputs:
            scale, shift = self.output_scale()
            output = output * scale + shift
        predicted = states + output if self.residual else output
        # Target dims are constants of the episode: copy them rather than predict them.
        return self.keep * predicted + (1.0 - self.keep) * states

    def _inputs(self, states: Tensor) -> Tensor:
        """[..., D] states -> [..., F] network inputs (target dims zeroed, periodic dims on the circle)."""
        masked = states * self.keep
        return masked if self.features is None else self.features(masked)

    def error(self, predicted: Tensor, next_states: Tensor) -> Tensor:
        """
        Prediction error, periodic dims wrapped into [-period/2, period/2) (0.99 predicted for -0.99 is off by 0.02).

        :param predicted: [..., D] predictions.
        :param next_states: [..., D] real next states.
        :return: [..., D] errors.
        """
        difference = predicted - next_states
        if not self.periodic_dims:
            return difference
        dims = list(self.periodic_dims)
        wrapped = difference.clone()
        wrapped[..., dims] = wrap_difference(difference[..., dims], self.period)
        return wrapped

    @torch.no_grad()
    def observe_transitions(self, states: Tensor, next_states: Tensor) -> None:
        """Fold a batch of training targets into the running statistics (exactly, as if fed one by one).

        :param states: [B, D] s.
        :param next_states: [B, D] s'; the target is s' - s (periodic dims wrapped, as :meth:`error` gives them)
            with ``residual``, else s'.
        :raises RuntimeError: when the model was built without ``standardize_outputs``.
        """
        if not self.standardize_outputs:
            raise RuntimeError("ForwardDynamicsModel keeps target statistics only with standardize_outputs=True.")
        targets = self.error(next_states, states) if self.residual else next_states
        batch = targets.detach().to(torch.float64).reshape(-1, self.state_dim)  # [B, D]
        count = float(batch.shape[0])
        if count == 0:
            return
        batch_mean = batch.mean(dim=0)  # [D]
        batch_m2 = ((batch - batch_mean) ** 2).sum(dim=0)  # [D]
        total = self.target_count + count
        delta = batch_mean - self.target_mean  # [D]
        self.target_mean += delta * (count / total)
        self.target_m2 += batch_m2 + delta**2 * (self.target_count * count / total)
        self.target_count.copy_(total)

    def output_scale(self, floor: float = 1e-6) -> tuple[Tensor, Tensor]:
        """The std and mean of each dim's target so far: the network's output is ``target = output * std + mean``.

        :param floor: smallest std used (a dim that never changed, such as a target dim, gets this one).
        :return: (std [D], mean [D]) in the model's dtype; (ones, zeros) before two transitions were observed.
        :raises RuntimeError: when the model was built without ``standardize_outputs``.
        """
        if not self.standardize_outputs:
            raise RuntimeError("ForwardDynamicsModel has an output scale only with standardize_outputs=True.")
        if self.target_count.item() < 2:
            return torch.ones_like(self.keep), torch.zeros_like(self.keep)
        std = (self.target_m2 / self.target_count).sqrt().clamp_min(floor)  # [D]
        return std.to(self.keep.dtype), self.target_mean.to(self.keep.dtype)

    def inference_evaluator(self) -> Callable[[Tensor, Tensor], Tensor] | None:
        """
        This model as a gradient-free callable on a weight snapshot with reused buffers (the EBM planner's fast path,
        ``ebm_agent.fast_mlp``), so that both planners run their networks on the same kernels.

        :return: ``f(states [..., D], actions [..., A]) -> [..., D]``, or None when the network cannot be evaluated so.
        """
        network = WorkspaceMLP.from_sequential(self.net)
        if network is None:
            return None
        keep, residual, features = self.keep, self.residual, self._inputs
        scale = self.output_scale() if self.standardize_outputs else None  # a snapshot, as the weights are

        def predict(states: Tensor, actions: Tensor) -> Tensor:
            inputs = torch.cat([features(states), actions], dim=-1)  # [..., F + A]
            output = network(inputs.reshape(-1, inputs.shape[-1])).reshape(states.shape)
            if scale is not None:
                output = output * scale[0] + scale[1]
            predicted = states + output if residual else output
            return keep * predicted + (1.0 - keep) * states

        return predict


class ActionFFAgent(PlannerAgentBase):
    """The Action FF baseline: a learned f(s, a) -> s', planned through by MPPI over action sequences.

    It shares the EBM agent's online loop (plan, act until the real states deviate from the predicted ones, train
    on the real transitions with the same replay and the same step accounting), so the two differ only in the model
    and the planner. Trained by MSE to the real next state.

    :param policy: ``"MultiInputPolicy"``.
    :param env: a goal-conditioned env, its id, or a VecEnv.
    :param learning_rate: Adam learning rate (1e-3, beta1 = 0 as the original's main optimiser).
    :param horizon: T, planned actions; None: the planner's (``planner_config.horizon``, 10 by default), which the
        agent reads back as ``self.horizon``.
    :param planner_config: :class:`~baselines.action_planner.ActionPlannerConfig` or a dict of its fields (the agent
        plans with a copy).
    :param network: the trunk's :class:`~ebm_agent.energy.EnergyConfig` (same as the EBM's by default).
    :param residual: predict the state change s' - s (default) instead of the absolute next state (the original's,
        ``False``); with absolute predictions the one-step errors on random data are a sizeable part of a move
        (docs/baselines.md).
    :param clip_sigma: the original Adam's per-element gradient clip; None for plain Adam.
    :param online: :class:`~ebm_agent.config.OnlineConfig` or a dict of its fields.
    :param inverse_dynamics: unused for acting (the plan has actions); kept for API symmetry.
    :param standardize_outputs: predict each state dim's change (or next state without ``residual``) in units of
        its running mean and std over the transitions trained on, and train on the standardized errors (the default);
        False is the original's plain MSE on raw dims, in which the dims with the largest changes (the Sawyer's joint
        velocities) drown the others (docs/baselines.md, 'Standardized outputs'). ``None`` (only from ``load``)
        stands for a model saved before this option existed, which was trained without it.
    :param subgoal_graph: graph subgoals (:class:`~ebm_agent.base.PlannerAgentBase`); Action FF has no energy, so
        its graph's edges must be the moves it made (``{"edges": "real"}``). None (the default): plans aim at the goal.
    :param explore: frontier exploration during ``learn`` (:class:`~ebm_agent.base.PlannerAgentBase`); None: none.
    :param subgoal_class: the subgoal provider built with ``subgoal_graph``'s keywords
        (:class:`~ebm_agent.base.PlannerAgentBase`; it gets no energy); None: :class:`~ebm_agent.subgoals.GraphSubgoals`.
    :param goal_indices: the observation dims that ``achieved_goal`` copies (None: the env's ``goal_indices``, else
        inferred from a reset observation and printed with ``verbose >= 1``; ``goal_spec.goal_indices`` holds them).
    :param stats_window_size: episodes averaged for ``rollout/*``.
    :param tensorboard_log: TensorBoard folder.
    :param verbose: verbosity.
    :param seed: seed.
    :param device: torch device.
    """

    default_tb_log_name: ClassVar[str] = "ActionFF"

    def __init__(
        self,
        policy: str | type[PlanningPolicy],
        env: GymEnv | str | None,
        learning_rate: float = 1e-3,
        horizon: int | None = None,
        planner_config: ActionPlannerConfig | dict[str, Any] | None = None,
        network: EnergyConfig | dict[str, Any] | None = None,
        residual: bool = True,
        clip_sigma: float | None = 3.0,
        online: OnlineConfig | dict[str, Any] | None = None,
        inverse_dynamics: str | InverseDynamics | None = None,
        standardize_outputs: bool | None = True,
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
        self.planner_config = planner_horizon(make_config(ActionPlannerConfig, planner_config, "planner_config"), horizon)
        horizon = self.planner_config.horizon
        self.network_config = make_config(EnergyConfig, network, "network")
        self.residual = residual
        self.clip_sigma = clip_sigma
        # SB3's load builds the agent with _init_setup_model=False and then sets the saved attributes: a model saved
        # before this option existed has none, and None marks it (it was trained without).
        self.standardize_outputs = standardize_outputs if _init_setup_model else None
        super().__init__(
            policy,
            env,
            learning_rate=learning_rate,
            horizon=horizon,
            online=online,
            inverse_dynamics=inverse_dynamics,
            subgoal_graph=subgoal_graph,
            explore=explore,
            subgoal_class=subgoal_class,
            goal_indices=goal_indices,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            seed=seed,
            device=device,
            _init_setup_model=False,
        )
        if _init_setup_model:
            self._setup_model()

    @property
    def dynamics_model(self) -> ForwardDynamicsModel:
        """The learned forward model f(s, a) -> s'."""
        model = self.policy.network("dynamics")
        assert isinstance(model, ForwardDynamicsModel)
        return model

    def _build_model(self) -> None:
        if self.standardize_outputs is None:  # loaded from a file saved before the option existed
            self.standardize_outputs = False
        spec = self.goal_spec
        assert spec is not None
        dynamics = ForwardDynamicsModel(
            spec.state_dim,
            spec.action_dim,
            self.network_config,
            spec.target_indices.tolist(),
            self.residual,
            periodic_dims=spec.goal_indices.tolist() if spec.goal_period is not None else (),
            period=spec.goal_period or 2.0,
            standardize_outputs=bool(self.standardize_outputs),
        )
        self.policy = PlanningPolicy(
            self.observation_space,
            self.action_space,
            networks={"dynamics": dynamics},
            learning_rate=self.lr_schedule(1.0),
            clip_sigma=self.clip_sigma,
        ).to(self.device)
        self.planner = ActionPlanner(
            self.planner_config, spec.action_low, spec.action_high, spec.goal_indices, device=self.device
        )

    def _plan(
        self,
        states: np.ndarray,
        goals: np.ndarray,
        init_plans: np.ndarray | None,
        generator: torch.Generator,
        training: bool,
        init_actions: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        # Action plans warm-start from the previous actions, shifted (config.warm_iterations), never from the state
        # plan; without a warm-start budget they start from zero each time, as the original.
        self.policy.set_training_mode(False)
        start = torch.as_tensor(states, device=self.device)  # [n, D]
        goal = torch.as_tensor(goals, device=self.device)  # [n, G]
        init = None if init_actions is None else torch.as_tensor(init_actions, device=self.device)  # [n, T, A]
        iterations = learn_budgets(self.planner_config)[0] if (training and init is None) else None
        predicted, actions, distance = self.planner.plan(
            self.dynamics_model, start, goal, generator, iterations=iterations, init_actions=init
        )
        return predicted.cpu().numpy(), actions.cpu().numpy(), distance.cpu().numpy()

    def _mse_step(self, states: np.ndarray, next_states: np.ndarray, actions: np.ndarray) -> dict[str, float]:
        """One MSE gradient step of f(s, a) toward s' (on standardized targets with ``standardize_outputs``).

        :param states: [B, D].
        :param next_states: [B, D].
        :param actions: [B, A].
        :return: ``{"loss": ...}`` (the loss minimised), with ``standardize_outputs`` also ``{"mse": ...}`` (raw).
        :raises FloatingPointError: on a non-finite loss (no update applied).
        """
        self.policy.set_training_mode(True)
        model = self.dynamics_model
        as_tensor = lambda array: torch.as_tensor(array, device=self.device)  # noqa: E731
        start, target = as_tensor(states), as_tensor(next_states)  # [B, D]
        stats: dict[str, float] = {}
        if model.standardize_outputs:
            model.observe_transitions(start, target)  # the batch counts before its own step
        squared = model.error(model(start, as_tensor(actions)), target) ** 2  # [B, D]
        if model.standardize_outputs:
            stats["mse"] = float(squared.detach().mean().item())
            loss = (squared / model.output_scale()[0] ** 2).mean()  # the error in units of each dim's std
        else:
            loss = squared.mean()
        if not torch.isfinite(loss):
            raise FloatingPointError(
                f"The forward model diverged (loss={loss.item()}) at update {self._n_updates}; no update was applied."
            )
        optimizer = self.policy.optimizer
        assert optimizer is not None
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        return {"loss": float(loss.item()), **stats}

    def _train_on_segments(self, segments: list[Segment]) -> dict[str, float]:
        positives = self._replay_positives(self._fresh_positives(segments))
        assert positives.actions is not None
        if not self.online.train_every_plan:
            return {}  # the untrained control: the buffer fills, the model stays as initialised
        return self._mse_step(positives.states, positives.next_states, positives.actions)

    def _offline_step(self, states: np.ndarray, next_states: np.ndarray, actions: np.ndarray) -> dict[str, float]:
        return self._mse_step(states, next_states, actions)
