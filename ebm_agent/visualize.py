"""Pictures of what the EBM learned: energy landscapes over 2-D states with plans drawn on top."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import torch
from matplotlib.figure import Figure
from torch import nn


def energy_map(
    energy: nn.Module,
    low: np.ndarray,
    high: np.ndarray,
    resolution: int = 64,
    move: tuple[float, float] = (0.02, 0.02),
) -> np.ndarray:
    """Energy of a small move centred at each cell of a grid over a 2-D state space.

    As the original's ``--energy_heatmap``: E(c - move/2, c + move/2) for every grid centre c; low values are
    places the model believes the particle can move through (free space), high values walls and unseen regions.

    :param energy: E(states [..., 2], next_states [..., 2]) -> [...].
    :param low: [2] lower corner.
    :param high: [2] upper corner.
    :param resolution: cells per axis.
    :param move: the probed displacement.
    :return: [resolution, resolution] energies, row index = y (origin at ``low``).
    """
    xs = np.linspace(low[0], high[0], resolution, dtype=np.float32)
    ys = np.linspace(low[1], high[1], resolution, dtype=np.float32)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1)  # [R, R, 2], [y, x]
    half = np.asarray(move, dtype=np.float32) / 2
    device = next(energy.parameters()).device
    with torch.no_grad():
        values = energy(torch.as_tensor(grid - half, device=device), torch.as_tensor(grid + half, device=device))
    return values.cpu().numpy()


def move_energy_map(
    energy: nn.Module,
    low: np.ndarray,
    high: np.ndarray,
    step: np.ndarray,
    resolution: int = 64,
    directions: int = 8,
) -> np.ndarray:
    """The highest energy of a one-step move from each cell of a grid over a 2-D state space, over ``directions``
    directions: where some move from a state is one the env refuses (beside a wall), an energy that learned the walls
    is high; in the open, every move is possible and all are low. Unlike :func:`energy_map` (a move centred at the
    state), it shows the walls' edges, where feasibility changes.

    :param energy: E(states [..., 2], next_states [..., 2]) -> [...].
    :param low: [2] lower corner.
    :param high: [2] upper corner.
    :param step: [2] the size of a move along each axis (e.g. the largest real one-step change).
    :param resolution: cells per axis.
    :param directions: moves probed, evenly spaced in angle (8: the axes and the diagonals).
    :return: [resolution, resolution] energies, row index = y (origin at ``low``).
    """
    xs = np.linspace(low[0], high[0], resolution, dtype=np.float32)
    ys = np.linspace(low[1], high[1], resolution, dtype=np.float32)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1)  # [R, R, 2], [y, x]
    angles = 2 * np.pi * np.arange(directions) / directions  # [K]
    moves = (np.stack([np.cos(angles), np.sin(angles)], axis=-1) * np.asarray(step, np.float32)).astype(np.float32)  # [K, 2]
    starts = np.broadcast_to(grid[None], (directions, *grid.shape))  # [K, R, R, 2]
    ends = starts + moves[:, None, None, :]  # [K, R, R, 2]
    device = next(energy.parameters()).device
    with torch.no_grad():
        values = energy(torch.as_tensor(np.ascontiguousarray(starts), device=device), torch.as_tensor(ends, device=device))
    return values.max(dim=0).values.cpu().numpy()  # [R, R]


def energy_maps_figure(energy: nn.Module, low: np.ndarray, high: np.ndarray, step: np.ndarray, resolution: int = 64) -> Figure:
    """Two panels of a 2-D energy: :func:`energy_map` (a small move centred at each state, the paper's Fig. 9) and
    :func:`move_energy_map` (the highest energy of a one-step move from each state: the walls' edges).

    :param energy: the energy model.
    :param low: [2] lower corner of the state space.
    :param high: [2] upper corner.
    :param step: [2] the size of a one-step move along each axis.
    :param resolution: cells per axis.
    :return: the matplotlib figure (close it after use).
    """
    figure, axes = plt.subplots(1, 2, figsize=(8, 4))
    panels = [
        (energy_map(energy, low, high, resolution), "E(c - m/2, c + m/2), m = (0.02, 0.02)"),
        (move_energy_map(energy, low, high, step, resolution), "max over 8 directions of E(s, s + one step)"),
    ]
    for axis, (values, title) in zip(axes, panels):
        image = axis.imshow(values, origin="lower", extent=(low[0], high[0], low[1], high[1]), cmap="viridis")
        figure.colorbar(image, ax=axis, fraction=0.046)
        axis.set_title(title, fontsize=8)
    figure.tight_layout()
    return figure


def plan_figure(
    energy: nn.Module,
    low: np.ndarray,
    high: np.ndarray,
    planned: np.ndarray,
    real: np.ndarray | None = None,
    goal: np.ndarray | None = None,
    resolution: int = 64,
) -> Figure:
    """A figure of the energy map with a plan (and its real execution) drawn on it.

    :param energy: the energy model.
    :param low: [2] lower corner of the state space.
    :param high: [2] upper corner.
    :param planned: [T+1, 2] planned states, or [P, T+1, 2] several plans.
    :param real: [k, 2] real states reached, or None.
    :param goal: [2] goal, or None.
    :param resolution: cells per axis of the energy map.
    :return: the matplotlib figure (close it after use).
    """
    values = energy_map(energy, low, high, resolution)
    figure, axis = plt.subplots(figsize=(4, 4))
    image = axis.imshow(values, origin="lower", extent=(low[0], high[0], low[1], high[1]), cmap="viridis")
    figure.colorbar(image, ax=axis, fraction=0.046)
    paths = planned[None] if planned.ndim == 2 else planned
    for path in paths:
        axis.plot(path[:, 0], path[:, 1], "-", color="white", linewidth=1.0, alpha=0.8)
    axis.plot(paths[0, 0, 0], paths[0, 0, 1], "o", color="white", markersize=4)
    if real is not None and len(real):
        axis.plot(real[:, 0], real[:, 1], ".", color="red", markersize=3)
    if goal is not None:
        axis.plot(goal[0], goal[1], "*", color="gold", markersize=10)
    axis.set_xlim(low[0], high[0])
    axis.set_ylim(low[1], high[1])
    axis.set_title("energy E(c, c + 0.02) and plan")
    figure.tight_layout()
    return figure
