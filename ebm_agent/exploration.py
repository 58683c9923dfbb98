"""Measuring exploration while any SB3 algorithm learns: visited states, grid coverage, energy snapshots.

- :func:`count_occupied_cells`, :func:`grid_counts`, :func:`grid_coverage`: occupancy of a regular grid (the
  original's maze heatmap is 20 x 20 over [-1, 1]^2).
- :class:`VisitedStatesCallback` keeps every ``achieved_goal`` an agent sees and records an occupancy curve at
  chosen transition counts (logged as ``explore/occupancy``); it works with any SB3 algorithm whose ``learn`` puts
  ``new_obs``, ``dones`` and ``infos`` in the callback locals (the EBM agent, Action FF, the random agent, PPO, SAC).
- :class:`EnergyMapCallback` also snapshots a 2-D EBM's energy map and the visitation grid at those counts.

Example, the coverage of the maze by PPO every 10,000 transitions::

    from ebm_agent.exploration import VisitedStatesCallback, grid_coverage, linear_checkpoints

    callback = VisitedStatesCallback(linear_checkpoints(50_000, 5), grid_coverage)
    PPO("MultiInputPolicy", env).learn(50_000, callback=callback)
    print(callback.curve_timesteps, callback.curve_values)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback

from ebm_agent.visualize import energy_map


def count_occupied_cells(
    states: np.ndarray, bins: int | tuple[int, ...], low: float | np.ndarray, high: float | np.ndarray
) -> int:
    """Count the cells of a regular grid over the box [low, high] that contain at least one of ``states``.

    :param states: points [M, G].
    :param bins: cells per dimension (int or one per dimension, each >= 1).
    :param low: lower corner, scalar or [G].
    :param high: upper corner, scalar or [G]; points exactly on it fall in the last cell.
    :return: number of occupied cells.
    """
    states = np.asarray(states, dtype=np.float64)
    if states.ndim != 2:
        raise ValueError(f"states must be [M, G], got shape {states.shape}.")
    n_dims = states.shape[1]
    bins_arr = np.broadcast_to(np.asarray(bins, dtype=np.int64), (n_dims,))
    low_arr = np.broadcast_to(np.asarray(low, dtype=np.float64), (n_dims,))
    high_arr = np.broadcast_to(np.asarray(high, dtype=np.float64), (n_dims,))
    if np.any(bins_arr < 1):
        raise ValueError(f"bins must be >= 1 in every dimension, got {bins}.")
    if np.any(high_arr <= low_arr):
        raise ValueError(f"high must exceed low in every dimension, got low={low}, high={high}.")
    if len(states) == 0:
        return 0
    inside = np.all((states >= low_arr) & (states <= high_arr), axis=1)
    cells = np.floor((states[inside] - low_arr) / (high_arr - low_arr) * bins_arr).astype(np.int64)  # [m, G]
    cells = np.minimum(cells, bins_arr - 1)
    return len(np.unique(cells, axis=0))


def grid_counts(points: np.ndarray, bins: int = 20, low: float = -1.0, high: float = 1.0) -> np.ndarray:
    """Visit counts of a square grid over [low, high]^2 (the original's maze heatmap, before its log).

    :param points: [M, 2] (x, y) positions; points outside the box are ignored.
    :param bins: cells per axis.
    :param low: lower corner on both axes.
    :param high: upper corner on both axes.
    :return: [bins, bins] counts, row index = y, column index = x (``imshow(origin="lower")`` order).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    counts, _, _ = np.histogram2d(points[:, 1], points[:, 0], bins=bins, range=[[low, high], [low, high]])
    return counts


def grid_coverage(points: np.ndarray, bins: int = 20, low: float = -1.0, high: float = 1.0) -> float:
    """Fraction of the cells of a square grid over [low, high]^2 holding at least one point.

    :param points: [M, 2] positions.
    :param bins: cells per axis.
    :param low: lower corner.
    :param high: upper corner.
    :return: occupied cells / bins^2, in [0, 1].
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    return count_occupied_cells(points, bins, low, high) / bins**2


def linear_checkpoints(total: int, points: int) -> list[int]:
    """``points`` transition counts evenly spaced up to ``total`` (the last is ``total``).

    :param total: the budget.
    :param points: how many.
    :return: sorted distinct counts in [1, total].
    """
    return sorted({max(1, round(total * (i + 1) / points)) for i in range(points)})


def log_checkpoints(total: int, points: int, first: int = 10) -> list[int]:
    """``points`` transition counts log-spaced from ``first`` to ``total`` (for a log x axis).

    :param total: the budget.
    :param points: how many.
    :param first: the first count.
    :return: sorted distinct counts in [1, total].
    """
    first = max(1, min(first, total))
    return sorted({round(v) for v in np.geomspace(first, total, points)} | {total})


class VisitedStatesCallback(BaseCallback):
    """Keep every visited ``achieved_goal`` and record ``measure(visited so far)`` at chosen transition counts.

    Visited states are the first observation, each step's new observations, and the real last observation of
    finished episodes (``terminal_observation``). A checkpoint is recorded at the first step whose transition count
    reaches it (SB3 callbacks see one vectorised step, ``n_envs`` transitions, at a time) and at the end of training.

    :param checkpoints: transition counts to record at.
    :param measure: visited states [M, G] -> a number (e.g. :func:`grid_coverage`), or None to only keep states.
    :param key: the observation entry that is recorded.
    :param verbose: SB3 verbosity.
    """

    def __init__(
        self,
        checkpoints: Sequence[int] = (),
        measure: Callable[[np.ndarray], float] | None = None,
        key: str = "achieved_goal",
        verbose: int = 0,
    ) -> None:
        super().__init__(verbose)
        self.checkpoints = sorted(int(c) for c in checkpoints)
        self.measure = measure
        self.key = key
        self.curve_timesteps: list[int] = []
        self.curve_values: list[float] = []
        self._chunks: list[np.ndarray] = []  # each [n, G]
        self._steps: list[np.ndarray] = []  # each [n]
        self._next = 0  # index of the next checkpoint

    @property
    def visited_states(self) -> np.ndarray:
        """All visited states in order: [M, G]."""
        return np.concatenate(self._chunks) if self._chunks else np.zeros((0, 0))

    @property
    def visited_timesteps(self) -> np.ndarray:
        """Transition count at which each row of :attr:`visited_states` was seen: [M]."""
        return np.concatenate(self._steps) if self._steps else np.zeros(0, dtype=np.int64)

    def _on_training_start(self) -> None:
        self._record_observation(getattr(self.model, "_last_obs", None))

    def _on_step(self) -> bool:
        dones = np.asarray(self.locals.get("dones", []), dtype=bool)
        infos = self.locals.get("infos", [])
        for index in np.flatnonzero(dones):
            self._record_observation(infos[index].get("terminal_observation"))
        self._record_observation(self.locals.get("new_obs"))
        while self._next < len(self.checkpoints) and self.num_timesteps >= self.checkpoints[self._next]:
            self._next += 1
            self._checkpoint()
        return True

    def _on_training_end(self) -> None:
        if not self.curve_timesteps or self.curve_timesteps[-1] != self.num_timesteps:
            self._checkpoint()

    def _checkpoint(self) -> None:
        """Record the measure of everything visited so far (subclasses add their own snapshots)."""
        if self.measure is None:
            return
        value = float(self.measure(self.visited_states))
        self.curve_timesteps.append(int(self.num_timesteps))
        self.curve_values.append(value)
        self.logger.record("explore/occupancy", value)

    def _record_observation(self, observation: Any) -> None:
        if observation is None:
            return
        states = observation[self.key] if isinstance(observation, dict) else observation
        states = np.asarray(states, dtype=np.float64)
        states = states.reshape(1, -1) if states.ndim == 1 else states.reshape(states.shape[0], -1)  # [n, G]
        self._chunks.append(states)
        self._steps.append(np.full(len(states), self.num_timesteps, dtype=np.int64))


@dataclass
class EnergySnapshot:
    """The energy landscape and the visits at one point of training.

    :param timestep: transitions consumed.
    :param energies: [R, R] energy map (``ebm_agent.visualize.energy_map``), row = y.
    :param visit_counts: [B, B] visit counts of the coverage grid, row = y.
    :param cell_energies: [B, B] energy of a move centred on each grid cell's centre, row = y.
    """

    timestep: int
    energies: np.ndarray
    visit_counts: np.ndarray
    cell_energies: np.ndarray


class EnergyMapCallback(VisitedStatesCallback):
    """Snapshot the energy map of a 2-D EBM agent and its visitation grid at chosen transition counts.

    As the original's ``--energy_heatmap``: the energy of a small diagonal move (0.02, 0.02) centred at each point
    of a grid; low energy is where the model believes the agent can move.

    :param checkpoints: transition counts to snapshot at (0 snapshots the untrained model).
    :param resolution: cells per axis of the drawn energy map (the original: 300).
    :param bins: cells per axis of the visitation grid (20 as the maze heatmap).
    :param low: lower corner of the state box.
    :param high: upper corner of the state box.
    :param verbose: SB3 verbosity.
    """

    def __init__(
        self,
        checkpoints: Sequence[int],
        resolution: int = 300,
        bins: int = 20,
        low: float = -1.0,
        high: float = 1.0,
        verbose: int = 0,
    ) -> None:
        super().__init__(checkpoints, measure=lambda states: grid_coverage(states, bins, low, high), verbose=verbose)
        self.resolution, self.bins, self.low, self.high = resolution, bins, low, high
        self.snapshots: list[EnergySnapshot] = []

    def _on_training_start(self) -> None:
        super()._on_training_start()
        if self.checkpoints and self.checkpoints[0] <= 0:
            self._next = 1
            self._checkpoint()

    def _on_training_end(self) -> None:
        # Snapshots only at the chosen counts; the end of training adds no extra panel.
        return

    def _checkpoint(self) -> None:
        super()._checkpoint()
        energy = self.model.energy_model  # type: ignore[attr-defined]
        low, high = np.full(2, self.low), np.full(2, self.high)
        self.snapshots.append(
            EnergySnapshot(
                timestep=int(self.num_timesteps),
                energies=energy_map(energy, low, high, self.resolution),
                visit_counts=grid_counts(self.visited_states, self.bins, self.low, self.high),
                cell_energies=cell_energies(energy, self.bins, self.low, self.high),
            )
        )


def cell_energies(energy: torch.nn.Module, bins: int, low: float, high: float, move: float = 0.02) -> np.ndarray:
    """Energy of the move (c - move/2) -> (c + move/2) along the diagonal, for each cell centre c of a square grid.

    :param energy: E(states [..., 2], next_states [..., 2]) -> [...].
    :param bins: cells per axis.
    :param low: lower corner.
    :param high: upper corner.
    :param move: the probed displacement per axis.
    :return: [bins, bins] energies, row = y.
    """
    width = (high - low) / bins
    centres = low + width * (np.arange(bins) + 0.5)
    grid = np.stack(np.meshgrid(centres, centres), axis=-1).astype(np.float32)  # [B, B, 2] as [y, x]
    device = next(energy.parameters()).device
    with torch.no_grad():
        values = energy(torch.as_tensor(grid - move / 2, device=device), torch.as_tensor(grid + move / 2, device=device))
    return values.cpu().numpy()


__all__ = [
    "EnergyMapCallback",
    "EnergySnapshot",
    "VisitedStatesCallback",
    "cell_energies",
    "count_occupied_cells",
    "grid_counts",
    "grid_coverage",
    "linear_checkpoints",
    "log_checkpoints",
]
