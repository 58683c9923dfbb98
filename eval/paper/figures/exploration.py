"""Exploration figures (paper Sec. 4.4): maze coverage and Sawyer finger occupancy, an EBM without a goal vs random.

The EBM explores with its goal energy switched off (``cost={"goal_weight": 0}``): plans follow the learned energy
and the acceleration prior only, so where it goes is decided by the energy landscape, which is low on unexplored
regions that training has not shaped yet (paper Sec. 3.3). Both agents consume the same number of transitions, and
what they visit is recorded during training by :class:`~ebm_agent.exploration.VisitedStatesCallback`.

- Maze: coverage = fraction of the cells of the original's 20 x 20 heatmap grid over [-1, 1]^2 with a visit (and,
  since the walls make some cells unreachable, the fraction of cells that hold free space). Random actions are
  uniform (the maze env has no exploration sampler).
- Sawyer (no-goal variant): the original's finger voxel occupancy (reference/original_code.md §8), normalised as its
  plot: occupancy / (max random occupancy + 5) x 100 %. Two random baselines: uniform torques (the original's
  ``--random_action``, which pins the arm at its joint limits) and the env's joint-target sampler (a stronger random
  explorer); the normaliser uses the largest final occupancy of either.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import matplotlib.pyplot as plt
import numpy as np

from baselines.random_agent import RandomAgent
from ebm_agent import EBMPlannerAgent
from ebm_agent.exploration import VisitedStatesCallback, grid_counts, grid_coverage, linear_checkpoints, log_checkpoints
from ebm_agent.presets import FAST_EBM, merge_settings
from envs.maze import maze_valid
from eval.paper.figures.common import (
    FigureBudget,
    FigureResult,
    build_ebm,
    figure_digest,
    finish,
    markdown_table,
    prepare,
    save_png,
    seed_result,
    summary,
)

MAZE_BINS = 20
"""Cells per axis of the original's maze heatmap over [-1, 1]^2."""

ORIGINAL_CUT = 4000
"""The original's maze heatmap exited after 4,000 steps; coverage there is reported too."""

NO_GOAL = {"goal_weight": 0.0}
"""The EBM's cost without a goal: exploration follows the energy alone."""

FRONTIER_EXPLORE = {"every": 250, "goal_heuristic": 0.0}
"""``EBMPlannerAgent(explore=...)`` of the frontier explorer: the graph rebuilt every 250 transitions, no goal."""

FRONTIER_GOAL_WEIGHT = {"goal_weight": 10.0}
"""The frontier explorer's cost: its plans aim at the frontier subgoals with weight 10."""

VOXEL_CORNERS = np.linspace(-1.0, 1.0, 10)
"""Lower corners of the original's finger voxels on each axis (spacing 2/9 = 0.222)."""

VOXEL_WIDTH = 0.2
"""Width of each original finger voxel: narrower than the spacing, so the voxels leave 0.022 gaps."""


def original_voxel_occupancy(points: np.ndarray) -> int:
    """The original's finger occupancy: voxels with lower corners ``linspace(-1, 1, 10)`` per axis, 0.2 wide.

    A voxel counts when some point lies *strictly* inside it (``train.py:569-577``). The voxels do not tile the
    space: a point in a 0.022 gap between two voxels, or on a voxel face, counts for none.

    :param points: [M, 3] finger positions.
    :return: number of occupied voxels (at most 1000).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    spacing = VOXEL_CORNERS[1] - VOXEL_CORNERS[0]
    index = np.floor((points - VOXEL_CORNERS[0]) / spacing).astype(np.int64)  # [M, 3] the only candidate voxel
    valid = (index >= 0) & (index < len(VOXEL_CORNERS))
    corner = VOXEL_CORNERS[np.clip(index, 0, len(VOXEL_CORNERS) - 1)]  # [M, 3]
    inside = valid & (points > corner) & (points < corner + VOXEL_WIDTH)
    occupied = index[inside.all(axis=1)]
    return len(np.unique(occupied, axis=0)) if len(occupied) else 0


def maze_exploration(out_dir: Path, *, seeds: Sequence[int], scale: str = "paper") -> FigureResult:
    """Coverage of the maze by the goal-free online EBM and by uniform random actions over the same transitions.

    :param out_dir: folder of the PNGs and ``figure.json``.
    :param seeds: one EBM run and one random run per seed.
    :param scale: ``"paper"`` or ``"smoke"``.
    :return: the result; ``metrics["agents"][a]`` holds final coverage (mean/std/per seed) and the coverage curve.
    """
    explorers = {
        "ebm": lambda seed, budget: build_ebm(gym.make("ebm/Maze-v0"), seed, budget, cost=NO_GOAL),
        "random": _random_explorer,
    }
    return _maze_coverage("maze_exploration", explorers, out_dir, seeds, scale)


def frontier_exploration(out_dir: Path, *, seeds: Sequence[int], scale: str = "paper") -> FigureResult:
    """Coverage of the maze by the EBM exploring the frontier of what it visited without a goal (not in the paper:
    ``EBMPlannerAgent(explore={"goal_heuristic": 0})``, the fast preset's planning budgets, goal weight 10 on the
    frontier subgoals) and by uniform random actions over the same transitions.

    :param out_dir: folder of the PNGs and ``figure.json``.
    :param seeds: one run of each per seed.
    :param scale: ``"paper"`` or ``"smoke"``.
    :return: the result, as :func:`maze_exploration`'s.
    """

    def frontier(seed: int, budget: FigureBudget) -> EBMPlannerAgent:
        planner = merge_settings(FAST_EBM["planner_config"], budget.planner)  # a smoke budget's tiny planner wins
        settings = {"cost": FRONTIER_GOAL_WEIGHT, "explore": FRONTIER_EXPLORE, "planner_config": planner}
        return build_ebm(gym.make("ebm/Maze-v0"), seed, budget, **settings)

    return _maze_coverage(
        "frontier_exploration", {"ebm_frontier": frontier, "random": _random_explorer}, out_dir, seeds, scale
    )


def _random_explorer(seed: int, budget: FigureBudget) -> RandomAgent:
    """Uniform random actions on the maze (it has no exploration sampler)."""
    return RandomAgent("MultiInputPolicy", gym.make("ebm/Maze-v0"), seed=seed, record_visited=False)


def _maze_coverage(
    figure: str, explorers: Mapping[str, Callable[[int, FigureBudget], Any]], out_dir: Path, seeds: Sequence[int], scale: str
) -> FigureResult:
    """The coverage figure of some maze explorers, each learning for the budget's maze transitions per seed.

    :param figure: the figure's name.
    :param explorers: agent name -> ``(seed, budget) -> agent`` (an SB3 algorithm with ``learn``).
    :param out_dir: the figure's folder.
    :param seeds: one run of each explorer per seed.
    :param scale: the scale.
    :return: the result.
    """
    out_dir, seeds, budget = prepare(out_dir, seeds, scale)
    checkpoints = linear_checkpoints(budget.maze_timesteps, budget.curve_points)
    if ORIGINAL_CUT < budget.maze_timesteps:
        checkpoints = sorted({*checkpoints, ORIGINAL_CUT})
    measure = lambda states: grid_coverage(states, MAZE_BINS)  # noqa: E731
    runs: dict[str, list[VisitedStatesCallback]] = {agent: [] for agent in explorers}
    for seed in seeds:
        for agent, make in explorers.items():
            runs[agent].append(_record(make(seed, budget), budget.maze_timesteps, checkpoints, measure))
    free = free_cells(MAZE_BINS)
    agents: dict[str, Any] = {}
    for name, callbacks in runs.items():
        curve_t, curve_values = _curves(callbacks)
        finals = [float(c.curve_values[-1]) for c in callbacks]
        cells = [count_cells(c.visited_states) for c in callbacks]
        agents[name] = {
            "coverage": {**summary(finals), "per_seed": finals},
            "coverage_of_free": summary([n / int(free.sum()) for n in cells]),
            "curve": {"timesteps": curve_t, **_curve_summary(curve_values)},
        }
        if ORIGINAL_CUT in curve_t:
            agents[name]["coverage_at_4000"] = summary(curve_values[:, curve_t.index(ORIGINAL_CUT)])
    metrics = {
        "seeds": seeds,
        "timesteps": budget.maze_timesteps,
        "grid": f"{MAZE_BINS} x {MAZE_BINS} cells over [-1, 1]^2",
        "free_cells": int(free.sum()),
        "agents": agents,
    }
    first = {name: callbacks[0].visited_states for name, callbacks in runs.items()}
    pngs = [
        _plot_maze_heatmaps(first, free, out_dir / "maze_heatmaps.png", order=list(reversed(first))),
        _plot_curves(agents, out_dir / "maze_coverage.png", "maze coverage (fraction of 20 x 20 cells)", log_x=False),
    ]
    rows = [
        [name, *(f"{agents[name][k]['mean']:.3f} ± {agents[name][k]['std']:.3f}" for k in ("coverage", "coverage_of_free"))]
        for name in agents
    ]
    table = markdown_table(["agent", "coverage (all cells)", "coverage (cells with free space)"], rows)
    return finish(figure, out_dir, seeds, scale, pngs=pngs, metrics=metrics, table_md=table)


def sawyer_exploration(out_dir: Path, *, seeds: Sequence[int], scale: str = "paper") -> FigureResult:
    """Finger voxel occupancy of the goal-free online EBM and of two random explorers on the no-goal Sawyer.

    :param out_dir: folder of the PNG and ``figure.json``.
    :param seeds: runs per agent (the paper: 4).
    :param scale: ``"paper"`` (EBM 50k transitions, random 250k) or ``"smoke"``.
    :return: the result; ``metrics["agents"][a]`` holds final occupancy, its normalised value and the curve.
    """
    out_dir, seeds, budget = prepare(out_dir, seeds, scale)
    runs: dict[str, list[Curve]] = {"ebm": [], "random_uniform": [], "random_joint_targets": []}

    def explore(seed: int) -> dict[str, Any]:
        """The occupancy curves of the EBM and both random explorers of one seed."""
        ebm = build_ebm(gym.make("ebm/SawyerReach-v0", goal=None), seed, budget, cost=NO_GOAL)
        curves = {"ebm": _sawyer_run(ebm, budget.sawyer_ebm_timesteps, budget.curve_points)}
        for name, sampler in (("random_uniform", False), ("random_joint_targets", True)):
            env = gym.make("ebm/SawyerReach-v0", goal=None)
            agent = RandomAgent("MultiInputPolicy", env, seed=seed, use_env_sampler=sampler, record_visited=False)
            # The EBM's budget is a checkpoint too: the occupancies at equal transitions are compared exactly.
            curves[name] = _sawyer_run(agent, budget.sawyer_random_timesteps, budget.curve_points, budget.sawyer_ebm_timesteps)
        return {name: {"timesteps": c.curve_timesteps, "values": c.curve_values} for name, c in curves.items()}

    digest = figure_digest("sawyer_exploration")
    for seed in seeds:
        # Each finished seed is kept in out_dir/seeds/ (about an hour each), so a figure cut short resumes.
        measured = seed_result(out_dir, "sawyer_exploration", seed, functools.partial(explore, seed), digest=digest)
        for name in runs:
            runs[name].append(Curve(list(measured[name]["timesteps"]), list(measured[name]["values"])))
    max_random = max(c.curve_values[-1] for name in ("random_uniform", "random_joint_targets") for c in runs[name])
    normaliser = max_random + 5.0
    agents: dict[str, Any] = {}
    for name, callbacks in runs.items():
        curve_t, curve_values = _curves(callbacks)
        finals = [float(c.curve_values[-1]) for c in callbacks]
        agents[name] = {
            "timesteps": int(curve_t[-1]),
            "occupancy": {**summary(finals), "per_seed": finals},
            "normalised_percent": summary([100.0 * f / normaliser for f in finals]),
            "curve": {"timesteps": curve_t, **_curve_summary(curve_values)},
        }
    ebm_budget = budget.sawyer_ebm_timesteps
    for name in ("random_uniform", "random_joint_targets"):
        curve = agents[name]["curve"]
        if ebm_budget in curve["timesteps"]:
            at_budget = [float(c.curve_values[c.curve_timesteps.index(ebm_budget)]) for c in runs[name]]
            agents[name]["occupancy_at_ebm_budget"] = {**summary(at_budget), "per_seed": at_budget}
        target = agents["ebm"]["occupancy"]["mean"]
        reached = [t for t, v in zip(curve["timesteps"], curve["mean"]) if v >= target]
        agents[name]["transitions_to_reach_ebm_final"] = reached[0] if reached else None
    metrics = {
        "seeds": seeds,
        "voxels": "original: lower corners linspace(-1, 1, 10) per axis, 0.2 wide, strictly inside",
        "max_random_occupancy": max_random,
        "normaliser": normaliser,
        "agents": agents,
    }
    ebm_finals = agents["ebm"]["occupancy"]["per_seed"]
    agents["ebm"]["occupancy_at_ebm_budget"] = {**summary(ebm_finals), "per_seed": ebm_finals}
    title = f"Sawyer finger occupancy / (max random {max_random:.0f} + 5), seeds {seeds}"
    pngs = [_plot_curves(agents, out_dir / "sawyer_occupancy.png", title, log_x=True, scale=100.0 / normaliser)]
    rows = [
        [
            name,
            agents[name]["timesteps"],
            _mean_std(agents[name]["occupancy"]),
            agents[name]["normalised_percent"]["mean"],
            _mean_std(agents[name].get("occupancy_at_ebm_budget")),
        ]
        for name in agents
    ]
    header = ["agent", "transitions", "voxels occupied", "% of (max random + 5)", f"voxels at {ebm_budget} transitions"]
    table = markdown_table(header, rows)
    return finish("sawyer_exploration", out_dir, seeds, scale, pngs=pngs, metrics=metrics, table_md=table)


def _mean_std(numbers: dict[str, Any] | None) -> str:
    """``mean ± std`` of a :func:`summary`, or ``-`` when there is none."""
    return "-" if numbers is None else f"{numbers['mean']:.1f} ± {numbers['std']:.1f}"


def free_cells(bins: int = MAZE_BINS, samples: int = 10) -> np.ndarray:
    """Which cells of the square grid over [-1, 1]^2 hold free maze space (checked on a sub-grid of each cell).

    :param bins: cells per axis.
    :param samples: sub-grid points per axis and cell.
    :return: [bins, bins] bool, row = y.
    """
    offsets = (np.arange(samples) + 0.5) / samples
    coords = -1.0 + (np.arange(bins)[:, None] + offsets[None, :]).ravel() * (2.0 / bins)  # [bins * samples]
    xs, ys = np.meshgrid(coords, coords)  # [y, x]
    valid = maze_valid(np.stack([xs, ys], axis=-1))  # [B*S, B*S]
    return np.asarray(valid.reshape(bins, samples, bins, samples).any(axis=(1, 3)))


def count_cells(states: np.ndarray, bins: int = MAZE_BINS) -> int:
    """Number of maze grid cells with a visit.

    :param states: [M, 2] visited positions.
    :param bins: cells per axis.
    :return: the count.
    """
    return int((grid_counts(states, bins) > 0).sum())


def _record(agent: Any, timesteps: int, checkpoints: list[int], measure: Any) -> VisitedStatesCallback:
    callback = VisitedStatesCallback(checkpoints, measure)
    agent.learn(timesteps, callback=callback)
    return callback


def _sawyer_run(agent: Any, timesteps: int, points: int, *extra: int) -> VisitedStatesCallback:
    checkpoints = sorted({*log_checkpoints(timesteps, points), *(t for t in extra if t <= timesteps)})
    return _record(agent, timesteps, checkpoints, original_voxel_occupancy)


@dataclass(frozen=True)
class Curve:
    """An explorer's measure at its checkpoints, as a :class:`VisitedStatesCallback` records it.

    :param curve_timesteps: transitions at each checkpoint [C].
    :param curve_values: the measure (occupied voxels or cells) at each [C].
    """

    curve_timesteps: list[int]
    curve_values: list[float]


def _curves(callbacks: Sequence[VisitedStatesCallback | Curve]) -> tuple[list[int], np.ndarray]:
    """The seeds' curves on the first seed's checkpoints: (timesteps [C], values [seeds, C])."""
    grid = callbacks[0].curve_timesteps
    values = np.stack([np.interp(grid, c.curve_timesteps, c.curve_values) for c in callbacks])
    return list(grid), values


def _curve_summary(values: np.ndarray) -> dict[str, list[float]]:
    return {"mean": values.mean(0).tolist(), "min": values.min(0).tolist(), "max": values.max(0).tolist()}


def _plot_curves(agents: dict[str, Any], path: Path, title: str, log_x: bool, scale: float = 1.0) -> Path:
    figure, axis = plt.subplots(figsize=(6, 4))
    for name, record in agents.items():
        curve = record["curve"]
        mean = np.asarray(curve["mean"]) * scale
        (line,) = axis.plot(curve["timesteps"], mean, marker="o", markersize=3, label=name)
        axis.fill_between(
            curve["timesteps"],
            np.asarray(curve["min"]) * scale,
            np.asarray(curve["max"]) * scale,
            color=line.get_color(),
            alpha=0.2,
        )
    if log_x:
        axis.set_xscale("log")
    axis.set_xlabel("transitions")
    axis.set_ylabel("%" if scale != 1.0 else "coverage")
    axis.set_title(title, fontsize="medium")
    axis.grid(alpha=0.3)
    axis.legend(fontsize="small")
    return save_png(figure, path)


def _plot_maze_heatmaps(visited: dict[str, np.ndarray], free: np.ndarray, path: Path, order: list[str]) -> Path:
    figure, axes = plt.subplots(1, len(order) + 1, figsize=(3.7 * (len(order) + 1), 3.8))
    extent = (-1.0, 1.0, -1.0, 1.0)
    for axis, name in zip(axes, order):
        counts = grid_counts(visited[name], MAZE_BINS)
        image = axis.imshow(np.log1p(counts), origin="lower", extent=extent, cmap="magma")
        figure.colorbar(image, ax=axis, fraction=0.046, label="log(1 + visits)")
        axis.set_title(f"{name}: {grid_coverage(visited[name], MAZE_BINS):.0%} of cells (first seed)")
    coords = np.linspace(-1.0, 1.0, 200)
    layout = maze_valid(np.stack(np.meshgrid(coords, coords), axis=-1))  # [200, 200] row = y
    axes[-1].imshow(layout, origin="lower", extent=extent, cmap="Blues", vmin=0, vmax=1.5)
    axes[-1].set_title("maze: admissible space in blue")
    return save_png(figure, path)


__all__ = [
    "FRONTIER_EXPLORE",
    "FRONTIER_GOAL_WEIGHT",
    "VOXEL_CORNERS",
    "VOXEL_WIDTH",
    "count_cells",
    "free_cells",
    "frontier_exploration",
    "maze_exploration",
    "original_voxel_occupancy",
    "sawyer_exploration",
]
