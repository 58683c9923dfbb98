"""The planner protocol shared by the state-space planners (MPPI, Langevin), their result type and warm-start helpers.

A plan holds T+1 states [s_0, s_1 .. s_T] with s_0 the pinned start: plans are [N, T+1, D] for N envs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np
import torch
from torch import Tensor

if TYPE_CHECKING:
    from ebm_agent.costs import PlanCost

__all__ = ["PlanResult", "Planner", "as_bounds", "clip_states", "initial_plan", "shift_plan", "validate_plan_inputs"]


@dataclass
class PlanResult:
    """
    What a planner returns.

    :param plans: the plans [N, T+1, D]; ``plans[:, 0]`` equals the start exactly.
    :param costs: the cost of each returned plan [N].
    :param iterations: how many iterations the planner ran.
    """

    plans: Tensor
    costs: Tensor
    iterations: int


@runtime_checkable
class Planner(Protocol):
    """A sampler of state-space plans from p(tau | s_0, g) ∝ exp(-cost(tau)), e.g. by MPPI or Langevin dynamics."""

    horizon: int

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
        Plan from each env's start.

        :param start: start states [N, D].
        :param goals: goals [N, G], or None when the cost has no goal energy.
        :param cost: the cost of candidate plans.
        :param init_plan: warm start [N, T+1, D] (e.g. the previous plan, shifted), or None to start with every state
            at the start (the original's smooth_path initialisation).
        :param generator: random generator for reproducible plans.
        :param iterations: override the configured number of iterations (the agent grows it adaptively).
        :return: the plans, their costs and the number of iterations run.
        """
        ...


def shift_plan(plans: Tensor, steps: Tensor | int) -> Tensor:
    """
    Drop the first ``steps`` states of each plan and pad by repeating its last state (warm start after execution).

    :param plans: plans [N, T+1, D].
    :param steps: states to drop: one int for all envs or a LongTensor [N] per env, each >= 0; shifting by T or more
        leaves every state at the last one.
    :return: shifted plans [N, T+1, D].
    """
    if plans.ndim != 3:
        raise ValueError(f"plans must be [N, T+1, D], got shape {tuple(plans.shape)}.")
    num_envs, num_states = plans.shape[:2]
    if isinstance(steps, Tensor):
        if steps.dtype.is_floating_point or steps.dtype == torch.bool:
            raise TypeError(f"steps must be an int or an integer tensor [N], got dtype {steps.dtype}.")
        steps = steps.to(device=plans.device, dtype=torch.long)
        if steps.ndim == 0:
            steps = steps.expand(num_envs)
        if steps.shape != (num_envs,):
            raise ValueError(f"steps must be a LongTensor [N] = [{num_envs}], got shape {tuple(steps.shape)}.")
    elif isinstance(steps, (int, np.integer)) and not isinstance(steps, bool):
        steps = torch.full((num_envs,), int(steps), device=plans.device, dtype=torch.long)
    else:
        raise TypeError(f"steps must be an int or a LongTensor [N], got {type(steps).__name__}.")
    if bool((steps < 0).any()):
        raise ValueError(f"steps must be >= 0 (states already executed), got {steps.tolist()}.")
    source = (torch.arange(num_states, device=plans.device)[None, :] + steps[:, None]).clamp_max(num_states - 1)  # [N, T+1]
    return torch.gather(plans, 1, source[..., None].expand_as(plans))


def initial_plan(start: Tensor, horizon: int) -> Tensor:
    """
    The original's smooth_path initialisation: every state of the plan at the start.

    :param start: start states [N, D].
    :param horizon: T, the number of planned transitions.
    :return: plans [N, T+1, D].
    """
    return start[:, None, :].expand(start.shape[0], horizon + 1, start.shape[1]).clone()


def as_bounds(
    low: np.ndarray | Tensor | None,
    high: np.ndarray | Tensor | None,
    state_dim: int,
    device: str | torch.device | None = None,
) -> tuple[Tensor | None, Tensor | None]:
    """
    Validate optional per-dim state bounds and convert them to float tensors.

    :param low: lower bounds [D] (or a scalar), or None for none.
    :param high: upper bounds [D] (or a scalar), or None for none.
    :param state_dim: D.
    :param device: device to put the bounds on (None: where they are).
    :return: (low [D] or None, high [D] or None) as float32 tensors; infinite entries mean unbounded.
    """
    bounds: list[Tensor | None] = []
    for name, value in (("state_low", low), ("state_high", high)):
        if value is None:
            bounds.append(None)
            continue
        tensor = (value if isinstance(value, Tensor) else torch.as_tensor(np.asarray(value))).to(torch.float32).flatten()
        if tensor.numel() == 1:
            tensor = tensor.expand(state_dim).clone()
        if tensor.numel() != state_dim:
            raise ValueError(f"{name} must have one value per state dim ({state_dim}), got {tensor.numel()} values.")
        bounds.append(tensor if device is None else tensor.to(device))
    if bounds[0] is not None and bounds[1] is not None and bool((bounds[0] > bounds[1]).any()):
        raise ValueError(f"state_low must be <= state_high on every dim, got {bounds[0].tolist()} and {bounds[1].tolist()}.")
    return bounds[0], bounds[1]


def validate_plan_inputs(
    start: Tensor, goals: Tensor | None, init_plan: Tensor | None, horizon: int, state_dim: int, iterations: int | None
) -> None:
    """
    Check a planner's inputs at the boundary, with errors that name the fix.

    :param start: start states, must be [N, D].
    :param goals: goals, must be [N, G] or None.
    :param init_plan: warm start, must be [N, T+1, D] or None.
    :param horizon: T.
    :param state_dim: D.
    :param iterations: iteration override, must be None or an int >= 0.
    """
    for name, tensor in (("start", start), ("goals", goals), ("init_plan", init_plan)):
        if isinstance(tensor, Tensor) and tensor.dtype.is_floating_point and not bool(torch.isfinite(tensor).all()):
            raise ValueError(
                f"{name} contains NaN or inf; the planner cannot plan from non-finite states. "
                "Check the observation or goal passed."
            )
    if not isinstance(start, Tensor) or not start.dtype.is_floating_point:
        raise TypeError(f"start must be a floating point tensor [N, D], got {type(start).__name__}.")
    if start.ndim != 2 or start.shape[1] != state_dim:
        raise ValueError(
            f"start must be [N, D] with D={state_dim}, got shape {tuple(start.shape)}; add a batch dim for one env."
        )
    num_envs = start.shape[0]
    if goals is not None and (not isinstance(goals, Tensor) or goals.ndim != 2 or goals.shape[0] != num_envs):
        shape = tuple(goals.shape) if isinstance(goals, Tensor) else type(goals).__name__
        raise ValueError(f"goals must be a tensor [N, G] with N={num_envs} (one goal per env) or None, got {shape}.")
    if init_plan is not None and (not isinstance(init_plan, Tensor) or init_plan.shape != (num_envs, horizon + 1, state_dim)):
        shape = tuple(init_plan.shape) if isinstance(init_plan, Tensor) else type(init_plan).__name__
        raise ValueError(
            f"init_plan must be [N, T+1, D] = [{num_envs}, {horizon + 1}, {state_dim}] or None, got {shape}; "
            "use shift_plan() to warm-start from a previous plan."
        )
    if iterations is not None and (isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 0):
        raise ValueError(f"iterations must be None (use the configured number) or an int >= 0, got {iterations!r}.")


def clip_states(states: Tensor, low: Tensor | None, high: Tensor | None) -> Tensor:
    """
    Clip states to optional per-dim bounds.

    :param states: states [..., D].
    :param low: lower bounds [D] or None.
    :param high: upper bounds [D] or None.
    :return: clipped states, same shape.
    """
    if low is None and high is None:
        return states
    return torch.clamp(
        states,
        min=None if low is None else low.to(states.dtype),
        max=None if high is None else high.to(states.dtype),
    )
