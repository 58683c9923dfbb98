"""Langevin dynamics on the plan: the original code's gradient planner (``mcmc_step`` with ``--mppi=False``).

Each iteration adds N(0, noise_std^2) to the states s_1..s_T (the start is pinned) and takes a gradient step on the
plan cost at the noisy plan, x <- x + noise - step * grad cost(x + noise), in that order as the original did.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from ebm_agent.config import check_field_types
from ebm_agent.costs import PlanCost
from ebm_agent.planner import PlanResult, as_bounds, clip_states, initial_plan, validate_plan_inputs

__all__ = ["LangevinConfig", "LangevinPlanner"]


@dataclass
class LangevinConfig:
    """
    Settings of the Langevin planner; the defaults are the original's gradient planner's.

    :param horizon: T, the number of planned transitions.
    :param iterations: gradient steps per plan.
    :param step_size: the gradient step (the original's step_lr = 1.0).
    :param noise_std: std of the Gaussian noise added to the plan every iteration (the original's 0.01).
    :param anneal: multiply the step by k/K at iteration k = 1..K, as the original's ``--anneal`` (which counted
        from 0, so its first step was zero; counting from 1 keeps every step useful).
    :param grad_clip: clamp every element of step_size * grad to [-grad_clip, grad_clip] (before annealing), or None
        for no clamp. A learned energy can have huge gradients far from its data, and with step_size 1.0 one step
        would throw the plan out of range; 0.05 is the particle's largest move per env step.
    """

    horizon: int = 10
    iterations: int = 80
    step_size: float = 1.0
    noise_std: float = 0.01
    anneal: bool = False
    grad_clip: float | None = 0.05

    def __post_init__(self) -> None:
        check_field_types(self)
        if isinstance(self.horizon, bool) or not isinstance(self.horizon, int) or self.horizon < 1:
            raise ValueError(f"LangevinConfig.horizon must be an int >= 1, got {self.horizon!r}.")
        if isinstance(self.iterations, bool) or not isinstance(self.iterations, int) or self.iterations < 0:
            raise ValueError(f"LangevinConfig.iterations must be an int >= 0, got {self.iterations!r}.")
        if not self.step_size > 0:
            raise ValueError(f"LangevinConfig.step_size must be > 0, got {self.step_size}.")
        if not self.noise_std >= 0:
            raise ValueError(f"LangevinConfig.noise_std must be >= 0, got {self.noise_std}.")
        if self.grad_clip is not None and not self.grad_clip > 0:
            raise ValueError(f"LangevinConfig.grad_clip must be > 0 or None (no clipping), got {self.grad_clip}.")


class LangevinPlanner:
    """
    Gradient-based plan sampling by Langevin dynamics (implements ``Planner``). The cost must be differentiable.

    :param config: the planner settings.
    :param state_dim: D, the number of state dims.
    :param state_low: lower state bounds [D] the plan is clipped to after every step, or None.
    :param state_high: upper state bounds [D], or None.
    :param device: device to plan on.
    """

    def __init__(
        self,
        config: LangevinConfig,
        state_dim: int,
        state_low: np.ndarray | Tensor | None = None,
        state_high: np.ndarray | Tensor | None = None,
        device: str | torch.device = "cpu",
    ) -> None:
        if not isinstance(config, LangevinConfig):
            raise TypeError(f"config must be a LangevinConfig, got {type(config).__name__}.")
        if isinstance(state_dim, bool) or not isinstance(state_dim, int) or state_dim < 1:
            raise ValueError(f"state_dim must be an int >= 1, got {state_dim!r}.")
        self.config = config
        self.horizon = config.horizon
        self.state_dim = state_dim
        self.device = torch.device(device)
        self.state_low, self.state_high = as_bounds(state_low, state_high, state_dim, self.device)

    def plan(
        self,
        start: Tensor,
        goals: Tensor | None,
        cost: PlanCost,
        init_plan: Tensor | None = None,
        generator: torch.Generator | None = None,
        iterations: int | None = None,
    ) -> PlanResult:
        """
        Plan from each env's start by Langevin dynamics on states s_1..s_T.

        :param start: start states [N, D].
        :param goals: goals [N, G], or None when the cost has no goal energy.
        :param cost: the cost of plans; must be differentiable in the plan.
        :param init_plan: warm start [N, T+1, D], or None to start with every state at the start.
        :param generator: random generator on the planner's device; the same seed gives the same plan.
        :param iterations: override ``config.iterations``.
        :return: the plans [N, T+1, D] with ``plans[:, 0] == start``, their costs [N], and the iterations run.
        """
        validate_plan_inputs(start, goals, init_plan, self.horizon, self.state_dim, iterations)
        num_iterations = self.config.iterations if iterations is None else iterations
        # Work outside inference mode and on clones, so that inference tensors from the caller can enter autograd.
        with torch.inference_mode(False), torch.enable_grad():
            start = start.detach().to(self.device).clone()
            goals = None if goals is None else goals.detach().to(self.device).clone()
            if init_plan is None:
                plans = initial_plan(start, self.horizon)
            else:
                plans = init_plan.detach().to(self.device, start.dtype).clone()
            tail = clip_states(plans[:, 1:], self.state_low, self.state_high)  # [N, T, D]
            for iteration in range(1, num_iterations + 1):
                noise = torch.randn(tail.shape, generator=generator, device=tail.device, dtype=tail.dtype)
                noisy_tail = (tail + self.config.noise_std * noise).requires_grad_(True)
                total_cost = cost(torch.cat([start[:, None], noisy_tail], dim=1)[:, None], goals).sum()
                # autograd.grad rather than backward(): the energy's parameters must not accumulate .grad here.
                if total_cost.requires_grad:
                    (gradient,) = torch.autograd.grad(total_cost, noisy_tail, allow_unused=True, materialize_grads=True)
                else:  # a cost that does not depend on the plan: pure noise
                    gradient = torch.zeros_like(noisy_tail)
                step = self.config.step_size * gradient
                if self.config.grad_clip is not None:
                    step = step.clamp(-self.config.grad_clip, self.config.grad_clip)
                if self.config.anneal:
                    # Annealed after the clip so that the schedule still acts when every step hits the clip.
                    step = step * (iteration / num_iterations)
                tail = clip_states(noisy_tail.detach() - step, self.state_low, self.state_high)
            plans = torch.cat([start[:, None], tail], dim=1)  # [N, T+1, D]
            with torch.no_grad():
                final_costs = cost(plans[:, None], goals)[:, 0]
        return PlanResult(plans=plans, costs=final_costs, iterations=num_iterations)

    def to(self, device: str | torch.device) -> LangevinPlanner:
        """
        Move the planner's bounds to another device (in place).

        :param device: the target device.
        :return: this planner.
        """
        self.device = torch.device(device)
        self.state_low = None if self.state_low is None else self.state_low.to(self.device)
        self.state_high = None if self.state_high is None else self.state_high.to(self.device)
        return self
