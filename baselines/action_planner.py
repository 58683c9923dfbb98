"""Planning over *action* sequences through a learned forward model: what the Action FF baseline plans with."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from ebm_agent.config import check_field_types

ForwardModel = Callable[[Tensor, Tensor], Tensor]
"""f(states [..., D], actions [..., A]) -> next states [..., D]."""


@dataclass
class ActionPlannerConfig:
    """Settings of the action-sequence planner; K, T and the iteration budgets default to the EBM planner's for a fair
    match (``ebm_agent.presets.FAST_ACTION_FF`` gives the budgets of ``FAST_EBM``).

    :param horizon: T, actions per plan.
    :param num_samples: K, candidate action sequences per env and iteration (MPPI).
    :param iterations: MPPI iterations, or gradient steps for ``method="gradient"``.
    :param method: ``"mppi"`` (the paper's description of the baseline) or ``"gradient"`` (what the original code
        did: gradient descent on the actions through the unrolled model, lr 1.0, N(0, 0.01^2) noise per step).
    :param temperature: MPPI's lambda in softmax(-cost / lambda).
    :param noise_std: std of the Gaussian action perturbations, in action units.
    :param step_size: gradient planner's learning rate (the original's 1.0).
    :param gradient_noise: std of the noise the gradient planner adds before each step (0.01).
    :param warm_iterations: MPPI iterations of a plan warm-started from the previous action sequence, shifted by the
        steps executed, or None to plan every time from zero actions with ``iterations`` (the original). The EBM
        planner's ``MPPIConfig.warm_iterations`` counterpart: set both alike for equal budgets.
    :param train_iterations: MPPI iterations of a fresh plan while the agent learns (None: ``iterations``);
        ``MPPIConfig.train_iterations``' counterpart. Evaluation plans keep ``iterations``.
    :param keep_warm_start: for each env whose iterations ended farther from the goal than its warm start, return
        the warm start (``MPPIConfig.keep_warm_start``'s counterpart).
    """

    horizon: int = 10
    num_samples: int = 80
    iterations: int = 80
    method: str = "mppi"
    temperature: float = 1e-4
    noise_std: float = 0.3
    step_size: float = 1.0
    gradient_noise: float = 0.01
    warm_iterations: int | None = None
    train_iterations: int | None = None
    keep_warm_start: bool = False

    def __post_init__(self) -> None:
        check_field_types(self)
        if self.method not in ("mppi", "gradient"):
            raise ValueError(f"ActionPlannerConfig.method must be 'mppi' or 'gradient', got {self.method!r}.")
        for name in ("horizon", "num_samples"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"ActionPlannerConfig.{name} must be >= 1, got {getattr(self, name)!r}.")
        for name in ("warm_iterations", "train_iterations"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 0):
                raise ValueError(f"ActionPlannerConfig.{name} must be None or an int >= 0, got {value!r}.")
        if not self.temperature > 0 or not self.noise_std > 0:
            raise ValueError("ActionPlannerConfig.temperature and noise_std must be > 0.")


def final_goal_distance(states: Tensor, goals: Tensor, goal_indices: Tensor) -> Tensor:
    """L2 distance of the last predicted state's goal dims to the goal (the paper's Action FF score).

    :param states: [..., T+1, D] predicted rollouts.
    :param goals: [..., G] goals, broadcastable to the rollouts' batch dims.
    :param goal_indices: [G] long tensor.
    :return: [...] distances.
    """
    return torch.linalg.vector_norm(states[..., -1, goal_indices] - goals, dim=-1)


class ActionPlanner:
    """Plans action sequences by rolling them out through a forward model and scoring the final predicted state.

    :param config: the settings.
    :param action_low: [A] lower action bounds.
    :param action_high: [A] upper action bounds.
    :param goal_indices: [G] state dims the goal constrains.
    :param device: torch device.
    """

    def __init__(
        self,
        config: ActionPlannerConfig,
        action_low: np.ndarray,
        action_high: np.ndarray,
        goal_indices: np.ndarray,
        device: str | torch.device = "cpu",
    ) -> None:
        self.config = config
        self.device = torch.device(device)
        self.action_low = torch.as_tensor(action_low, dtype=torch.float32, device=self.device)
        self.action_high = torch.as_tensor(action_high, dtype=torch.float32, device=self.device)
        self.goal_indices = torch.as_tensor(goal_indices, dtype=torch.long, device=self.device)

    @property
    def horizon(self) -> int:
        """T, the number of planned actions."""
        return self.config.horizon

    def rollout(self, model: ForwardModel, start: Tensor, actions: Tensor) -> Tensor:
        """Unroll the model from ``start`` under ``actions``.

        :param model: the forward model.
        :param start: [..., D] start states.
        :param actions: [..., T, A] action sequences.
        :return: [..., T+1, D] predicted states, the start first.
        """
        states = [start]
        for t in range(actions.shape[-2]):  # inherently sequential: each prediction feeds the next
            states.append(model(states[-1], actions[..., t, :]))
        return torch.stack(states, dim=-2)

    def plan(
        self,
        model: ForwardModel,
        start: Tensor,
        goals: Tensor,
        generator: torch.Generator,
        iterations: int | None = None,
        init_actions: Tensor | None = None,
    ) -> tuple[Tensor, Tensor, Tensor]:
        """Plan for a batch of envs.

        :param model: the forward model.
        :param start: [N, D] start states.
        :param goals: [N, G] goals.
        :param generator: noise source.
        :param iterations: override ``config.iterations`` (and ``warm_iterations``).
        :param init_actions: [N, T, A] warm start (e.g. the previous plan's actions, shifted), used by the MPPI
            method when ``config.warm_iterations`` is set; NaN rows start from zero actions. None: no warm start.
        :return: (predicted states [N, T+1, D], actions [N, T, A], final goal distance [N]).
        """
        cfg = self.config
        warm = init_actions is not None and cfg.method == "mppi" and cfg.warm_iterations is not None
        num_iterations = cfg.iterations if iterations is None else iterations
        if warm and iterations is None:
            assert cfg.warm_iterations is not None
            num_iterations = min(cfg.warm_iterations, cfg.iterations)
        num_envs, action_dim = start.shape[0], self.action_low.shape[0]
        states: Tensor | None = None  # [N, T+1, D] once rolled out
        if cfg.method == "gradient":
            actions = self._gradient(model, start, goals, generator, num_iterations)
        else:
            actions = torch.zeros(num_envs, cfg.horizon, action_dim, device=self.device)  # [N, T, A]
            if warm:
                assert init_actions is not None
                init = init_actions.to(self.device, actions.dtype)
                actions = torch.clamp(torch.nan_to_num(init, nan=0.0), self.action_low, self.action_high)
            with torch.no_grad():
                fast = _fast_model(model)
                initial = actions  # [N, T, A] the warm start
                for _ in range(num_iterations):
                    actions = self._mppi_update(fast, start, goals, actions, generator)
                if warm and cfg.keep_warm_start:
                    # Both candidates in one rollout [2N, T+1, D], which also gives the returned plan's states.
                    ends = self.rollout(fast, torch.cat([start, start]), torch.cat([initial, actions]))
                    before, after = final_goal_distance(ends, torch.cat([goals, goals]), self.goal_indices).chunk(2)
                    worse = (after > before)[:, None, None]  # [N, 1, 1]
                    actions = torch.where(worse, initial, actions)
                    states = torch.where(worse, ends[:num_envs], ends[num_envs:])
        with torch.no_grad():
            if states is None:
                states = self.rollout(_fast_model(model), start, actions)  # [N, T+1, D]
            distance = final_goal_distance(states, goals, self.goal_indices)
        return states, actions, distance

    def _mppi_update(
        self, model: ForwardModel, start: Tensor, goals: Tensor, mean: Tensor, generator: torch.Generator
    ) -> Tensor:
        cfg = self.config
        num_envs = start.shape[0]
        noise = torch.randn(
            num_envs, cfg.num_samples, *mean.shape[1:], generator=generator, device=self.device
        )  # [N, K, T, A]
        candidates = torch.clamp(mean[:, None] + cfg.noise_std * noise, self.action_low, self.action_high)
        starts = start[:, None].expand(-1, cfg.num_samples, -1)  # [N, K, D]
        states = self.rollout(model, starts, candidates)  # [N, K, T+1, D]
        costs = final_goal_distance(states, goals[:, None], self.goal_indices)  # [N, K]
        costs = torch.where(torch.isfinite(costs), costs, torch.full_like(costs, float("inf")))
        weights = torch.softmax(-costs / cfg.temperature, dim=1)  # [N, K]
        return (weights[:, :, None, None] * candidates).sum(dim=1)

    def _gradient(
        self, model: ForwardModel, start: Tensor, goals: Tensor, generator: torch.Generator, iterations: int
    ) -> Tensor:
        cfg = self.config
        shape = (start.shape[0], cfg.horizon, self.action_low.shape[0])
        # The original initialised evaluation plans from U(-0.1, 0.1) (train.py:1509-1562).
        actions = (torch.rand(shape, generator=generator, device=self.device) * 0.2 - 0.1).requires_grad_(True)
        for _ in range(iterations):
            with torch.no_grad():
                actions += cfg.gradient_noise * torch.randn(shape, generator=generator, device=self.device)
            states = self.rollout(model, start, actions)
            loss = (final_goal_distance(states, goals, self.goal_indices) ** 2).sum()
            (grad,) = torch.autograd.grad(loss, actions)
            with torch.no_grad():
                actions -= cfg.step_size * grad
                actions.copy_(torch.clamp(actions, self.action_low, self.action_high))
        return actions.detach()


def _fast_model(model: ForwardModel) -> ForwardModel:
    """The model's gradient-free evaluator with reused buffers when it has one (call under no_grad), else the model."""
    evaluator = getattr(model, "inference_evaluator", None)
    fast = evaluator() if callable(evaluator) else None
    return model if fast is None else fast
