"""Learning curves from ``evaluations.npz``: score vs transitions, one line per agent, a band over seeds."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: the harness runs headless

import matplotlib.pyplot as plt
import numpy as np

from eval.anchors import EnvAnchors
from eval.jobs import JobResult

Curve = tuple[np.ndarray, np.ndarray]
"""(timesteps [E], mean score of each evaluation [E]) of one seed."""


def load_curve(path: Path) -> Curve:
    """Read one seed's curve from an SB3 ``evaluations.npz``.

    :param path: the file.
    :return: timesteps [E] and the mean over episodes of each evaluation [E].
    """
    with np.load(path) as data:
        timesteps = np.asarray(data["timesteps"], dtype=np.float64)  # [E]
        results = np.asarray(data["results"], dtype=np.float64)  # [E, episodes]
    if results.ndim != 2 or len(results) != len(timesteps):
        raise ValueError(f"{path} is not in SB3's format: results must be [evaluations, episodes], got {results.shape}")
    return timesteps, results.mean(axis=1)


def aggregate_curves(curves: Sequence[Curve]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Mean, min and max over seeds on a common grid (the evaluation points of the shortest curve).

    :param curves: one curve per seed.
    :return: grid [G], mean [G], min [G], max [G].
    """
    if not curves:
        raise ValueError("no curve to aggregate")
    grid = min((timesteps for timesteps, _ in curves), key=len)  # [G]
    # Seeds evaluate at the same transitions under equal budgets; interpolation covers n_envs rounding.
    values = np.stack([np.interp(grid, timesteps, scores) for timesteps, scores in curves])  # [seeds, G]
    return grid, values.mean(axis=0), values.min(axis=0), values.max(axis=0)


def plot_curves(
    curves: Mapping[str, Sequence[Curve]],
    path: Path,
    title: str = "",
    anchors: EnvAnchors | None = None,
) -> Path:
    """Draw one line per agent (mean over seeds) with a min-max band over seeds, plus the anchors.

    :param curves: agent label -> one curve per seed.
    :param path: the PNG file.
    :param title: the figure title.
    :param anchors: the env's anchors, drawn as horizontal lines.
    :return: ``path``.
    """
    figure, axis = plt.subplots(figsize=(6.4, 4.2))
    try:
        for label, seed_curves in curves.items():
            if not seed_curves:
                continue
            grid, mean, low, high = aggregate_curves(seed_curves)
            (line,) = axis.plot(grid, mean, marker="o", markersize=3, label=f"{label} ({len(seed_curves)} seeds)")
            if len(seed_curves) > 1:
                axis.fill_between(grid, low, high, color=line.get_color(), alpha=0.2, linewidth=0)
        if anchors is not None:
            if anchors.optimum is not None:
                axis.axhline(anchors.optimum, color="black", linestyle="--", linewidth=1, label="optimum")
            axis.axhline(anchors.random_mean, color="grey", linestyle=":", linewidth=1, label="random policy")
            axis.axhline(anchors.still_score, color="grey", linestyle="-.", linewidth=1, label="standing still")
        axis.set_xlabel("transitions")
        axis.set_ylabel("score (sum of rewards per episode)")
        axis.set_title(title)
        axis.grid(alpha=0.3)
        axis.legend(fontsize="small")
        figure.tight_layout()
        figure.savefig(path, dpi=120)
    finally:
        plt.close(figure)
    return path


def plot_learning_curves(
    results: Sequence[JobResult], out_dir: Path, anchors: dict[str, EnvAnchors | None] | None = None
) -> list[Path]:
    """Write ``learning_curves_<env>.png`` for each env of a sweep, from the runs' ``evaluations.npz``.

    :param results: the sweep's results (failed runs and runs without a file are skipped).
    :param out_dir: the sweep's folder.
    :param anchors: env short name -> anchors.
    :return: the PNG files written.
    """
    per_env: dict[str, dict[str, list[Curve]]] = {}
    for result in results:
        path = result.run_dir / "evaluations.npz"
        if result.ok and path.exists():
            per_env.setdefault(result.job.env_short, {}).setdefault(result.job.agent, []).append(load_curve(path))
    written = []
    for env, curves in per_env.items():
        env_anchors = (anchors or {}).get(env)
        written.append(
            plot_curves(curves, Path(out_dir) / f"learning_curves_{env}.png", f"{env}: learning curves", env_anchors)
        )
    return written


__all__ = ["aggregate_curves", "load_curve", "plot_curves", "plot_learning_curves"]
