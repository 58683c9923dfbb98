"""A plan cost bound to the planner's candidate buffer: the same numbers, with the per-call work done once per plan.

MPPI rewrites one candidate buffer [N, K', T+1, D] in place every iteration and scores it ~80 times per plan. Calling
:class:`~ebm_agent.costs.PlanCost` on it each time repeats the argument checks and rebuilds a dozen views (the
transition pairs, the goal dims, the finite differences of the priors), each a few microseconds of Python and
dispatcher work next to ~300 microseconds of arithmetic per iteration at the agent's default size. :func:`bind_cost`
does that once: it returns a function of no arguments that evaluates the current contents of the buffer with the same
torch operations in the same order as ``cost(plans, goals)``, so the costs are equal bit for bit. Terms it does not
know are called as they are.

What is read when binding (once per plan): ``prior_scale``, the weights of the terms and the goals. Change them before
planning, as the agent does, not during a plan.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import torch
from torch import Tensor

from ebm_agent.costs import (
    AccelerationPrior,
    ExtraEnergy,
    GoalEnergy,
    PlanCost,
    RewardGoalEnergy,
    VelocityPrior,
    check_goals,
    select_dims,
    weighted_mean_square,
    wrap_difference,
)

__all__ = ["bind_cost"]

Bound = Callable[[], Tensor]
"""A function of no arguments returning a cost term [N, K] (or energies) of the bound buffer's current contents."""


def bind_cost(cost: Callable[[Tensor, Tensor | None], Tensor], plans: Tensor, goals: Tensor | None) -> Bound:
    """
    ``cost(plans, goals)`` as a function of no arguments that re-reads ``plans`` on every call.

    The first call runs ``cost(plans, goals)`` itself, so every check of :class:`PlanCost` (term shapes, goals given)
    runs once per plan; later calls take the bound path. Costs that are not a ``PlanCost`` are called as they are.

    :param cost: the plan cost.
    :param plans: the candidate buffer [N, K', T+1, D] (or a chunk of it along K'), kept by reference.
    :param goals: goals [N, G], or None.
    :return: a function returning the costs [N, K'] of the buffer's current contents.
    """
    if not isinstance(cost, PlanCost):
        return functools.partial(cost, plans, goals)
    if plans.ndim != 4 or plans.shape[-2] < 2:
        raise ValueError(f"plans must be [N, K, T+1, D] with T >= 1, got shape {tuple(plans.shape)}.")
    if cost.goal_energy is not None and goals is None:
        raise ValueError("this PlanCost has a goal energy, so goals [N, G] must be given (got None).")
    terms = [_bind_transition(cost, plans)]
    if cost.goal_energy is not None:
        assert goals is not None
        terms.append(_scaled(_bind_goal(cost.goal_energy, plans, goals), cost.prior_scale))
    terms.extend(_scaled(_bind_extra(extra, plans), cost.prior_scale) for extra in cost.extra_energies)
    checked = False

    def total() -> Tensor:
        nonlocal checked
        if not checked:
            checked = True
            return cost(plans, goals)
        return torch.stack([term() for term in terms]).sum(0)  # as PlanCost.__call__ sums its terms

    return total


def _scaled(term: Bound, scale: float) -> Bound:
    if scale == 1.0:  # PlanCost skips the multiplication by 1.0 too
        return term
    return lambda: scale * term()


def _bind_transition(cost: PlanCost, plans: Tensor) -> Bound:
    """sum_t E(s_t, s_{t+1}) [N, K] as PlanCost computes it (cast to the plans' dtype, optional linear decay)."""
    energy = cost.transition_energy
    if energy is None:
        return lambda: plans.new_zeros(plans.shape[:2])
    states, next_states = plans[..., :-1, :], plans[..., 1:, :]  # [N, K, T, D] views
    bind = getattr(energy, "bind", None)
    energies_of: Bound = bind(states, next_states) if callable(bind) else functools.partial(energy, states, next_states)
    dtype = plans.dtype
    weights = None
    if cost.transition_weights == "linear_decay":
        weights = torch.arange(plans.shape[-2] - 1, 0, -1, device=plans.device, dtype=dtype)  # [T]: T - t

    def transition() -> Tensor:
        energies = energies_of()  # [N, K, T]
        if energies.dtype != dtype and energies.dtype.is_floating_point:
            energies = energies.to(dtype)
        if weights is not None:
            energies = energies * weights
        return energies.sum(-1)

    return transition


def _bind_goal(goal_energy: GoalEnergy, plans: Tensor, goals: Tensor) -> Bound:
    l1 = getattr(goal_energy, "_l1", None)
    if isinstance(goal_energy, RewardGoalEnergy) and l1 is not None and l1[0] is goal_energy.reward_fn:
        _, indices, period = l1
        check_goals(goals, plans, len(indices))
        selected = _dims_view(plans[..., 1:, :], indices)  # [N, K, T, G]
        if selected is None:
            return functools.partial(goal_energy, plans, goals)
        goal_view = goals[:, None, None, :]  # [N, 1, 1, G]
        weight = goal_energy.weight

        def l1_cost() -> Tensor:  # RewardGoalEnergy.__call__'s negative-L1 path
            cost = wrap_difference(torch.sub(selected, goal_view), period).abs_().sum(dim=(-2, -1))
            return cost if weight == 1.0 else cost.mul_(weight)

        return l1_cost
    return functools.partial(goal_energy, plans, goals)


def _bind_extra(extra: ExtraEnergy, plans: Tensor) -> Bound:
    if type(extra) in (VelocityPrior, AccelerationPrior):
        prior: VelocityPrior | AccelerationPrior = extra  # type: ignore[assignment]
        states = plans if prior.dims is None else _dims_view(plans, prior.dims)  # [N, K, T+1, D']
        if states is None:
            return functools.partial(extra, plans)
        later, earlier = states[..., 1:, :], states[..., :-1, :]  # what torch.diff subtracts
        weight = prior.weight
        if isinstance(prior, VelocityPrior):
            return lambda: weighted_mean_square(torch.sub(later, earlier), weight)
        if states.shape[-2] >= 3:
            return lambda: weighted_mean_square(torch.diff(torch.sub(later, earlier), dim=-2), weight)
    return functools.partial(extra, plans)


def _dims_view(tensor: Tensor, indices: tuple[int, ...]) -> Tensor | None:
    """The dims ``indices`` of ``tensor`` as a view that follows later writes, or None where selecting them copies."""
    selected = select_dims(tensor, indices)
    return selected if selected.untyped_storage().data_ptr() == tensor.untyped_storage().data_ptr() else None
