"""The paper's figure experiments (Sec. 4.3-4.4), by name: each trains what it needs, measures, and draws.

Every experiment is a function ``f(out_dir, *, seeds, scale="paper") -> FigureResult`` that writes its PNGs and a
``figure.json`` (:meth:`FigureResult.save`) under ``out_dir``. ``scale="paper"`` uses the paper's budgets (50k
online transitions, 100k random transitions for pretraining, Sawyer random exploration to 250k); ``scale="smoke"``
uses tens of transitions and a tiny planner, so that a test runs each in seconds. All numbers are computed; the
paper's own numbers only appear beside ours, labelled as the paper's.

=========================== ====================================================================================
name                        what it reproduces
=========================== ====================================================================================
``obstacle_generalisation`` EBM vs Action FF around a box unseen in training (paper: EBM -61.94, FF -81.24)
``plan_diversity``          the envelope of sampled particle plans grows with the planning horizon
``reacher_directions``      Reacher plans to one goal go both clockwise and counter-clockwise
``maze_exploration``        maze coverage of a goal-free EBM vs random actions, heatmaps and curve
``sawyer_exploration``      Sawyer finger voxel occupancy of a goal-free EBM vs random (log-x curve)
``frontier_exploration``    not in the paper: maze coverage of the EBM exploring its visited states' frontier vs random
``energy_maps``             energy and visitation maps at several points of training (particle, maze)
=========================== ====================================================================================

Example::

    from pathlib import Path
    from eval.paper.figures import FIGURES

    result = FIGURES["plan_diversity"](Path("results/plan_diversity"), seeds=[0, 1, 2])
    print(result.table_md)
"""

from __future__ import annotations

from collections.abc import Callable

from eval.paper.figures.common import SCALES, FigureBudget, FigureResult, budget_for
from eval.paper.figures.energy import energy_maps
from eval.paper.figures.exploration import frontier_exploration, maze_exploration, original_voxel_occupancy, sawyer_exploration
from eval.paper.figures.obstacle import OBSTACLE_BOX, obstacle_generalisation, obstacle_optimum
from eval.paper.figures.planning import plan_diversity, reacher_directions

FIGURES: dict[str, Callable[..., FigureResult]] = {
    "obstacle_generalisation": obstacle_generalisation,
    "plan_diversity": plan_diversity,
    "reacher_directions": reacher_directions,
    "maze_exploration": maze_exploration,
    "frontier_exploration": frontier_exploration,
    "sawyer_exploration": sawyer_exploration,
    "energy_maps": energy_maps,
}
"""Experiment name -> function ``(out_dir, *, seeds, scale="paper") -> FigureResult``."""

__all__ = [
    "FIGURES",
    "OBSTACLE_BOX",
    "SCALES",
    "FigureBudget",
    "FigureResult",
    "budget_for",
    "energy_maps",
    "frontier_exploration",
    "maze_exploration",
    "obstacle_generalisation",
    "obstacle_optimum",
    "original_voxel_occupancy",
    "plan_diversity",
    "reacher_directions",
    "sawyer_exploration",
]
