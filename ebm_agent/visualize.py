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
