"""The particle environment of the paper (original ``envs.Point``), with the optional box obstacle of its test."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from envs import rendering
from envs.point_base import PointGoalEnv, PointLike


class ParticleEnv(PointGoalEnv):
    """A particle in [-1, 1]^2 moving by at most 0.05 per axis per step; reward = -L1 distance to the goal.

    The paper's evaluation is ``start=(0, 0), goal=(0.5, 0.5)``, whose best score (sum of rewards) is -4.5: ten
    diagonal steps. Training uses a random start (``start=None``).

    :param start: fixed start (x, y), or ``None`` (default) for a uniform random start on every reset.
    :param goal: fixed goal (x, y) (default (0.5, 0.5)), or ``None`` for a uniform random goal.
    :param obstacle: ``None`` or an axis-aligned box ``(xmin, ymin, xmax, ymax)``; a step is rejected (the particle
        stays put) when the bounding box of its segment touches the obstacle, boundary included (original rule).
        The original flag's order was ``[top, left, bottom, right]``: its default ``[0.5, 0.1, 0.1, 0.5]`` is
        ``(0.1, 0.1, 0.5, 0.5)`` here, which touches the goal (0.5, 0.5) and is therefore refused.
    :param success_threshold: terminate when the L1 distance to the goal is below this (paper's evaluation: 0.01).
    :param render_mode: ``None`` or ``"rgb_array"``.
    :param render_size: side in pixels of the ``rgb_array`` frame.
    """

    def __init__(
        self,
        start: PointLike | None = None,
        goal: PointLike | None = (0.5, 0.5),
        obstacle: Sequence[float] | np.ndarray | None = None,
        success_threshold: float = 0.01,
        render_mode: str | None = None,
        render_size: int = 256,
    ) -> None:
        # The obstacle must exist before the base class validates start and goal against it.
        self.obstacle: np.ndarray | None = None if obstacle is None else _check_box(obstacle)
        super().__init__(
            start=start, goal=goal, success_threshold=success_threshold, render_mode=render_mode, render_size=render_size
        )

    def _is_free(self, points: np.ndarray) -> np.ndarray:
        if self.obstacle is None:
            return super()._is_free(points)
        points = np.asarray(points, dtype=np.float64)
        return ~_boxes_touch(points, points, self.obstacle)

    def _move_allowed(self, states: np.ndarray, next_states: np.ndarray) -> np.ndarray:
        if self.obstacle is None:
            return super()._move_allowed(states, next_states)
        return ~_boxes_touch(np.minimum(states, next_states), np.maximum(states, next_states), self.obstacle)

    def _blocked_reason(self) -> str:
        box = _format_box(self.obstacle)
        return f"it lies in the obstacle box (xmin, ymin, xmax, ymax) = {box}; move the box or the point"

    def _draw_background(self, image: np.ndarray) -> np.ndarray:
        if self.obstacle is None:
            return image
        return rendering.fill_box(image, self.obstacle, rendering.WALL_GRAY)


def _boxes_touch(lows: np.ndarray, highs: np.ndarray, box: np.ndarray) -> np.ndarray:
    """Whether the boxes [lows, highs] ([..., 2] each) overlap ``box`` by >= 0 (touching counts)."""
    return (lows[..., 0] <= box[2]) & (highs[..., 0] >= box[0]) & (lows[..., 1] <= box[3]) & (highs[..., 1] >= box[1])


def _check_box(obstacle: Sequence[float] | np.ndarray) -> np.ndarray:
    """Validate ``(xmin, ymin, xmax, ymax)``; the original silently accepted degenerate boxes that never collide."""
    box = np.asarray(obstacle, dtype=np.float64)
    if box.shape != (4,) or not np.all(np.isfinite(box)):
        raise ValueError(f"obstacle must be a finite box (xmin, ymin, xmax, ymax) or None, got {obstacle!r}")
    text = _format_box(box)
    if box[0] >= box[2] or box[1] >= box[3]:
        raise ValueError(
            f"obstacle {text} is degenerate: it needs xmin < xmax and ymin < ymax (order is (xmin, ymin, xmax, ymax), "
            "not the original's [top, left, bottom, right])"
        )
    if box[2] < -1.0 or box[0] > 1.0 or box[3] < -1.0 or box[1] > 1.0:
        raise ValueError(f"obstacle {text} lies entirely outside the state box [-1, 1]^2, so it would never collide")
    if box[0] <= -1.0 and box[1] <= -1.0 and box[2] >= 1.0 and box[3] >= 1.0:
        raise ValueError(f"obstacle {text} covers the whole state box [-1, 1]^2: there is no free position")
    return box


def _format_box(box: np.ndarray | None) -> str:
    return "None" if box is None else "(" + ", ".join(f"{float(v):g}" for v in box) + ")"


__all__ = ["ParticleEnv"]
