"""Obstacle generalisation (paper Sec. 4.3, Fig. "navigation path with a central obstacle the model was not trained with").

Both models learn the particle online *without* any obstacle, then are evaluated from (0, 0) to (0.5, 0.5) with an
unseen box in the way (the env rejects any move whose segment's bounding box touches it). Four ways to plan:

- EBM + box energy: the box is composed with the learned energy as an extra plan energy
  (``set_plan_constraints([BoxObstacleEnergy])``): a state-space planner takes a new constraint at test time.
- EBM, blind, and Action FF, blind: as the original, whose plan costs had no obstacle term (the EBM's: energy,
  priors and goal, reference/original_code.md §3; the Action FF's: the final predicted state's distance to the goal,
  §7); the env stops them at the box and they replan. These two are what the paper's -61.94 and -81.24 measured.
- Action FF + box in its model: the box's rejection rule composed into the forward model (a predicted move that
  touches the box stays put), the closest action-space analogue of adding an energy; not in the paper.

The authors' box (0.1, 0.1, 0.5, 0.5) touches the goal, so their goal was unreachable (our env refuses that box);
the box here, (0.1, 0.1, 0.4, 0.4), is as central and leaves the goal reachable. Its optimum is computed by value
iteration on a lattice (:func:`obstacle_optimum`).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import matplotlib.pyplot as plt
import numpy as np
import torch
from matplotlib.patches import Rectangle
from torch import Tensor

from baselines.action_ff import ActionFFAgent
from baselines.action_planner import ActionPlanner, ForwardModel
from ebm_agent import BoxObstacleEnergy
from ebm_agent.presets import PAPER_ACTION_FF, merge_settings
from envs.particle import ParticleEnv
from eval.anchors import compute_anchors
from eval.paper.figures.common import (
    FigureResult,
    build_ebm,
    figure_digest,
    finish,
    markdown_table,
    paper_numbers,
    prepare,
    run_episode,
    save_png,
    seed_result,
    summary,
)

OBSTACLE_BOX = (0.1, 0.1, 0.4, 0.4)
"""(xmin, ymin, xmax, ymax) of the unseen box: central between start and goal, goal still reachable."""

OBSTACLE_START = (0.0, 0.0)
OBSTACLE_GOAL = (0.5, 0.5)
BOX_MARGIN = 0.03
"""The box energy's safety margin: the env also rejects moves whose bounding box merely touches the box."""

METHODS = ("ebm_box_energy", "ebm_no_box_energy", "action_ff", "action_ff_box_model")
LABELS = {
    "ebm_box_energy": "EBM + box energy",
    "ebm_no_box_energy": "EBM, blind (as the original)",
    "action_ff": "Action FF, blind (as the original)",
    "action_ff_box_model": "Action FF + box in its model",
}


def obstacle_generalisation(
    out_dir: Path, *, seeds: Sequence[int], scale: str = "paper", box: Sequence[float] = OBSTACLE_BOX
) -> FigureResult:
    """Train the EBM and Action FF on the open particle, evaluate them around an unseen box; plot the paths.

    :param out_dir: folder of the PNG and ``figure.json``.
    :param seeds: training seeds (one EBM and one Action FF each).
    :param scale: ``"paper"`` (50k online transitions, 10 episodes) or ``"smoke"``.
    :param box: the obstacle (xmin, ymin, xmax, ymax).
    :return: the result; ``metrics["methods"][m]`` holds mean/std over seeds and episodes, per-seed means, success.
    """
    out_dir, seeds, budget = prepare(out_dir, seeds, scale)
    eval_kwargs: dict[str, Any] = {"start": OBSTACLE_START, "goal": OBSTACLE_GOAL, "obstacle": tuple(box)}
    eval_env = gym.make("ebm/Particle-v0", **eval_kwargs)
    scores: dict[str, list[list[float]]] = {m: [] for m in METHODS}
    successes: dict[str, list[bool]] = {m: [] for m in METHODS}
    paths: dict[str, np.ndarray] = {}
    box_energy = BoxObstacleEnergy(low=box[:2], high=box[2:], margin=BOX_MARGIN)

    def train_and_measure(seed: int) -> dict[str, Any]:
        """Both agents of one seed trained on the open particle and evaluated around the box by every method."""
        ebm = build_ebm(gym.make("ebm/Particle-v0"), seed, budget)  # random starts, no obstacle
        ebm.learn(budget.online_timesteps)
        ff_settings = merge_settings(PAPER_ACTION_FF, {"planner_config": dict(budget.ff_planner)})
        ff = ActionFFAgent("MultiInputPolicy", gym.make("ebm/Particle-v0"), seed=seed, **ff_settings)
        ff.learn(budget.online_timesteps)
        blind_planner = ff.planner
        measured: dict[str, Any] = {"scores": {}, "successes": {}, "paths": {}}
        for method in METHODS:
            agent: Any = ff if method.startswith("action_ff") else ebm
            ebm.set_plan_constraints([box_energy] if method == "ebm_box_energy" else [])
            ff.planner = BoxAwareActionPlanner(blind_planner, box) if method == "action_ff_box_model" else blind_planner
            measured["scores"][method], measured["successes"][method] = [], []
            for episode in range(budget.eval_episodes):
                score, path, success = run_episode(agent, eval_env, seed=1000 + episode)
                measured["scores"][method].append(score)
                measured["successes"][method].append(success)
                if episode == 0:
                    measured["paths"][method] = path  # [L+1, 2]
        return measured

    for seed in seeds:
        # Each finished seed is kept in out_dir/seeds/, so a figure cut short resumes at the next seed.
        measured = seed_result(
            out_dir,
            "obstacle_generalisation",
            seed,
            functools.partial(train_and_measure, seed),
            digest=figure_digest("obstacle_generalisation"),
        )
        for method in METHODS:
            scores[method].append([float(v) for v in measured["scores"][method]])
            successes[method].extend(bool(v) for v in measured["successes"][method])
            if seed == seeds[0]:
                paths[method] = np.asarray(measured["paths"][method], dtype=np.float64)
    anchors = compute_anchors("ebm/Particle-v0", eval_kwargs, seed=0)
    paper = paper_numbers("obstacle_generalisation")
    metrics = {
        "box": list(box),
        "start": list(OBSTACLE_START),
        "goal": list(OBSTACLE_GOAL),
        "seeds": seeds,
        "train_timesteps": budget.online_timesteps,
        "eval_episodes": budget.eval_episodes,
        "optimum": obstacle_optimum(box, OBSTACLE_START, OBSTACLE_GOAL),
        "standing_still": anchors.still_score,
        "random_mean": anchors.random_mean,
        "methods": {
            m: {
                **summary(np.ravel(scores[m])),
                "per_seed": [float(np.mean(s)) for s in scores[m]],
                "success_rate": float(np.mean(successes[m])),
            }
            for m in METHODS
        },
        "paper": {method: paper[label] for method, label in (("ebm", "EBM"), ("action_ff", "Action FF"))},
    }
    png = _plot_paths(paths, box, out_dir / "obstacle_paths.png")
    return finish("obstacle_generalisation", out_dir, seeds, scale, pngs=[png], metrics=metrics, table_md=_table(metrics))


class BoxAwareActionPlanner(ActionPlanner):
    """An Action FF planner whose forward model knows the box: a predicted move touching it stays put (the env's rule).

    :param inner: the agent's planner (its settings and bounds are reused).
    :param box: (xmin, ymin, xmax, ymax) over state dims 0 and 1.
    """

    def __init__(self, inner: ActionPlanner, box: Sequence[float]) -> None:
        bounds = (inner.action_low.cpu().numpy(), inner.action_high.cpu().numpy(), inner.goal_indices.cpu().numpy())
        super().__init__(inner.config, *bounds, device=inner.device)
        self.box = torch.as_tensor(np.asarray(box, dtype=np.float32), device=inner.device)  # [4]

    def plan(
        self,
        model: ForwardModel,
        start: Tensor,
        goals: Tensor,
        generator: torch.Generator,
        iterations: int | None = None,
        init_actions: Tensor | None = None,
    ) -> tuple[Tensor, Tensor, Tensor]:
        """Plan as the inner planner does, through the model with the box composed in (see the class)."""
        box = self.box

        def blocked_model(states: Tensor, actions: Tensor) -> Tensor:
            predicted = model(states, actions)  # [..., D]
            low = torch.minimum(states[..., :2], predicted[..., :2])  # [..., 2] the segment's bounding box
            high = torch.maximum(states[..., :2], predicted[..., :2])
            touches = (low[..., 0] <= box[2]) & (high[..., 0] >= box[0]) & (low[..., 1] <= box[3]) & (high[..., 1] >= box[1])
            return torch.where(touches[..., None], states, predicted)

        return super().plan(blocked_model, start, goals, generator, iterations, init_actions)


def obstacle_optimum(
    box: Sequence[float],
    start: Sequence[float] = OBSTACLE_START,
    goal: Sequence[float] = OBSTACLE_GOAL,
    spacing: float = 0.01,
) -> float:
    """Best score from ``start`` to ``goal`` around ``box`` on a lattice, by value iteration over the env's own moves.

    Every move of up to 0.05 per axis between lattice points is tried with ``ParticleEnv.forward_dynamics`` (so the
    env's rejection rule decides), costing the L1 distance to the goal after the move; reaching the goal ends.

    :param box: the obstacle (xmin, ymin, xmax, ymax).
    :param start: start point, snapped to the lattice.
    :param goal: goal point, snapped to the lattice.
    :param spacing: lattice spacing; it must divide 0.05.
    :return: the optimal score (negative), or -inf when the goal is unreachable.
    """
    reach = round(0.05 / spacing)
    if abs(reach * spacing - 0.05) > 1e-12:
        raise ValueError(f"spacing must divide the 0.05 move exactly, got {spacing}")
    env = ParticleEnv(start=start, goal=goal, obstacle=box)  # validates the box against start and goal
    cells = round(1.0 / spacing)
    coords = np.arange(-cells, cells + 1) / cells  # [L]
    grid = np.stack(np.meshgrid(coords, coords, indexing="ij"), axis=-1)  # [L, L, 2]

    def snap(point: Sequence[float]) -> tuple[int, int]:
        x, y = (round((float(v) + 1.0) * cells) for v in point)
        return x, y

    goal_index = snap(goal)
    arrival = np.abs(grid - grid[goal_index]).sum(-1)  # [L, L] |reward| after arriving
    successors = []
    for dx in range(-reach, reach + 1):
        for dy in range(-reach, reach + 1):
            if dx or dy:
                actions = np.broadcast_to(np.array([dx, dy]) * spacing * 20.0, grid.shape)
                nxt = np.rint((env.forward_dynamics(grid, actions) + 1.0) * cells).astype(np.int64)  # [L, L, 2]
                successors.append((nxt[..., 0], nxt[..., 1]))
    cost_to_go = np.full(arrival.shape, np.inf)
    cost_to_go[goal_index] = 0.0
    while True:
        through = arrival + cost_to_go  # [L, L] cost of arriving at a cell, then going on
        through[goal_index] = 0.0
        best = np.min([through[ix, iy] for ix, iy in successors], axis=0)
        best[goal_index] = 0.0
        if np.array_equal(best, cost_to_go):
            return -float(cost_to_go[snap(start)])
        cost_to_go = best


def _plot_paths(paths: dict[str, np.ndarray], box: Sequence[float], path: Path) -> Path:
    figure, axis = plt.subplots(figsize=(5, 5))
    axis.add_patch(Rectangle((box[0], box[1]), box[2] - box[0], box[3] - box[1], color="0.6", label="unseen obstacle"))
    for method, positions in paths.items():
        axis.plot(positions[:, 0], positions[:, 1], "-o", markersize=2, linewidth=1.2, label=LABELS[method])
    axis.plot(*OBSTACLE_START, "ks", markersize=6, label="start")
    axis.plot(*OBSTACLE_GOAL, "*", color="gold", markeredgecolor="k", markersize=14, label="goal")
    points = np.concatenate([np.reshape(box, (2, 2)), *paths.values()])  # [M, 2] everything drawn
    low, high = min(points.min(), -0.25) - 0.05, max(points.max(), 0.75) + 0.05
    axis.set_xlim(low, high)
    axis.set_ylim(low, high)
    axis.set_aspect("equal")
    axis.grid(alpha=0.3)
    axis.set_title("Unseen obstacle: first seed, first episode")
    axis.legend(fontsize="x-small", loc="best")
    return save_png(figure, path)


def _table(metrics: dict[str, Any]) -> str:
    paper = metrics["paper"]
    paper_of = {"ebm_no_box_energy": paper["ebm"], "action_ff": paper["action_ff"]}
    rows: list[list[Any]] = []
    for method in METHODS:
        m = metrics["methods"][method]
        rows.append([LABELS[method], f"{m['mean']:.2f} ± {m['std']:.2f}", m["success_rate"], paper_of.get(method)])
    rows.append(["optimum (lattice value iteration)", f"{metrics['optimum']:.2f}", None, None])
    rows.append(["standing still", f"{metrics['standing_still']:.2f}", None, None])
    rows.append(["random actions", f"{metrics['random_mean']:.2f}", None, None])
    header = ["method", "score (mean ± std, seeds x episodes)", "success rate", "paper (authors' box, goal unreachable)"]
    return markdown_table(header, rows)


__all__ = ["OBSTACLE_BOX", "BoxAwareActionPlanner", "obstacle_generalisation", "obstacle_optimum"]
