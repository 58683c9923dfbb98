"""The real one-step moves s' - s an agent has seen: one running statistics object, periodic dims the short way round.

An env's own scale is in its real moves: the maze moves at most 0.05 per dim and step, Reacher's angles 0.0126, the
Sawyer's joints their own. Everything in the agent that is sized by "one real step" reads it here (the reach box of
``loss="infonce_reach"``, the clip of ``online.hard_negative_reach``, the move normalisation of
``EnergyConfig.move_input`` and the perturbed negatives), so that every one of them wraps periodic dims: a move
across an angle's wrap at +-1 is the small move it is, not a jump of 2.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ebm_agent.costs import wrap_array

__all__ = ["MoveStatistics", "state_periods"]


def state_periods(goal_spec: Any, dims: int) -> np.ndarray | None:
    """The period of each state dim (0: not periodic), or None where no dim is periodic.

    The goal dims are periodic when the goal spec has a ``goal_period`` (the convention of the agent's costs and
    energy: Reacher's angles, normalised to [-1, 1), have period 2).

    :param goal_spec: an agent's ``goal_spec`` (``ebm_agent.goal_spec.GoalSpec``) or None.
    :param dims: the state's size D.
    :return: [D] float32 periods, or None.
    """
    period = getattr(goal_spec, "goal_period", None)
    if period is None:
        return None
    periods = np.zeros(dims, dtype=np.float32)
    periods[np.asarray(goal_spec.goal_indices)] = float(period)
    return periods


class MoveStatistics:
    """Running count, mean, std and largest magnitude per state dim of the real moves s' - s.

    :param periods: [D] the period of each state dim (0: not periodic), or None for none (:func:`state_periods`).
    """

    def __init__(self, periods: np.ndarray | None = None) -> None:
        self.periods = None if periods is None else np.asarray(periods, dtype=np.float32)
        self._sums: np.ndarray | None = None  # [3, D] float64: count, sum and sum of squares of the moves
        self._largest: np.ndarray | None = None  # [D] largest |s' - s| seen, in the transitions' dtype

    def moves(self, states: np.ndarray, next_states: np.ndarray) -> np.ndarray:
        """The moves s' - s of transitions, periodic dims wrapped into [-period / 2, period / 2).

        :param states: [M, D] real states.
        :param next_states: [M, D] their real next states.
        :return: [M, D] moves, in the transitions' dtype.
        """
        states, next_states = np.asarray(states), np.asarray(next_states)
        if states.ndim != 2 or states.shape != next_states.shape:
            raise ValueError(
                f"states and next_states must be [M, D] arrays alike, got {states.shape} and {next_states.shape}."
            )
        if self.periods is not None and len(self.periods) != states.shape[1]:
            raise ValueError(f"periods has {len(self.periods)} dims but the states have {states.shape[1]}.")
        return wrap_array(next_states - states, self.periods)

    def update(self, states: np.ndarray, next_states: np.ndarray) -> MoveStatistics:
        """Add real transitions (no-op for none).

        :param states: [M, D] real states.
        :param next_states: [M, D] their real next states.
        :return: self.
        """
        moves = self.moves(states, next_states)  # [M, D]
        if len(moves) == 0:
            return self
        largest = np.abs(moves).max(axis=0)  # [D]
        self._largest = largest if self._largest is None else np.maximum(self._largest, largest)
        wide = moves.astype(np.float64)  # [M, D]
        update = np.stack([np.full(wide.shape[1], len(wide), dtype=np.float64), wide.sum(0), np.square(wide).sum(0)])
        self._sums = update if self._sums is None else self._sums + update
        return self

    @property
    def count(self) -> int:
        """How many moves were added."""
        return 0 if self._sums is None else int(self._sums[0, 0])

    @property
    def mean(self) -> np.ndarray:
        """[D] float64 mean move; raises before any move was added."""
        count, total, _ = self._checked_sums()
        return total / count

    @property
    def std(self) -> np.ndarray:
        """[D] float64 std of the moves, plus 1e-6 so that a dim that never moved can be divided by."""
        count, total, squares = self._checked_sums()
        mean = total / count
        return np.sqrt(np.maximum(squares / count - np.square(mean), 0.0)) + 1e-6

    @property
    def largest(self) -> np.ndarray:
        """[D] the largest |s' - s| seen per dim (the env's real step); raises before any move was added."""
        if self._largest is None:
            raise RuntimeError("MoveStatistics: no move added yet; call update(states, next_states) first.")
        return self._largest

    def state_dict(self) -> dict[str, Any]:
        """:return: the running sums and largest moves (None before any move), to restore with :meth:`load_state_dict`."""
        return {
            "sums": None if self._sums is None else self._sums.copy(),
            "largest": None if self._largest is None else self._largest.copy(),
        }

    def load_state_dict(self, state: dict[str, Any] | None) -> None:
        """:param state: a dict from :meth:`state_dict`, or None for no move recorded."""
        state = state or {}
        sums, largest = state.get("sums"), state.get("largest")
        self._sums = None if sums is None else np.asarray(sums, dtype=np.float64).copy()
        self._largest = None if largest is None else np.asarray(largest).copy()

    def _checked_sums(self) -> np.ndarray:
        if self._sums is None:
            raise RuntimeError("MoveStatistics: no move added yet; call update(states, next_states) first.")
        return self._sums
