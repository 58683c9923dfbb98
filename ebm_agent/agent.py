"""``EBMPlannerAgent``: online energy-based planning (Du, Lin & Mordatch, CoRL 2019, Algorithm 1) behind SB3's API."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

import numpy as np
import torch
from stable_baselines3.common.logger import Figure
from stable_baselines3.common.type_aliases import GymEnv

from ebm_agent.base import PlannerAgentBase, Segment
from ebm_agent.buffers import TransitionBatch, TransitionBuffer
from ebm_agent.config import (
    TRAINING_FROM_ARGUMENTS,
    TRAINING_FROM_ONLINE,
    OnlineConfig,
    TrainingConfig,
    check_field_types,
    learn_budgets,
    make_config,
    planner_horizon,
)
from ebm_agent.costs import (
    AccelerationPrior,
    ExtraEnergy,
    GaussianGoalEnergy,
    GoalEnergy,
    PlanCost,
    RampedGoalEnergy,
    RewardGoalEnergy,
    VelocityPrior,
)
from ebm_agent.datasets import TransitionDataset
from ebm_agent.energy import EnergyConfig, EnergyModel
from ebm_agent.inverse_dynamics import InverseDynamics
from ebm_agent.langevin import LangevinConfig, LangevinPlanner
from ebm_agent.losses import ContrastBatch, EnergyLoss, make_loss, reach_candidates
from ebm_agent.mppi import MPPIConfig, MPPIPlanner
from ebm_agent.planner import Planner
from ebm_agent.policy import PlanningPolicy
from ebm_agent.subgoals import ExploreConfig, SubgoalGraphConfig

SelfEBMPlannerAgent = TypeVar("SelfEBMPlannerAgent", bound="EBMPlannerAgent")

GOAL_ENERGIES: dict[str, Callable[..., GoalEnergy]] = {
    "gaussian": GaussianGoalEnergy,  # paper Eq. 6: (s_T - g)^2
    "ramped": RampedGoalEnergy,  # the original code: ((t/T)^2 (s_t - g))^2 over the whole plan
    "reward": RewardGoalEnergy.negative_l1,  # max-ent form (paper Sec. 3.2): -sum_t R(s_t) with R = -L1
}
"""Goal energies by name; pass an instance to ``cost=`` for anything else."""

PLANNERS: dict[str, tuple[type, type]] = {"mppi": (MPPIPlanner, MPPIConfig), "langevin": (LangevinPlanner, LangevinConfig)}
"""Planners by name with their config types."""


@dataclass
class CostConfig:
    """The plan cost besides the learned energy; defaults follow the original code (§3).

    :param goal_energy: ``"reward"`` (the paper's maximum-entropy form, Sec. 3.2, with R = -L1 distance to the goal,
        the particle/maze/Reacher reward: a linear pull that keeps infeasible shortcuts expensive yet is precise at the
        goal), ``"gaussian"`` (paper Eq. 6, (s_T - g)^2) or ``"ramped"`` (the original code's time-ramped goal).
    :param goal_weight: weight of the goal term (g_coeff).
    :param eval_goal_weight: goal weight used by ``predict`` (None: ``goal_weight``). The default 10 keeps an agent
        trained on few transitions from being held by its young energy, which still rises with how rarely a state was
        seen (particle, 2,000 transitions: evaluated at the training weight 1 it failed on 6 of 10 seeds, at 10 on
        none; docs/agent.md); the original evaluated the arm with 10. The ``paper`` preset evaluates at the training
        weight, as the original's particle, maze and Reacher did.
    :param velocity_weight: weight of the velocity prior (v_coeff).
    :param acceleration_weight: weight of the acceleration prior (a_coeff).
    :param warmup_plans: number of plans over which the goal and prior weights ramp from 0 to 1 during ``learn`` (the
        original's ``l2_weight = min(itr / 200, 1)``); 0 disables the warm-up.
    """

    goal_energy: str = "reward"
    goal_weight: float = 1.0
    eval_goal_weight: float | None = 10.0
    velocity_weight: float = 0.0
    acceleration_weight: float = 1.0
    warmup_plans: int = 200

    def __post_init__(self) -> None:
        check_field_types(self)
        if self.goal_energy not in GOAL_ENERGIES:
            raise ValueError(f"CostConfig.goal_energy must be one of {sorted(GOAL_ENERGIES)}, got {self.goal_energy!r}.")
        for name in ("goal_weight", "velocity_weight", "acceleration_weight", "warmup_plans"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"CostConfig.{name} must be >= 0, got {getattr(self, name)!r}.")


class EBMPlannerAgent(PlannerAgentBase):
    """Model-based planning with an energy-based dynamics model E(s_t, s_{t+1}), learned online.

    The agent samples state trajectories with MPPI (or Langevin dynamics) under the energy plus a goal energy,
    turns them into actions with an inverse-dynamics model, executes them until the real states deviate from the
    plan, then takes one contrastive gradient step: real transitions down, planned transitions up (Algorithm 1).

    Example::

        import gymnasium as gym, envs
        from ebm_agent import EBMPlannerAgent
        agent = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Particle-v0"), seed=0)
        agent.learn(total_timesteps=50_000)

    :param policy: ``"MultiInputPolicy"``.
    :param env: a goal-conditioned env, its id, or a VecEnv.
    :param learning_rate: Adam learning rate (1e-3).
    :param horizon: T, planned transitions per plan; None: the planner's (``planner_config.horizon``, 10 by default).
        The planner owns it: the agent sets it in its own copy of the planner config and reads ``self.horizon`` back.
    :param planner: ``"mppi"`` or ``"langevin"``, or a :class:`~ebm_agent.planner.Planner` instance (its horizon).
    :param planner_config: :class:`MPPIConfig` / :class:`LangevinConfig` or a dict of its fields; the agent plans with
        a copy, so the caller's object is never changed.
    :param energy: :class:`EnergyConfig` or a dict of its fields.
    :param cost: :class:`CostConfig` or a dict of its fields.
    :param training: :class:`~ebm_agent.config.TrainingConfig` or a dict of its fields: how the energy learns (the
        contrastive loss and its L2 term, planned, perturbed and hard negatives, the L2 anneal).
    :param clip_sigma: per-element gradient clip of the original's Adam (3.0), None for plain Adam.
    :param online: :class:`OnlineConfig` or a dict of its fields.
    :param inverse_dynamics: ``"ground_truth"``, ``"rls_tracking"``, ``"rls"``, ``"mlp"``, an instance, or None (the
        default): the env's own where it has them, else the learned default (:class:`~ebm_agent.base.PlannerAgentBase`).
    :param subgoal_graph: the graph subgoals of :class:`~ebm_agent.base.PlannerAgentBase` (issue #36); its edges
        may come from this agent's energy (the default). None (the default, the paper's): plans aim at the goal.
    :param explore: frontier exploration during ``learn`` (:class:`~ebm_agent.base.PlannerAgentBase`). None (the
        default, the paper's): none.
    :param subgoal_class: the subgoal provider built with ``subgoal_graph``'s keywords and this agent's energy
        (:class:`~ebm_agent.base.PlannerAgentBase`); None: :class:`~ebm_agent.subgoals.GraphSubgoals`.
    :param image_log_interval: gradient steps between TensorBoard images of the plan and the energy map (2-D
        states only); 0 disables them.
    :param goal_indices: the observation dims that ``achieved_goal`` copies (None: the env's ``goal_indices``, else
        inferred from a reset observation and printed with ``verbose >= 1``; ``goal_spec.goal_indices`` holds them).
    :param stats_window_size: episodes averaged for ``rollout/*``.
    :param tensorboard_log: TensorBoard folder.
    :param verbose: verbosity.
    :param seed: seed.
    :param device: ``"auto"``, ``"cpu"`` or ``"cuda"``.
    """

    default_tb_log_name: ClassVar[str] = "EBM"
    checkpoint_buffers: ClassVar[tuple[str, ...]] = ("pos_buffer", "neg_buffer", "hard_negative_buffer")

    def __init__(
        self,
        policy: str | type[PlanningPolicy],
        env: GymEnv | str | None,
        learning_rate: float = 1e-3,
        horizon: int | None = None,
        planner: str | Planner = "mppi",
        planner_config: MPPIConfig | LangevinConfig | dict[str, Any] | None = None,
        energy: EnergyConfig | dict[str, Any] | None = None,
        cost: CostConfig | dict[str, Any] | None = None,
        training: TrainingConfig | dict[str, Any] | None = None,
        clip_sigma: float | None = 3.0,
        online: OnlineConfig | dict[str, Any] | None = None,
        inverse_dynamics: str | InverseDynamics | None = None,
        image_log_interval: int = 1000,
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
        if isinstance(planner, str) and planner not in PLANNERS:
            raise ValueError(f"planner must be one of {sorted(PLANNERS)} or a Planner instance, got {planner!r}.")
        self.planner_kind = planner
        if isinstance(planner, str):
            config_type = PLANNERS[planner][1]
            self.planner_config = planner_horizon(make_config(config_type, planner_config, "planner_config"), horizon)
            horizon = self.planner_config.horizon  # type: ignore[attr-defined]
        else:
            self.planner_config = None
            if horizon not in (None, planner.horizon):
                raise ValueError(f"horizon={horizon} but the planner instance plans {planner.horizon} steps; leave it out.")
            horizon = planner.horizon
        self.energy_config = make_config(EnergyConfig, energy, "energy")
        self.cost_config = make_config(CostConfig, cost, "cost")
        self.training = make_config(TrainingConfig, training, "training")
        self.clip_sigma = clip_sigma
        self.image_log_interval = image_log_interval
        self.extra_energies: list[ExtraEnergy] = []
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

    # ------------------------------------------------------------------ setup
    def _upgrade_saved_settings(self) -> dict[str, Any]:
        """A model saved before issue 45 held its training settings as constructor attributes (``loss``,
        ``l2_coeff``, ...) and in ``online`` (hard negatives, the L2 anneal, the negative buffer), and the cost's
        warm-up in ``online.prior_warmup_plans``: they become ``training`` and ``cost_config.warmup_plans``."""
        legacy = super()._upgrade_saved_settings()
        arguments = {name: self.__dict__.pop(name) for name in TRAINING_FROM_ARGUMENTS if name in self.__dict__}
        moved = {name: legacy[name] for name in TRAINING_FROM_ONLINE if name in legacy}
        if arguments or moved:
            self.training = TrainingConfig(**arguments, **moved)
        if "prior_warmup_plans" in legacy:
            self.cost_config = dataclasses.replace(self.cost_config, warmup_plans=int(legacy["prior_warmup_plans"]))
        return legacy

    def _build_model(self) -> None:
        spec = self.goal_spec
        assert spec is not None
        # The training objective, built once from the settings (``training``).
        self.loss_fn: EnergyLoss = make_loss(
            self.training.loss,
            self.training.perturbed_negatives,
            self.training.hard_negative_loss,
            self.training.hard_negative_weight,
            self.training.hard_negative_margin,
        )
        periodic = spec.goal_indices.tolist() if spec.goal_period is not None else []
        energy = EnergyModel(
            spec.state_dim,
            self.energy_config,
            masked_dims=spec.target_indices.tolist(),
            periodic_dims=periodic,
            period=spec.goal_period or 2.0,
        )
        self.policy = PlanningPolicy(
            self.observation_space,
            self.action_space,
            networks={"energy": energy},
            learning_rate=self.lr_schedule(1.0),
            clip_sigma=self.clip_sigma,
        ).to(self.device)
        self.neg_buffer = TransitionBuffer(self.training.neg_buffer_size, spec.state_dim, None, seed=self._base_seed() + 3)
        # Failed plan steps (training.hard_negatives): states s_t, next_states s'_plan (the impossible target) and, in
        # the action slot, s'_real (where the env actually went), so its "action_dim" is D.
        self.hard_negative_buffer = (
            TransitionBuffer(
                self.training.hard_negative_buffer_size, spec.state_dim, spec.state_dim, seed=self._base_seed() + 5
            )
            if self.training.hard_negatives
            else None
        )
        if isinstance(self.planner_kind, str):
            planner_type = PLANNERS[self.planner_kind][0]
            self.planner = planner_type(
                self.planner_config, spec.state_dim, state_low=spec.state_low, state_high=spec.state_high, device=self.device
            )
        else:
            self.planner = self.planner_kind
        cfg = self.cost_config
        goal_energy = GOAL_ENERGIES[cfg.goal_energy](
            spec.goal_indices.tolist(), weight=cfg.goal_weight, period=spec.goal_period
        )
        priors: list[ExtraEnergy] = []
        model_dims = spec.model_dims.tolist()
        if cfg.velocity_weight > 0:
            priors.append(VelocityPrior(cfg.velocity_weight, dims=model_dims))
        if cfg.acceleration_weight > 0:
            priors.append(AccelerationPrior(cfg.acceleration_weight, dims=model_dims))
        # The original's gradient (Langevin) planner weighted transition t by T - t; MPPI used a plain sum.
        weights = "linear_decay" if self.planner_kind == "langevin" else "uniform"
        self.plan_cost = PlanCost(self.energy_model, goal_energy, priors, transition_weights=weights)

    @property
    def energy_model(self) -> EnergyModel:
        """The learned energy E(s_t, s_{t+1})."""
        model = self.policy.network("energy")
        assert isinstance(model, EnergyModel)
        return model

    def _excluded_save_params(self) -> list[str]:
        return [
            *super()._excluded_save_params(),
            "neg_buffer",
            "hard_negative_buffer",
            "plan_cost",
            "extra_energies",
            "loss_fn",
            "_negative_radius",
        ]

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        names = ["policy", "policy.optimizer"]
        module = getattr(self.inverse_model, "module", None)
        if isinstance(module, torch.nn.Module):
            names += ["inverse_model.module", "inverse_model.optimizer"]
        return names, []

    def set_plan_constraints(self, energies: Sequence[ExtraEnergy]) -> None:
        """Add energies (e.g. :class:`~ebm_agent.costs.BoxObstacleEnergy`) to every later plan; [] removes them.

        This is how a test-time obstacle the model never saw is handled (paper Sec. 4.3): planning in state space
        composes it with the learned energy.

        :param energies: callables ``plans [N, K, T+1, D] -> [N, K]``.
        """
        for energy in energies:
            if not callable(energy):
                raise TypeError(f"set_plan_constraints expects callables plans -> [N, K], got {energy!r}.")
        self.extra_energies = list(energies)

    # --------------------------------------------------------------- planning
    def _plan(
        self,
        states: np.ndarray,
        goals: np.ndarray,
        init_plans: np.ndarray | None,
        generator: torch.Generator,
        training: bool,
        init_actions: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        cost = self.plan_cost.with_extra(*self.extra_energies) if self.extra_energies else self.plan_cost
        warmup = self.cost_config.warmup_plans
        cost.prior_scale = min(self.num_plans / warmup, 1.0) if (training and warmup > 0) else 1.0
        goal_energy = cost.goal_energy
        eval_weight = self.cost_config.eval_goal_weight
        if goal_energy is not None:
            goal_energy.weight = eval_weight if (eval_weight is not None and not training) else self.cost_config.goal_weight
        start = torch.as_tensor(states, device=self.device)  # [n, D]
        goal = torch.as_tensor(goals, device=self.device)  # [n, G]
        init = None if init_plans is None else torch.as_tensor(init_plans, device=self.device)  # [n, T+1, D]
        self.policy.set_training_mode(False)
        if isinstance(self.planner, MPPIPlanner) and self.planner.config.noise_units == "step":
            step = self._measured_step()  # [D] or None (no real move yet: state units)
            self.planner.noise_unit = None if step is None else torch.as_tensor(step, dtype=torch.float32, device=self.device)
        # The configured budget is the planner's own (a full search, or its warm-start budget for a warm start); a
        # fresh plan made while learning may have a budget of its own (train_iterations).
        iterations = learn_budgets(self.planner_config)[0] if training and init is None else None
        result = self.planner.plan(start, goal, cost, init_plan=init, generator=generator, iterations=iterations)
        plans = result.plans  # [n, T+1, D]
        with torch.no_grad():
            transition_energy = self.energy_model(plans[:, :-1], plans[:, 1:]).mean(dim=1)  # [n]
        return plans.cpu().numpy().astype(np.float32), None, transition_energy.cpu().numpy()

    # --------------------------------------------------------------- training
    def scheduled_l2_coeff(self) -> float:
        """The L2 term's weight at the current point of ``learn``: ``l2_coeff``, annealed linearly to
        ``training.l2_final`` between the fractions ``training.l2_anneal_start`` and ``l2_anneal_end`` of the budget.

        :return: the weight (``l2_coeff`` when no anneal is set, before the anneal, or outside ``learn``).
        """
        final, online = self.training.l2_final, self.training
        total = int(getattr(self, "_total_timesteps", 0) or 0)
        if final is None or total <= 0:
            return float(self.training.l2_coeff)
        progress = min(self.num_timesteps / total, 1.0)
        if progress < online.l2_anneal_start:
            return float(self.training.l2_coeff)
        span = online.l2_anneal_end - online.l2_anneal_start
        weight = 1.0 if span <= 0 else min((progress - online.l2_anneal_start) / span, 1.0)
        return float(self.training.l2_coeff + weight * (final - self.training.l2_coeff))

    def _train_on_segments(self, segments: list[Segment]) -> dict[str, float]:
        fresh = self._fresh_positives(segments)  # their real moves are in real_moves already (_run_online)
        positives = self._replay_positives(fresh)
        # Negatives: the planned transitions that were attempted, up to and including the one that deviated; the
        # planned transitions after the deviation are ignored (paper Sec. 3.3).
        neg_states = np.concatenate([s.planned[:-1] for s in segments])  # [M, D]
        neg_next = np.concatenate([s.planned[1:] for s in segments])  # [M, D]
        neg_states, neg_next = self._replay_negatives(neg_states, neg_next)
        hard, num_failed = self._hard_negatives(segments) if self.training.hard_negatives else (None, 0)
        l2_coeff = self.scheduled_l2_coeff()
        stats: dict[str, float] = {}
        if self.online.train_every_plan:
            stats = self._gradient_step(
                positives.states, positives.next_states, neg_states, neg_next, hard=hard, l2_coeff=l2_coeff
            )
        if self.training.l2_final is not None:
            stats["l2_coeff"] = l2_coeff
        if self.training.hard_negatives:
            stats["failed_steps"] = float(num_failed)
        if self.inverse_model is not None and positives.actions is not None:
            stats.update(
                {
                    f"inverse_{k}": v
                    for k, v in self.inverse_model.update(positives.states, positives.next_states, positives.actions).items()
                }
            )
        if self.image_log_interval and self._n_updates % self.image_log_interval == 0:
            self._log_images(segments[0])
        return stats

    def _replay_negatives(self, states: np.ndarray, next_states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Swap each fresh negative for a replayed one with probability ``neg_replay_prob``, then store the fresh ones.

        The original re-added the mixed batch (duplicating replayed items); only fresh negatives are stored here.

        :param states: [M, D] planned states.
        :param next_states: [M, D] planned next states.
        :return: the mixed negatives ([M, D], [M, D]).
        """
        mixed_states, mixed_next = states.copy(), next_states.copy()
        count = len(states)
        if len(self.neg_buffer) > count:
            replay = self.neg_buffer.sample(count)
            swap = self.neg_buffer.rng.random(count) < self.training.neg_replay_prob
            mixed_states[swap], mixed_next[swap] = replay.states[swap], replay.next_states[swap]
        self.neg_buffer.add(states, next_states)
        return mixed_states, mixed_next

    def _hard_negatives(self, segments: list[Segment]) -> tuple[TransitionBatch | None, int]:
        """The failed plan steps of ``segments`` plus up to ``hard_negative_batch`` replayed ones
        (``training.hard_negatives``).

        Step i of a segment failed when max |planned[i + 1] - real_next_states[i]| over the model dims exceeds
        ``training.hard_negative_threshold``: the agent aimed from the real state at the planned one and the env went
        elsewhere. With ``training.hard_negative_reach`` the planned state is first clipped into the reach box of the
        real moves seen so far (:meth:`real_moves`, which must have been given the segments' transitions). The fresh
        failed steps are stored after the replayed ones are drawn (as the planned negatives).

        :param segments: the finished segments.
        :return: a batch of states s_t [H, D], next_states s'_plan [H, D] and actions s'_real [H, D] (the real next
            state, stored in the action slot), or None when there is neither a fresh nor a stored failed step; and
            the number of fresh failed steps.
        """
        buffer = self.hard_negative_buffer
        assert buffer is not None, "hard_negative_buffer is built when training.hard_negatives is True"
        states = np.concatenate([s.real_states for s in segments])  # [k, D]
        real_next = np.concatenate([s.real_next_states for s in segments])  # [k, D]
        planned_next = np.concatenate([s.planned[1:] for s in segments])  # [k, D]
        if self.training.hard_negative_reach:
            reach = self.real_moves.largest  # [D]
            planned_next = states + np.clip(planned_next - states, -reach, reach)  # [k, D]
        failed = self._deviation(real_next, planned_next, reduce="max") > self.training.hard_negative_threshold  # [k]
        fresh = TransitionBatch(states[failed], planned_next[failed], real_next[failed])  # [F, D] each
        replay_count = min(len(buffer), int(self.training.hard_negative_batch))
        if replay_count > 0:
            replay = buffer.sample(replay_count)  # [R, D] each
            assert replay.actions is not None
            batch = TransitionBatch(
                np.concatenate([fresh.states, replay.states]),  # [F + R, D]
                np.concatenate([fresh.next_states, replay.next_states]),  # [F + R, D]
                np.concatenate([fresh.actions, replay.actions]),  # [F + R, D]
            )
        else:
            batch = fresh
        if failed.any():
            buffer.add(fresh.states, fresh.next_states, fresh.actions)
        return (batch if len(batch) > 0 else None), int(failed.sum())

    def _gradient_step(
        self,
        pos_states: np.ndarray,
        pos_next: np.ndarray,
        neg_states: np.ndarray,
        neg_next: np.ndarray,
        hard: TransitionBatch | None = None,
        l2_coeff: float | None = None,
    ) -> dict[str, float]:
        """One optimiser step on the contrastive loss; refuses to write non-finite weights.

        :param pos_states: [P, D] real states.
        :param pos_next: [P, D] real next states.
        :param neg_states: [M, D] planned states.
        :param neg_next: [M, D] planned next states.
        :param hard: failed plan steps (``training.hard_negatives``): states s_t [H, D], next_states s'_plan [H, D],
            actions s'_real [H, D]; None for none. Not used by ``loss="infonce_reach"`` and ``"infonce"``.
        :param l2_coeff: the L2 term's weight for this step (None: ``self.training.l2_coeff``; see :meth:`scheduled_l2_coeff`).
        :return: loss statistics.
        :raises FloatingPointError: on a NaN/inf loss or gradient (the weights are left untouched).
        """
        energy = self.energy_model
        l2 = self.training.l2_coeff if l2_coeff is None else l2_coeff
        if self.training.perturbed_negatives > 0 or self.energy_config.move_input:
            moves = self.real_moves
            energy.set_move_statistics(moves.mean, moves.std)
        self.policy.set_training_mode(True)
        as_tensor = lambda array: torch.as_tensor(array, device=self.device)  # noqa: E731
        states = as_tensor(pos_states)  # [P, D]
        candidates = None  # [P, K, D] the loss's contrast set of each real state, where it has one
        if self.loss_fn.contrast == "reach":
            radius = torch.as_tensor(self.real_moves.largest, device=self.device).clamp_min(1e-6)  # [D]
            candidates = reach_candidates(states, radius, self.training.reach_candidates, self._generator)
        elif self.loss_fn.contrast == "perturbed":
            candidates = as_tensor(self._perturbed_next_states(pos_states, pos_next))
        batch = ContrastBatch(
            states,
            as_tensor(pos_next),
            as_tensor(neg_states),
            as_tensor(neg_next),
            candidates,
            None if hard is None else (as_tensor(hard.states), as_tensor(hard.next_states), as_tensor(hard.actions)),
        )
        loss, stats = self.loss_fn(energy, batch, l2)
        optimizer = self.policy.optimizer
        assert optimizer is not None
        optimizer.zero_grad()
        loss.backward()
        grads_finite = all(torch.isfinite(p.grad).all() for p in energy.parameters() if p.grad is not None)
        if not torch.isfinite(loss) or not grads_finite:
            optimizer.zero_grad()
            raise FloatingPointError(
                f"The energy diverged (loss={loss.item()}) at update {self._n_updates}, timestep {self.num_timesteps}; "
                "no update was applied, so the weights (and the last checkpoint) are the last finite ones. Try a lower "
                "learning_rate, loss='cd' with l2_coeff >= 1, or energy={'spectral_norm': True}."
            )
        optimizer.step()
        stats["energy_gap"] = stats["energy_neg"] - stats["energy_pos"]
        return stats

    def _perturbed_next_states(self, states: np.ndarray, next_states: np.ndarray) -> np.ndarray:
        """``perturbed_negatives`` near misses of each real next state: s' + N(0, (c std(s' - s))^2), c from
        ``perturb_scales``, std the running std of the real moves (updated with these transitions unless the gradient
        step already did).

        :param states: [P, D] real states.
        :param next_states: [P, D] their real next states.
        :return: [P, M, D] perturbed next states (float32).
        """
        std = self.real_moves.std  # [D]
        shape = (len(states), self.training.perturbed_negatives, states.shape[1])
        scales = torch.as_tensor(self.training.perturb_scales, dtype=torch.float32, device=self.device)
        pick = torch.randint(len(self.training.perturb_scales), shape[:2], generator=self._generator, device=self.device)
        noise = torch.randn(shape, generator=self._generator, device=self.device) * scales[pick][..., None]  # [P, M, D]
        noise = noise * torch.as_tensor(std, dtype=torch.float32, device=self.device)
        return (torch.as_tensor(next_states, dtype=torch.float32, device=self.device)[:, None, :] + noise).cpu().numpy()

    def learn_offline(  # type: ignore[override]
        self: SelfEBMPlannerAgent,
        dataset: TransitionDataset,
        epochs: int = 10,
        batch_size: int = 256,
        sequential: bool = False,
        num_candidates: int = 4,
        negative_radius: float | np.ndarray | None = None,
        log_interval: int = 1,
        tb_log_name: str = "EBM_offline",
    ) -> SelfEBMPlannerAgent:
        """Pretrain the energy (and a learned inverse dynamics) on a fixed dataset of transitions (paper Sec. 4.2).

        Negatives for a real (s, s') are model samples: ``num_candidates`` next states s + U(-r, r) scored by the
        current energy, the lowest-energy one kept (a cheap stand-in for the original's ``num_steps > 0`` MPPI
        refinement of negatives), mixed 50/50 with replayed negatives. Keep ``num_candidates`` small: measured on
        5,000 random particle transitions x 40 epochs, 4 candidates learn E(0.5-diagonal jump) = 1.3 against
        E(feasible move) ~ 0, while 64 (hard negatives only) collapse the energy to a constant ~0.005
        (see tests/agent/test_learning.py).

        :param dataset: the transitions (e.g. from :func:`~ebm_agent.datasets.collect_random_transitions`).
        :param epochs: passes over the dataset (10 as the original).
        :param batch_size: transitions per gradient step (256).
        :param sequential: contiguous, correlated minibatches (the "directed + sequential" ablation).
        :param num_candidates: candidate next states per positive for the negative sample (1 = uniform negatives).
        :param negative_radius: half-width r of the candidate box per state dim; default 2x the largest |s' - s|.
        :param log_interval: epochs between log dumps.
        :param tb_log_name: TensorBoard run name.
        :return: self.
        """
        # The original's box, unwrapped even on periodic dims (the recorded paper-preset Reacher rows were made with it).
        radius = 2.0 * np.abs(dataset.next_states - dataset.states).max(axis=0) if negative_radius is None else negative_radius
        spec = self.goal_spec
        assert spec is not None
        self._negative_radius = torch.as_tensor(
            np.broadcast_to(np.asarray(radius, np.float32), (spec.state_dim,)).copy(), device=self.device
        )
        self._num_candidates = num_candidates
        return super().learn_offline(dataset, epochs, batch_size, sequential, log_interval, tb_log_name)

    def _offline_step(self, states: np.ndarray, next_states: np.ndarray, actions: np.ndarray) -> dict[str, float]:
        if self.training.loss in ("infonce_reach", "infonce_perturb"):  # its contrast set is drawn in the gradient step
            neg_states, neg_next = states, next_states
        else:
            negatives = self._sample_negatives(states, self._negative_radius, self._num_candidates)
            neg_states, neg_next = self._replay_negatives(states, negatives)
        stats = self._gradient_step(states, next_states, neg_states, neg_next)
        if self.inverse_model is not None:
            stats.update({f"inverse_{k}": v for k, v in self.inverse_model.update(states, next_states, actions).items()})
        return stats

    def _sample_negatives(self, states: np.ndarray, radius: torch.Tensor, num_candidates: int) -> np.ndarray:
        """Lowest-energy next state among random candidates around each state: a one-step model sample.

        :param states: [B, D].
        :param radius: [D] half-width of the candidate box.
        :param num_candidates: C.
        :return: [B, D] negative next states.
        """
        spec = self.goal_spec
        assert spec is not None
        start = torch.as_tensor(states, device=self.device)  # [B, D]
        noise = torch.rand(len(states), num_candidates, spec.state_dim, generator=self._generator, device=self.device) * 2 - 1
        candidates = start[:, None, :] + noise * radius  # [B, C, D]
        if spec.state_low is not None and spec.state_high is not None:
            low = torch.as_tensor(spec.state_low, device=self.device)
            high = torch.as_tensor(spec.state_high, device=self.device)
            candidates = torch.maximum(torch.minimum(candidates, high), low)
        with torch.no_grad():
            energies = self.energy_model(start[:, None, :].expand_as(candidates), candidates)  # [B, C]
        best = energies.argmin(dim=1)  # [B]
        return candidates[torch.arange(len(states)), best].cpu().numpy()

    # ----------------------------------------------------------- diagnostics
    def _log_images(self, segment: Segment) -> None:
        """TensorBoard figure of the energy landscape with the latest plan and its real execution (2-D states)."""
        spec = self.goal_spec
        assert spec is not None
        if spec.state_dim != 2 or spec.state_low is None or spec.state_high is None:
            return
        from ebm_agent.visualize import plan_figure

        figure = plan_figure(self.energy_model, spec.state_low, spec.state_high, segment.planned, segment.real_next_states)
        self.logger.record("plan/energy_map", Figure(figure, close=True), exclude=("stdout", "log", "json", "csv"))
