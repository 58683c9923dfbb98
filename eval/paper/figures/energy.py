"""Energy maps over training (paper Sec. 4.4, Fig. "energy values of states and corresponding visitation maps").

An online EBM is trained on the particle (the registered env: random starts, goal (0.5, 0.5)) and on the maze
without a goal (the exploration setting of the paper's figure). At evenly spaced points of training,
:class:`~ebm_agent.exploration.EnergyMapCallback` records the energy of a small diagonal move centred at every
point of a grid (the original's ``--energy_heatmap``: E(c - 0.01, c + 0.01)) and the visits so far.

The paper's claim is that energies stay put where the agent has been and keep changing where it has not, which
drives exploration. It is measured on the 20 x 20 visitation grid: between consecutive snapshots, the mean absolute
energy change of cells visited at both (``explored_energy_change``) against that of cells with free space visited
at neither (``unexplored_energy_change``), beside the mean energy of visited and unvisited free cells.
"""

from __future__ import annotations

import functools
import itertools
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import matplotlib.pyplot as plt
import numpy as np

from ebm_agent.exploration import EnergyMapCallback, EnergySnapshot, linear_checkpoints
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
    seed_result_path,
    summary,
)
from eval.paper.figures.exploration import MAZE_BINS, NO_GOAL, free_cells
from eval.paper.records import SEED_FOLDER

ENERGY_ENVS: dict[str, tuple[str, dict[str, float] | None]] = {
    "particle": ("ebm/Particle-v0", None),
    "maze": ("ebm/Maze-v0", NO_GOAL),
}
"""Short name -> (env id, the EBM's cost override)."""


def energy_maps(out_dir: Path, *, seeds: Sequence[int], scale: str = "paper") -> FigureResult:
    """Energy maps and visitation maps at several points of online training, on the particle and the maze.

    :param out_dir: folder of the PNGs and ``figure.json``.
    :param seeds: one run per env and seed (the PNGs show the first seed).
    :param scale: ``"paper"`` (50k transitions, 4 snapshots, 300 x 300 maps) or ``"smoke"``.
    :return: the result; ``metrics["envs"][env]`` holds per-snapshot energy statistics and the change measures.
    """
    out_dir, seeds, budget = prepare(out_dir, seeds, scale)
    checkpoints = linear_checkpoints(budget.online_timesteps, budget.energy_snapshots)
    metrics: dict[str, Any] = {"seeds": seeds, "timesteps": budget.online_timesteps, "checkpoints": checkpoints, "envs": {}}
    pngs = []
    for name, (env_id, cost) in ENERGY_ENVS.items():
        free = free_cells(MAZE_BINS) if name == "maze" else np.ones((MAZE_BINS, MAZE_BINS), dtype=bool)
        png = out_dir / f"energy_maps_{name}.png"
        kept_png = out_dir / SEED_FOLDER / png.name  # the first seed's maps, drawn when it finishes
        runs = []
        for seed in seeds:
            # Each finished run is kept in out_dir/seeds/, so a figure cut short resumes at the next one.
            drawing = kept_png if seed == seeds[0] else None
            if drawing is not None and not drawing.exists():  # its result without its drawing: train it again
                seed_result_path(out_dir, f"energy_maps_{name}", seed).unlink(missing_ok=True)
            compute = functools.partial(_energy_run, budget, checkpoints, env_id, name, cost, seed, drawing)
            measured = seed_result(out_dir, f"energy_maps_{name}", seed, compute, digest=figure_digest("energy_maps"))
            runs.append([SnapshotSummary.from_json(record) for record in measured["snapshots"]])
        metrics["envs"][name] = _env_metrics(runs, free)
        shutil.copyfile(kept_png, png)
        pngs.append(png)
    rows = []
    for name, record in metrics["envs"].items():
        last = record["snapshots"][-1]
        explored, unexplored = record["explored_energy_change"]["mean"], record["unexplored_energy_change"]["mean"]
        rows.append(
            [
                name,
                last["coverage"]["mean"],
                last["visited_energy"]["mean"],
                last["unvisited_energy"]["mean"],
                explored,
                unexplored,
            ]
        )
    header = ["env", "coverage", "E visited (last)", "E unvisited free (last)", "|ΔE| explored", "|ΔE| unexplored"]
    return finish("energy_maps", out_dir, seeds, scale, pngs=pngs, metrics=metrics, table_md=markdown_table(header, rows))


def _energy_run(
    budget: FigureBudget,
    checkpoints: list[int],
    env_id: str,
    name: str,
    cost: dict[str, float] | None,
    seed: int,
    drawing: Path | None,
) -> dict[str, Any]:
    """One online run with its snapshots, summarised; its energy maps are drawn into ``drawing`` when given."""
    agent = build_ebm(gym.make(env_id), seed, budget, cost=cost)
    callback = EnergyMapCallback(checkpoints, resolution=budget.energy_resolution, bins=MAZE_BINS)
    agent.learn(budget.online_timesteps, callback=callback)
    if drawing is not None:
        _plot_snapshots(callback.snapshots, name, drawing)
    return {"snapshots": [_summarise(snap) for snap in callback.snapshots]}


@dataclass(frozen=True)
class SnapshotSummary:
    """What the figure's numbers need of an :class:`EnergySnapshot` (its full energy map only goes into the drawing).

    :param timestep: transitions consumed.
    :param energy_mean: mean of the [R, R] energy map.
    :param energy_std: std of the energy map.
    :param visit_counts: [B, B] visit counts of the coverage grid.
    :param cell_energies: [B, B] energy of a move centred on each grid cell's centre.
    """

    timestep: int
    energy_mean: float
    energy_std: float
    visit_counts: np.ndarray
    cell_energies: np.ndarray

    @classmethod
    def from_json(cls, record: dict[str, Any]) -> SnapshotSummary:
        """Rebuild from :func:`_summarise`'s JSON form."""
        return cls(
            int(record["timestep"]),
            float(record["energy_mean"]),
            float(record["energy_std"]),
            np.asarray(record["visit_counts"]),
            np.asarray(record["cell_energies"], dtype=np.float64),
        )


def _summarise(snap: EnergySnapshot) -> dict[str, Any]:
    return {
        "timestep": snap.timestep,
        "energy_mean": float(snap.energies.mean()),
        "energy_std": float(snap.energies.std()),
        "visit_counts": snap.visit_counts,
        "cell_energies": snap.cell_energies,
    }


def _env_metrics(runs: list[list[SnapshotSummary]], free: np.ndarray) -> dict[str, Any]:
    """Per-snapshot statistics (mean/std over seeds) and the energy-change measures of one env."""
    per_snapshot: list[dict[str, list[float]]] = [{} for _ in runs[0]]
    explored_changes, unexplored_changes = [], []
    for snapshots in runs:
        for index, snap in enumerate(snapshots):
            visited = snap.visit_counts > 0  # [B, B]
            values = {
                "coverage": float(visited.mean()),
                "energy_mean": snap.energy_mean,
                "energy_std": snap.energy_std,
                "visited_energy": _masked_mean(snap.cell_energies, visited),
                "unvisited_energy": _masked_mean(snap.cell_energies, free & ~visited),
            }
            for key, value in values.items():
                per_snapshot[index].setdefault(key, []).append(value)
        for before, after in itertools.pairwise(snapshots):
            change = np.abs(after.cell_energies - before.cell_energies)  # [B, B]
            seen_before, seen_after = before.visit_counts > 0, after.visit_counts > 0
            explored_changes.append(_masked_mean(change, seen_before & seen_after))
            unexplored_changes.append(_masked_mean(change, free & ~seen_before & ~seen_after))
    return {
        "snapshots": [
            {"timestep": snap.timestep, **{key: _finite_summary(values) for key, values in record.items()}}
            for snap, record in zip(runs[0], per_snapshot)
        ],
        "explored_energy_change": _finite_summary(explored_changes),
        "unexplored_energy_change": _finite_summary(unexplored_changes),
    }


def _masked_mean(values: np.ndarray, mask: np.ndarray) -> float:
    return float(values[mask].mean()) if mask.any() else float("nan")


def _finite_summary(values: list[float]) -> dict[str, float | None]:
    finite = [v for v in values if np.isfinite(v)]
    return dict(summary(finite)) if finite else {"mean": None, "std": None}


def _plot_snapshots(snapshots: list[EnergySnapshot], name: str, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    columns = len(snapshots)
    figure, axes = plt.subplots(2, columns, figsize=(3.2 * columns, 6.2), squeeze=False, layout="constrained")
    extent = (-1.0, 1.0, -1.0, 1.0)
    stacked = np.stack([s.energies for s in snapshots])
    low, high = np.percentile(stacked, [2, 98])  # one colour scale per env, so changes between panels show
    for column, snap in enumerate(snapshots):
        image = axes[0, column].imshow(snap.energies, origin="lower", extent=extent, cmap="viridis", vmin=low, vmax=high)
        if name == "maze":
            coords = np.linspace(-1.0, 1.0, 200)
            walls = ~maze_valid(np.stack(np.meshgrid(coords, coords), axis=-1))  # [200, 200] row = y
            axes[0, column].contour(coords, coords, walls.astype(float), levels=[0.5], colors="white", linewidths=0.8)
        axes[0, column].set_title(f"{name}: energy at {snap.timestep} transitions", fontsize="small")
        axes[1, column].imshow(np.log1p(snap.visit_counts), origin="lower", extent=extent, cmap="magma")
        axes[1, column].set_title(f"visits (log) at {snap.timestep}", fontsize="small")
    figure.colorbar(image, ax=axes[0, :].tolist(), fraction=0.02, label="E(c - 0.01, c + 0.01)")
    return save_png(figure, path)


__all__ = ["ENERGY_ENVS", "energy_maps"]
