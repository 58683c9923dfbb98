"""Costs of candidate plans: the summed transition energy plus goal energies and extra energies (priors, obstacles).

Shapes: N envs, K candidates, T transitions, D state dims, G goal dims. A plan holds T+1 states, s_0 being the
pinned start, so candidate plans are [N, K, T+1, D] and every cost term is [N, K]. Lower is better: MPPI weights
candidates by softmax(-cost / temperature), i.e. the cost is the negative log of the unnormalised plan density
(paper Eq. 5-6).
"""

from __future__ import annotations

import copy
import functools
import re
from collections.abc import Callable, Sequence
from typing import Protocol, runtime_checkable

import numpy as np
import torch
from torch import Tensor

__all__ = [
    "AccelerationPrior",
    "BoxObstacleEnergy",
    "ExtraEnergy",
    "GaussianGoalEnergy",
    "GoalEnergy",
    "PlanCost",
    "RampedGoalEnergy",
    "RewardGoalEnergy",
    "TransitionEnergy",
    "VelocityPrior",
    "wrap_array",
    "wrap_difference",
]

TransitionEnergy = Callable[[Tensor, Tensor], Tensor]
"""(states [..., D], next_states [..., D]) -> energies [...]; e.g. an ``EnergyModel``."""

TRANSITION_WEIGHTS = ("uniform", "linear_decay")


@runtime_checkable
class GoalEnergy(Protocol):
    """A goal term: the cost of candidate plans [N, K, T+1, D] for goals [N, G], as [N, K]."""

    weight: float

    def __call__(self, plans: Tensor, goals: Tensor) -> Tensor: ...


@runtime_checkable
class ExtraEnergy(Protocol):
    """A goal-free term (prior, obstacle, constraint): the cost of candidate plans [N, K, T+1, D], as [N, K]."""

    weight: float

    def __call__(self, plans: Tensor) -> Tensor: ...


def wrap_difference(difference: Tensor, period: float | None) -> Tensor:
    """
    Map differences of periodic coordinates into [-period/2, period/2).

    :param difference: any differences, e.g. state - goal.
    :param period: the coordinate's period (2.0 for angles normalised to [-1, 1)), or None for no wrapping.
    :return: the wrapped differences, same shape.
    """
    if period is None:
        return difference
    half = 0.5 * period
    return torch.remainder(difference + half, period) - half


def wrap_array(difference: np.ndarray, period: float | np.ndarray | None) -> np.ndarray:
    """The numpy twin of :func:`wrap_difference`: differences of periodic coordinates in [-period/2, period/2).

    :param difference: [..., D] differences (e.g. s' - s).
    :param period: one period for every coordinate given, or [D] a period per dim (0: that dim is not periodic), or
        None for no wrapping.
    :return: the wrapped differences, same shape (``difference`` itself where nothing wraps).
    """
    if period is None:
        return difference
    if np.ndim(period) == 0:
        half = 0.5 * period
        return np.mod(difference + half, period) - half
    periods = np.asarray(period)
    periodic = periods > 0  # [D]
    out = np.array(difference, copy=True)
    half = 0.5 * periods[periodic]
    out[..., periodic] = np.mod(out[..., periodic] + half, periods[periodic]) - half
    return out


class _GoalTerm:
    """Shared settings of the goal energies that compare goal dims of plan states with the goal."""

    def __init__(self, goal_indices: Sequence[int], weight: float = 1.0, period: float | None = None) -> None:
        self.goal_indices = _check_indices(goal_indices, "goal_indices")
        self.weight = float(weight)
        self.period = _check_period(period)


class GaussianGoalEnergy(_GoalTerm):
    """
    Gaussian goal around the final state (paper Eq. 6): weight * sum_g (s_T[goal_indices] - g)^2.

    :param goal_indices: the G state dims the goal constrains, in the goal's order.
    :param weight: multiplier of the term.
    :param period: period of the goal coordinates (e.g. 2.0 for Reacher's normalised angles), or None.
    """

    def __call__(self, plans: Tensor, goals: Tensor) -> Tensor:
        """
        :param plans: candidate plans [N, K, T+1, D].
        :param goals: goals [N, G].
        :return: costs [N, K].
        """
        final_goal_states = select_dims(plans[..., -1, :], self.goal_indices)  # [N, K, G]
        check_goals(goals, plans, len(self.goal_indices))
        difference = wrap_difference(final_goal_states - goals[:, None, :], self.period)
        return self.weight * difference.square().sum(-1)


class RampedGoalEnergy(_GoalTerm):
    """
    The original code's goal term: weight * mean_{t,g} ((t/T)^2 (s_t[goal_indices] - g))^2 over t = 0..T.

    Quirk kept from the original (``train.py:1355-1403``; reference/original_code.md §3): every state is pulled
    towards the goal with a quartic-in-time ramp instead of the paper's final-state term (Eq. 6). The original
    multiplied the ramp by its l2_weight warm-up as well; here that warm-up is ``PlanCost.prior_scale``, applied once.

    :param goal_indices: the G state dims the goal constrains, in the goal's order.
    :param weight: multiplier of the term (the original's g_coeff: 1.0 in training, 10.0 in evaluation).
    :param period: period of the goal coordinates, or None.
    """

    def __call__(self, plans: Tensor, goals: Tensor) -> Tensor:
        """
        :param plans: candidate plans [N, K, T+1, D].
        :param goals: goals [N, G].
        :return: costs [N, K].
        """
        goal_states = select_dims(plans, self.goal_indices)  # [N, K, T+1, G]
        check_goals(goals, plans, len(self.goal_indices))
        horizon = plans.shape[-2] - 1
        ramp = (torch.arange(horizon + 1, device=plans.device, dtype=plans.dtype) / max(horizon, 1)).square()  # [T+1]
        difference = wrap_difference(goal_states - goals[:, None, None, :], self.period)
        return self.weight * (ramp[:, None] * difference).square().mean(dim=(-2, -1))


class RewardGoalEnergy:
    """
    Maximum-entropy goal (paper Sec. 3.2): P(O_t | s_t) = exp(R(s_t, g)), so cost = -weight * sum_{t=1..T} R(s_t, g).

    The start s_0 is excluded because it is pinned: its reward is the same for every candidate.

    :param reward_fn: R(states [..., D], goals [..., G]) -> rewards [...], batched over any leading shape.
    :param weight: multiplier of the term (an inverse temperature on the reward).
    """

    def __init__(self, reward_fn: Callable[[Tensor, Tensor], Tensor], weight: float = 1.0) -> None:
        if not callable(reward_fn):
            raise TypeError(f"reward_fn must be callable R(states [..., D], goals [..., G]) -> [...], got {reward_fn!r}.")
        self.reward_fn = reward_fn
        self.weight = float(weight)
        # (reward_fn, goal dims, period) when reward_fn is negative_l1's, whose cost __call__ computes in fewer ops.
        self._l1: tuple[Callable[[Tensor, Tensor], Tensor], tuple[int, ...], float | None] | None = None

    @classmethod
    def negative_l1(cls, goal_indices: Sequence[int], weight: float = 1.0, period: float | None = None) -> RewardGoalEnergy:
        """
        The reward of the particle, maze and Reacher envs: R(s, g) = -sum_g |s[goal_indices] - g| (wrapped if periodic).

        :param goal_indices: the G state dims the goal constrains.
        :param weight: multiplier of the term.
        :param period: period of the goal coordinates, or None.
        :return: the goal energy.
        """
        indices = _check_indices(goal_indices, "goal_indices")
        period = _check_period(period)

        def negative_l1_reward(states: Tensor, goals: Tensor) -> Tensor:
            return -wrap_difference(select_dims(states, indices) - goals, period).abs().sum(-1)

        energy = cls(negative_l1_reward, weight)
        energy._l1 = (negative_l1_reward, indices, period)
        return energy

    def __call__(self, plans: Tensor, goals: Tensor) -> Tensor:
        """
        :param plans: candidate plans [N, K, T+1, D].
        :param goals: goals [N, G].
        :return: costs [N, K].
        """
        if goals.ndim != 2 or goals.shape[0] != plans.shape[0]:
            raise ValueError(f"goals must be [N, G] with N={plans.shape[0]}, got shape {tuple(goals.shape)}.")
        planned = plans[..., 1:, :]  # [N, K, T, D]
        if self._l1 is not None and self._l1[0] is self.reward_fn:
            # The same cost, weight * sum_{t,g} |s_t[g] - goal_g|, in 3-4 ops instead of 6 (it runs every MPPI iteration).
            _, indices, period = self._l1
            check_goals(goals, plans, len(indices))
            difference = torch.sub(select_dims(planned, indices), goals[:, None, None, :])  # [N, K, T, G]
            cost = wrap_difference(difference, period).abs_().sum(dim=(-2, -1))  # [N, K]
            return cost if self.weight == 1.0 else cost.mul_(self.weight)
        goals_per_state = goals[:, None, None, :].expand(*planned.shape[:-1], goals.shape[-1])  # [N, K, T, G]
        rewards = self.reward_fn(planned, goals_per_state)  # [N, K, T]
        if rewards.shape != planned.shape[:-1]:
            raise ValueError(
                f"reward_fn must return one reward per state, shape {tuple(planned.shape[:-1])}, got {tuple(rewards.shape)}."
            )
        return -self.weight * rewards.sum(-1)


class VelocityPrior:
    """
    Penalise fast plans: weight * mean_{t,d} (s_{t+1} - s_t)^2 (the original's v_coeff term, 0.1 in training).

    :param weight: multiplier of the term.
    :param dims: state dims to include, or None for all (the original used all, even the arm's target dims).
    """

    def __init__(self, weight: float = 0.1, dims: Sequence[int] | None = None) -> None:
        self.weight = float(weight)
        self.dims = None if dims is None else _check_indices(dims, "dims")

    def __call__(self, plans: Tensor) -> Tensor:
        """
        :param plans: candidate plans [N, K, T+1, D].
        :return: costs [N, K].
        """
        states = plans if self.dims is None else select_dims(plans, self.dims)
        velocity = torch.diff(states, dim=-2)  # [N, K, T, D']: s_{t+1} - s_t
        return weighted_mean_square(velocity, self.weight)


class AccelerationPrior:
    """
    Penalise jerky plans: weight * mean_{t,d} (s_{t+2} - 2 s_{t+1} + s_t)^2 (the original's a_coeff term).

    With T < 2 there is no second difference and the term is zero.

    :param weight: multiplier of the term (0.01 in the original's training command).
    :param dims: state dims to include, or None for all.
    """

    def __init__(self, weight: float = 0.01, dims: Sequence[int] | None = None) -> None:
        self.weight = float(weight)
        self.dims = None if dims is None else _check_indices(dims, "dims")

    def __call__(self, plans: Tensor) -> Tensor:
        """
        :param plans: candidate plans [N, K, T+1, D].
        :return: costs [N, K].
        """
        states = plans if self.dims is None else select_dims(plans, self.dims)
        if states.shape[-2] < 3:
            return plans.new_zeros(plans.shape[:-2])
        acceleration = torch.diff(states, n=2, dim=-2)  # [N, K, T-1, D']: s_{t+2} - 2 s_{t+1} + s_t
        return weighted_mean_square(acceleration, self.weight)


class BoxObstacleEnergy:
    """
    A test-time obstacle as an energy: penalise plan states inside an axis-aligned box and segments crossing it.

    Each transition s_t -> s_{t+1} is sampled at ``samples_per_segment`` evenly spaced points (ending at s_{t+1}),
    and each point inside the box (grown by ``margin``) costs its penetration depth, the distance to the nearest box
    face. The depth is continuous and grows towards the box centre, so sampled candidates that cut a corner cost
    little and candidates through the middle cost much, which lets MPPI route around the box:
    cost = weight * sum_t mean_points depth.

    :param low: lower corner of the box, one value per entry of ``dims``.
    :param high: upper corner of the box, one value per entry of ``dims``.
    :param dims: the state dims the box lives in (the position dims).
    :param weight: multiplier of the term; large so that crossing is never worth it.
    :param margin: grow the box by this much on every side (a safety distance), >= 0.
    :param samples_per_segment: points checked per transition, so that a fast segment cannot jump over the box.
    """

    def __init__(
        self,
        low: Sequence[float],
        high: Sequence[float],
        dims: Sequence[int] = (0, 1),
        weight: float = 100.0,
        margin: float = 0.0,
        samples_per_segment: int = 8,
    ) -> None:
        self.dims = _check_indices(dims, "dims")
        self.low = torch.as_tensor(low, dtype=torch.float64).flatten()
        self.high = torch.as_tensor(high, dtype=torch.float64).flatten()
        if self.low.numel() != len(self.dims) or self.high.numel() != len(self.dims):
            raise ValueError(
                f"low and high need one value per box dim (dims={self.dims}), got {self.low.numel()} and {self.high.numel()}."
            )
        if not bool((self.low < self.high).all()):
            raise ValueError(
                f"the box needs low < high on every axis, got low={self.low.tolist()}, high={self.high.tolist()}."
            )
        if margin < 0:
            raise ValueError(f"margin must be >= 0 (it grows the box), got {margin}.")
        if samples_per_segment < 1:
            raise ValueError(f"samples_per_segment must be >= 1, got {samples_per_segment}.")
        self.weight = float(weight)
        self.margin = float(margin)
        self.samples_per_segment = int(samples_per_segment)
        self._box_cache: dict[str, object] = {}

    def penetration_depth(self, points: Tensor) -> Tensor:
        """
        Distance from points inside the (grown) box to its nearest face; zero outside.

        :param points: positions [..., len(dims)] (already restricted to the box dims).
        :return: depths [...], >= 0.
        """
        low, high = self._grown_box(points.device, points.dtype)
        distance_to_faces = torch.minimum(points - low, high - points)  # [..., B] negative outside on that axis
        return distance_to_faces.amin(-1).clamp_min(0.0)

    def _grown_box(self, device: torch.device, dtype: torch.dtype) -> tuple[Tensor, Tensor]:
        # Cached per device and dtype: a fresh host-to-device copy in every MPPI iteration would sync a CUDA stream.
        key = (device, dtype, self.margin, id(self.low), id(self.high))
        if self._box_cache.get("key") != key:
            low = (self.low - self.margin).to(device=device, dtype=dtype)
            high = (self.high + self.margin).to(device=device, dtype=dtype)
            self._box_cache = {"key": key, "box": (low, high)}
        return self._box_cache["box"]  # type: ignore[return-value]

    def __call__(self, plans: Tensor) -> Tensor:
        """
        :param plans: candidate plans [N, K, T+1, D].
        :return: costs [N, K].
        """
        positions = select_dims(plans, self.dims)  # [N, K, T+1, B]
        fractions = torch.arange(1, self.samples_per_segment + 1, device=plans.device, dtype=plans.dtype)
        fractions = fractions / self.samples_per_segment  # [S] in (0, 1]
        starts, ends = positions[..., :-1, None, :], positions[..., 1:, None, :]  # [N, K, T, 1, B]
        points = starts + fractions[:, None] * (ends - starts)  # [N, K, T, S, B]
        return self.weight * self.penetration_depth(points).mean(-1).sum(-1)


class PlanCost:
    """
    Total cost of candidate plans: sum_t E(s_t, s_{t+1}) + goal energy + extra energies.

    The transition energies of all N*K*T pairs are one call of ``transition_energy``. ``prior_scale`` multiplies the
    goal and extra terms (the original's l2_weight warm-up over the first 200 online iterations; 1.0 by default).

    :param transition_energy: E(states [..., D], next_states [..., D]) -> [...], or None for no dynamics term.
    :param goal_energy: the goal term, or None.
    :param extra_energies: goal-free terms (priors, obstacles).
    :param transition_weights: "uniform" (MPPI in the original) or "linear_decay", weighting transition t by
        T - t as the original's gradient planner did.
    """

    def __init__(
        self,
        transition_energy: TransitionEnergy | None,
        goal_energy: GoalEnergy | None = None,
        extra_energies: Sequence[ExtraEnergy] = (),
        transition_weights: str = "uniform",
    ) -> None:
        if transition_energy is not None and not callable(transition_energy):
            raise TypeError(
                f"transition_energy must be callable E(states, next_states) -> energies, got {transition_energy!r}."
            )
        if goal_energy is not None and not callable(goal_energy):
            raise TypeError(f"goal_energy must be callable (plans, goals) -> [N, K], got {goal_energy!r}.")
        for extra in extra_energies:
            if not callable(extra):
                raise TypeError(f"every extra energy must be callable plans -> [N, K], got {extra!r}.")
        if transition_weights not in TRANSITION_WEIGHTS:
            raise ValueError(f"transition_weights must be one of {TRANSITION_WEIGHTS}, got {transition_weights!r}.")
        self.transition_energy = transition_energy
        self.goal_energy = goal_energy
        self.extra_energies: tuple[ExtraEnergy, ...] = tuple(extra_energies)
        self.transition_weights = transition_weights
        self.prior_scale: float = 1.0

    def __call__(self, plans: Tensor, goals: Tensor | None) -> Tensor:
        """
        :param plans: candidate plans [N, K, T+1, D].
        :param goals: goals [N, G], or None when there is no goal energy.
        :return: total costs [N, K].
        """
        return torch.stack(self._term_values(plans, goals)).sum(0)

    def terms(self, plans: Tensor, goals: Tensor | None) -> dict[str, Tensor]:
        """
        Every term of the cost, for logging; their sum is the total cost.

        :param plans: candidate plans [N, K, T+1, D].
        :param goals: goals [N, G], or None when there is no goal energy.
        :return: {"transition": [N, K], "goal": [N, K], one entry per extra energy named after its class}; a term
            that is not configured is absent, except "transition", which is zeros without a transition energy.
        """
        values = iter(self._term_values(plans, goals))
        terms = {"transition": next(values)}
        if self.goal_energy is not None:
            terms["goal"] = next(values)
        for extra in self.extra_energies:
            terms[_unique_name(_snake_case(type(extra).__name__), terms)] = next(values)
        return terms

    def _term_values(self, plans: Tensor, goals: Tensor | None) -> list[Tensor]:
        # The unnamed terms in the order of terms(): __call__ runs once per MPPI iteration, so it skips the naming.
        if plans.ndim != 4 or plans.shape[-2] < 2:
            raise ValueError(f"plans must be [N, K, T+1, D] with T >= 1, got shape {tuple(plans.shape)}.")
        values = [self._transition_term(plans)]
        if self.goal_energy is not None:
            if goals is None:
                raise ValueError("this PlanCost has a goal energy, so goals [N, G] must be given (got None).")
            values.append(self._checked(self._scaled(self.goal_energy(plans, goals)), plans, "goal energy"))
        for extra in self.extra_energies:
            values.append(self._checked(self._scaled(extra(plans)), plans, type(extra).__name__))
        return values

    def _scaled(self, term: Tensor) -> Tensor:
        # Skipping the multiplication by the usual 1.0 saves one op per term and MPPI iteration (same values).
        return term if self.prior_scale == 1.0 else self.prior_scale * term

    def with_extra(self, *extra: ExtraEnergy) -> PlanCost:
        """
        A copy with more extra energies (e.g. obstacles known only at plan time); this cost is unchanged.

        :param extra: the energies to add.
        :return: the new cost, with the same prior_scale.
        """
        new_cost = copy.copy(self)
        new_cost.extra_energies = self.extra_energies + tuple(extra)
        return new_cost

    def _transition_term(self, plans: Tensor) -> Tensor:
        if self.transition_energy is None:
            return plans.new_zeros(plans.shape[:2])
        energies = self.transition_energy(plans[..., :-1, :], plans[..., 1:, :])  # [N, K, T]
        expected = (*plans.shape[:2], plans.shape[-2] - 1)
        if energies.shape != expected:
            raise ValueError(
                f"transition_energy must return one energy per transition, shape {tuple(expected)}, got "
                f"{tuple(energies.shape)}; an nn.Module energy should squeeze its last output dim."
            )
        if energies.dtype != plans.dtype and energies.dtype.is_floating_point:
            # An energy run under autocast returns bf16/fp16; summing T of those in reduced precision loses the
            # small differences MPPI's low temperature resolves, so the sum runs in the plans' dtype.
            energies = energies.to(plans.dtype)
        if self.transition_weights == "linear_decay":
            horizon = energies.shape[-1]
            # T - t for t = 0..T-1: early transitions matter most, as the original's gradient planner weighted them.
            weights = torch.arange(horizon, 0, -1, device=energies.device, dtype=energies.dtype)
            energies = energies * weights
        return energies.sum(-1)

    @staticmethod
    def _checked(term: Tensor, plans: Tensor, name: str) -> Tensor:
        if term.shape != plans.shape[:2]:
            raise ValueError(
                f"{name} must return one cost per candidate, shape {tuple(plans.shape[:2])}, got {tuple(term.shape)}."
            )
        return term


def select_dims(tensor: Tensor, indices: tuple[int, ...]) -> Tensor:
    """
    The state dims ``indices`` of ``tensor`` [..., D]: a view when they are consecutive, else a gathered copy.

    :param tensor: states [..., D].
    :param indices: the dims, each < D.
    :return: [..., len(indices)].
    """
    if max(indices) >= tensor.shape[-1]:
        raise ValueError(f"state dims {indices} are out of range for states with {tensor.shape[-1]} dims.")
    run = _as_slice(indices)
    # A run of consecutive dims (the usual goal and position dims) is a view: no gather copy, and on CUDA no
    # host-to-device transfer of an index list in every planner iteration.
    return tensor[..., list(indices)] if run is None else tensor[..., run]


@functools.lru_cache(maxsize=256)
def _as_slice(indices: tuple[int, ...]) -> slice | None:
    first = indices[0]
    return slice(first, first + len(indices)) if indices == tuple(range(first, first + len(indices))) else None


def _check_indices(indices: Sequence[int], name: str) -> tuple[int, ...]:
    result = tuple(int(index) for index in indices)
    if not result or min(result) < 0:
        raise ValueError(f"{name} must be a non-empty sequence of non-negative state dims, got {indices!r}.")
    return result


def _check_period(period: float | None) -> float | None:
    if period is not None and not period > 0:
        raise ValueError(f"period must be > 0 (e.g. 2.0 for angles in [-1, 1)) or None, got {period}.")
    return None if period is None else float(period)


def weighted_mean_square(values: Tensor, weight: float) -> Tensor:
    """
    weight * mean of values^2 over the last two dims, in 3 ops (the priors run in every MPPI iteration).

    :param values: [N, K, a, b], e.g. finite differences of plans.
    :param weight: the multiplier.
    :return: [N, K].
    """
    count = values.shape[-2] * values.shape[-1]
    norm = torch.linalg.vector_norm(values, dim=(-2, -1))
    if values.requires_grad:  # the norm's backward needs its output: no in-place ops (the Langevin planner's gradient)
        return norm.square().mul(weight / max(count, 1))
    return norm.square_().mul_(weight / max(count, 1))


def check_goals(goals: Tensor, plans: Tensor, goal_dim: int) -> None:
    """
    Raise a ValueError unless goals is [N, G] with N plans' envs and G = goal_dim.

    :param goals: the goals.
    :param plans: candidate plans [N, K, T+1, D].
    :param goal_dim: G.
    """
    if goals.ndim != 2 or goals.shape[0] != plans.shape[0] or goals.shape[1] != goal_dim:
        raise ValueError(
            f"goals must be [N, G] = [{plans.shape[0]}, {goal_dim}] (one goal per env, one value per goal index), "
            f"got shape {tuple(goals.shape)}."
        )


def _snake_case(name: str) -> str:
    return re.sub(r"(?<!^)(?=[A-Z])", "_", name).lower()


def _unique_name(name: str, taken: dict[str, Tensor]) -> str:
    candidate, index = name, 1
    while candidate in taken:
        index += 1
        candidate = f"{name}_{index}"
    return candidate
