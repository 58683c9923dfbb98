"""MPPI over state trajectories with smooth STOMP perturbations (paper Eq. 1 and Sec. 3.2; original ``mppi_step``).

Each iteration perturbs the current mean plan's states s_1..s_T (the start is pinned) with K smooth noise samples,
scores all N x K candidates with one cost call, and moves the mean to their softmax(-cost / temperature) average.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from ebm_agent.costs import PlanCost
from ebm_agent.planner import PlanResult, as_bounds, clip_states, initial_plan, validate_plan_inputs
from ebm_agent.stomp import StompNoise

__all__ = ["MPPIConfig", "MPPIPlanner"]


@dataclass
class MPPIConfig:
    """
    Settings of the MPPI planner; the defaults are the original code's (README command: T=10 flag default, K=80,
    80 iterations).

    :param horizon: T, the number of planned transitions.
    :param num_samples: K, the candidate plans per env and iteration (the original's noise_sim).
    :param iterations: MPPI iterations per plan (the original's num_plan_steps).
    :param temperature: lambda in softmax(-cost / lambda); the original hard-coded cost * 10000, i.e. 1e-4, which is
        close to picking the best candidate.
    :param noise_scale: c in N(0, c (A^T A)^-1).
    :param terminal_first_difference: keep the original's terminal first-difference row in the STOMP matrix.
    :param include_mean: also score the current mean as a candidate (the original did not), so the mean can only
        be replaced by a candidate that is at least as good when the temperature is low.
    """

    horizon: int = 10
    num_samples: int = 80
    iterations: int = 80
    temperature: float = 1e-4
    noise_scale: float = 1e-5
    terminal_first_difference: bool = True
    include_mean: bool = False

    def __post_init__(self) -> None:
        for name in ("horizon", "num_samples"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"MPPIConfig.{name} must be an int >= 1, got {value!r}.")
        if isinstance(self.iterations, bool) or not isinstance(self.iterations, int) or self.iterations < 0:
            raise ValueError(f"MPPIConfig.iterations must be an int >= 0, got {self.iterations!r}.")
        if not self.temperature > 0:
            raise ValueError(f"MPPIConfig.temperature must be > 0, got {self.temperature}; the original used 1e-4.")
        if not self.noise_scale > 0:
            raise ValueError(f"MPPIConfig.noise_scale must be > 0, got {self.noise_scale}; the original used 1e-5.")


class MPPIPlanner:
    """
    Model Predictive Path Integral planning in state space (implements ``Planner``).

    :param config: the planner settings.
    :param state_dim: D, the number of state dims.
    :param state_low: lower state bounds [D] that candidates and the mean are clipped to (the original clipped to
        [-1, 1] for every env but the arm), or None.
    :param state_high: upper state bounds [D], or None.
    :param device: device to plan on.
    """

    def __init__(
        self,
        config: MPPIConfig,
        state_dim: int,
        state_low: np.ndarray | Tensor | None = None,
        state_high: np.ndarray | Tensor | None = None,
        device: str | torch.device = "cpu",
    ) -> None:
        if not isinstance(config, MPPIConfig):
            raise TypeError(f"config must be an MPPIConfig, got {type(config).__name__}.")
        if isinstance(state_dim, bool) or not isinstance(state_dim, int) or state_dim < 1:
            raise ValueError(f"state_dim must be an int >= 1, got {state_dim!r}.")
        self.config = config
        self.horizon = config.horizon
        self.state_dim = state_dim
        self.device = torch.device(device)
        self.noise = StompNoise(config.horizon, config.noise_scale, config.terminal_first_difference, device=self.device)
        low, high = as_bounds(state_low, state_high, state_dim)
        self.state_low = None if low is None else low.to(self.device)
        self.state_high = None if high is None else high.to(self.device)

    def plan(
        self,
        start: Tensor,
        goals: Tensor | None,
        cost: PlanCost,
        init_plan: Tensor | None = None,
        generator: torch.Generator | None = None,
        iterations: int | None = None,
        noise: Tensor | None = None,
    ) -> PlanResult:
        """
        Plan from each env's start by MPPI.

        :param start: start states [N, D].
        :param goals: goals [N, G], or None when the cost has no goal energy.
        :param cost: the cost of candidate plans; it is evaluated without gradients.
        :param init_plan: warm start [N, T+1, D], or None to start with every state at the start. Its first state is
            replaced by ``start``.
        :param generator: random generator on the planner's device; the same seed gives the same plan.
        :param iterations: override ``config.iterations``.
        :param noise: pre-drawn perturbations [I, N, K, T, D] to use instead of sampling (for tests and
            reproducibility across batch sizes); I is then the number of iterations.
        :return: the plans [N, T+1, D] with ``plans[:, 0] == start``, their costs [N], and the iterations run.
        """
        validate_plan_inputs(start, goals, init_plan, self.horizon, self.state_dim, iterations)
        num_envs = start.shape[0]
        num_iterations = self.config.iterations if iterations is None else iterations
        if noise is not None:
            expected = (num_envs, self.config.num_samples, self.horizon, self.state_dim)
            if noise.ndim != 5 or tuple(noise.shape[1:]) != expected:
                raise ValueError(f"noise must be [I, N, K, T, D] with (N, K, T, D) = {expected}, got {tuple(noise.shape)}.")
            if iterations is not None and iterations != noise.shape[0]:
                raise ValueError(f"iterations={iterations} disagrees with the {noise.shape[0]} noise draws given.")
            num_iterations = noise.shape[0]
        with torch.inference_mode():
            start = start.to(self.device)
            goals = None if goals is None else goals.to(self.device)
            mean = initial_plan(start, self.horizon) if init_plan is None else init_plan.to(self.device, start.dtype).clone()
            mean[:, 0] = start
            mean[:, 1:] = clip_states(mean[:, 1:], self.state_low, self.state_high)
            for iteration in range(num_iterations):
                if noise is None:
                    perturbation = self.noise.sample((num_envs, self.config.num_samples), self.state_dim, generator)
                else:
                    perturbation = noise[iteration].to(self.device)
                mean = self.update(mean, perturbation.to(start.dtype), goals, cost)
            final_costs = cost(mean[:, None], goals)[:, 0]  # [N]
        # Cloning outside inference mode gives ordinary tensors that the agent may later feed to a trained energy.
        return PlanResult(plans=mean.clone(), costs=final_costs.clone(), iterations=num_iterations)

    def update(self, mean: Tensor, perturbation: Tensor, goals: Tensor | None, cost: PlanCost) -> Tensor:
        """
        One MPPI iteration: perturb, clip, score, and average the candidates by softmax(-cost / temperature).

        :param mean: current plans [N, T+1, D]; ``mean[:, 0]`` is the pinned start.
        :param perturbation: noise on states s_1..s_T [N, K, T, D].
        :param goals: goals [N, G] or None.
        :param cost: the cost of candidate plans.
        :return: the new plans [N, T+1, D], with the same start.
        """
        start, mean_tail = mean[:, :1], mean[:, 1:]  # [N, 1, D], [N, T, D]
        candidate_tails = clip_states(mean_tail[:, None] + perturbation, self.state_low, self.state_high)  # [N, K, T, D]
        if self.config.include_mean:
            candidate_tails = torch.cat([mean_tail[:, None], candidate_tails], dim=1)  # [N, K+1, T, D]
        num_candidates = candidate_tails.shape[1]
        starts = start[:, None].expand(-1, num_candidates, -1, -1)  # [N, K, 1, D]
        candidates = torch.cat([starts, candidate_tails], dim=2)  # [N, K, T+1, D]
        costs = cost(candidates, goals)  # [N, K]
        # A NaN or infinite cost (e.g. an energy that blew up) gets zero weight instead of poisoning the average.
        finite = torch.isfinite(costs)
        costs = torch.where(finite, costs, torch.full_like(costs, float("inf")))
        weights = torch.softmax(-costs / self.config.temperature, dim=1)  # [N, K]
        new_tail = (weights[:, :, None, None] * candidate_tails).sum(dim=1)  # [N, T, D]
        new_tail = clip_states(new_tail, self.state_low, self.state_high)
        # An env whose candidates all have non-finite costs keeps its mean.
        new_tail = torch.where(finite.any(dim=1)[:, None, None], new_tail, mean_tail)
        return torch.cat([start, new_tail], dim=1)

    def to(self, device: str | torch.device) -> MPPIPlanner:
        """
        Move the planner's noise factor and bounds to another device (in place).

        :param device: the target device.
        :return: this planner.
        """
        self.device = torch.device(device)
        self.noise.to(self.device)
        self.state_low = None if self.state_low is None else self.state_low.to(self.device)
        self.state_high = None if self.state_high is None else self.state_high.to(self.device)
        return self
