"""Shared base of the 2-D point environments (particle, particle with obstacle, maze): dynamics, reward, contract.

Numerics (why the inverse dynamics is exact): the state is always a float32-representable point, kept in float64 so
that the move arithmetic adds no rounding of its own, and the observation is that state cast to float32 with no loss.
``inverse_dynamics`` computes ``clip(20 * (s' - s), -1, 1)`` in float64 and returns it as float32; stepping from
``s`` with that action lands on ``s'`` up to the float32 rounding of the action (|error| < 1e-7 per axis), for every
move of L-inf size <= 0.05 that stays inside the box and is not rejected.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from gymnasium_robotics.core import GoalEnv

from envs import rendering

ACTION_SCALE = 20.0
"""An action of L-inf norm 1 moves the point by 1 / ACTION_SCALE = 0.05 per axis (original ``envs.Point``)."""

MAX_RESAMPLE_TRIES = 10_000

PointLike = Sequence[float] | np.ndarray


class PointGoalEnv(GoalEnv):
    """A point in [-1, 1]^2 moved by at most 0.05 per axis per step towards a goal; subclasses add walls.

    Subclasses override ``_is_free`` (where the point may be) and, if needed, ``_move_allowed`` (which moves are
    rejected: the point then stays put) and ``_draw_background``.

    :param start: fixed start (x, y), or ``None`` for a uniform random free start on every reset.
    :param goal: fixed goal (x, y), or ``None`` for a uniform random free goal on every reset.
    :param success_threshold: the episode terminates (``info["is_success"] = 1.0``) when the L1 distance to the
        goal after a step is below this (0.01 is the paper's evaluation eps; the original trained online with 0.05).
    :param render_mode: ``None`` or ``"rgb_array"``.
    :param render_size: side in pixels of the square ``rgb_array`` frame.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(
        self,
        start: PointLike | None = None,
        goal: PointLike | None = None,
        success_threshold: float = 0.01,
        render_mode: str | None = None,
        render_size: int = 256,
    ) -> None:
        super().__init__()
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        if not (np.isfinite(success_threshold) and success_threshold > 0):
            raise ValueError(f"success_threshold must be a positive float (L1 distance), got {success_threshold!r}")
        if int(render_size) < 16:
            raise ValueError(f"render_size must be an int >= 16 pixels, got {render_size!r}")
        self.render_mode = render_mode
        self.render_size = int(render_size)
        self.success_threshold = float(success_threshold)

        # Contract of envs/__init__.py, on the unwrapped env.
        self.goal_indices = np.array([0, 1])
        self.target_indices = np.array([], dtype=int)
        self.goal_period: float | None = None
        self.state_low = -np.ones(2)
        self.state_high = np.ones(2)

        box = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.observation_space = spaces.Dict({"observation": box, "achieved_goal": box, "desired_goal": box})
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)

        self.start = None if start is None else self._check_point(start, "start")
        self.goal = None if goal is None else self._check_point(goal, "goal")
        self._state = np.zeros(2)  # [2] float64 holding float32-representable values
        self._goal = np.zeros(2)
        self._background: np.ndarray | None = None

    # ----------------------------------------------------------------------------------------------------- hooks
    def _is_free(self, points: np.ndarray) -> np.ndarray:
        """Where the point may be (start and goal must be free); the plain particle is free everywhere.

        :param points: points [..., 2].
        :return: bool mask [...].
        """
        return np.ones(np.shape(points)[:-1], dtype=bool)

    def _move_allowed(self, states: np.ndarray, next_states: np.ndarray) -> np.ndarray:
        """Whether a move from ``states`` to the (clipped) ``next_states`` is accepted; a rejected move stays put.

        :param states: points [..., 2].
        :param next_states: proposed points [..., 2], already clipped to the box.
        :return: bool mask [...].
        """
        return self._is_free(next_states)

    def _draw_background(self, image: np.ndarray) -> np.ndarray:
        """Draw the static scene (walls, obstacle) onto a blank canvas.

        :param image: blank image [H, W, 3] uint8.
        :return: the background image.
        """
        return image

    # ---------------------------------------------------------------------------------------------- gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Start an episode.

        :param seed: seeds ``self.np_random`` (the only source of randomness).
        :param options: optional ``{"start": (x, y), "goal": (x, y)}`` overriding the constructor's for this episode.
        :return: ``(observation dict, info)``.
        """
        super().reset(seed=seed, options=options)
        options = dict(options or {})
        unknown = set(options) - {"start", "goal"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)}; supported: 'start', 'goal'")
        start = options.get("start", self.start)
        goal = options.get("goal", self.goal)
        self._state = self._sample_free_point("start") if start is None else self._check_point(start, "start")
        self._goal = self._sample_free_point("goal") if goal is None else self._check_point(goal, "goal")
        distance = self._distance()
        return self._get_obs(), {"is_success": float(distance < self.success_threshold), "distance": distance}

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Move the point by ``action / max(||action||_inf, 1) / 20`` (rejected moves stay put).

        :param action: [2] in [-1, 1]; larger actions are rescaled, not clipped (original ``envs.Point``).
        :return: ``(observation, reward, terminated, truncated, info)``; reward = -L1 distance to the goal after the
            move; ``info`` holds ``is_success``, ``distance`` and ``rejected``.
        """
        action = np.asarray(action, dtype=np.float64)
        if action.shape != (2,) or not np.all(np.isfinite(action)):
            raise ValueError(f"action must be a finite array of shape (2,), got {action!r}")
        proposed = self._propose(self._state, action)
        rejected = not bool(self._move_allowed(self._state, proposed))
        if not rejected:
            self._state = proposed
        obs = self._get_obs()
        info: dict[str, Any] = {"rejected": rejected}
        reward = float(self.compute_reward(obs["achieved_goal"], obs["desired_goal"], info))
        terminated = bool(self.compute_terminated(obs["achieved_goal"], obs["desired_goal"], info))
        info.update(is_success=float(terminated), distance=-reward)
        return obs, reward, terminated, False, info

    def render(self) -> np.ndarray | None:
        """Render the scene: walls or obstacle (grey), goal (green), point (blue).

        :return: image [render_size, render_size, 3] uint8 in ``rgb_array`` mode, ``None`` otherwise.
        """
        if self.render_mode != "rgb_array":
            return None
        image = self.render_background()
        image = rendering.draw_disc(image, self._goal, max(self.success_threshold, 0.03), rendering.GOAL_GREEN)
        return rendering.draw_disc(image, self._state, 0.025, rendering.AGENT_BLUE)

    def render_background(self) -> np.ndarray:
        """The static scene alone (cached), e.g. to draw plans over with ``envs.rendering.draw_paths``.

        :return: image [render_size, render_size, 3] uint8.
        """
        if self._background is None:
            self._background = self._draw_background(rendering.blank_canvas(self.render_size))
        return self._background.copy()

    # ------------------------------------------------------------------------------------------- goal-env API
    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        """Negative L1 distance, vectorised over leading axes (HER relabelling).

        :param achieved_goal: [..., 2].
        :param desired_goal: [..., 2].
        :param info: unused (a dict or an array of dicts).
        :return: rewards [...] float64 (a numpy scalar for un-batched inputs).
        """
        return -_l1_distance(achieved_goal, desired_goal)

    def compute_terminated(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        """Success test, vectorised: L1 distance below ``success_threshold``.

        :param achieved_goal: [..., 2].
        :param desired_goal: [..., 2].
        :param info: unused.
        :return: bool [...].
        """
        return _l1_distance(achieved_goal, desired_goal) < self.success_threshold

    def compute_truncated(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        """Never truncates by itself (the registered ``TimeLimit`` does).

        :param achieved_goal: [..., 2].
        :param desired_goal: [..., 2].
        :param info: unused.
        :return: bool [...], all False.
        """
        return np.zeros(np.shape(_l1_distance(achieved_goal, desired_goal)), dtype=bool)

    # ---------------------------------------------------------------------------------------------- dynamics
    def forward_dynamics(self, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """Ground-truth batched transition, walls included (what ``step`` does, without touching the env).

        :param states: points [..., 2].
        :param actions: actions [..., 2] (same leading shape).
        :return: next points [..., 2] float64, each float32-representable.
        """
        states = np.asarray(states, dtype=np.float64)
        actions = np.asarray(actions, dtype=np.float64)
        _check_pair_shapes(states, actions, "states", "actions")
        proposed = self._propose(states, actions)
        allowed = self._move_allowed(states, proposed)[..., None]
        return np.where(allowed, proposed, states)

    def inverse_dynamics(self, states: np.ndarray, next_states: np.ndarray) -> np.ndarray:
        """Ground-truth inverse dynamics ``clip(20 * (s' - s), -1, 1)``; exact for every reachable in-bounds move.

        :param states: points [B, 2] or [2].
        :param next_states: points [B, 2] or [2] (same shape).
        :return: actions [B, 2] or [2] float32.
        """
        states = np.asarray(states, dtype=np.float64)
        next_states = np.asarray(next_states, dtype=np.float64)
        _check_pair_shapes(states, next_states, "states", "next_states")
        return np.clip(ACTION_SCALE * (next_states - states), -1.0, 1.0).astype(np.float32)

    # ---------------------------------------------------------------------------------------------- helpers
    @staticmethod
    def _propose(states: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """The move before walls: rescale to the L-inf ball, step, clip to the box, round to float32 precision."""
        scale = np.maximum(np.abs(actions).max(axis=-1, keepdims=True), 1.0)  # [..., 1]
        proposed = np.clip(states + actions / scale / ACTION_SCALE, -1.0, 1.0)
        return proposed.astype(np.float32).astype(np.float64)

    def _get_obs(self) -> dict[str, np.ndarray]:
        position = self._state.astype(np.float32)
        goal = self._goal.astype(np.float32)
        return {"observation": position.copy(), "achieved_goal": position.copy(), "desired_goal": goal}

    def _distance(self) -> float:
        return float(_l1_distance(self._state.astype(np.float32), self._goal.astype(np.float32)))

    def _check_point(self, point: PointLike, name: str) -> np.ndarray:
        """Validate a user-given start/goal; returns it rounded to float32 precision, held in float64."""
        array = np.asarray(point, dtype=np.float64)
        if array.shape != (2,) or not np.all(np.isfinite(array)):
            raise ValueError(f"{name} must be a finite (x, y) pair or None, got {point!r}")
        if np.any(np.abs(array) > 1.0):
            raise ValueError(f"{name} {tuple(array.tolist())} lies outside the state box [-1, 1]^2")
        array = array.astype(np.float32).astype(np.float64)
        if not bool(self._is_free(array)):
            raise ValueError(f"{name} {tuple(array.tolist())} is not a free position: {self._blocked_reason()}")
        return array

    def _blocked_reason(self) -> str:
        """Human-readable description of what blocks positions, for error messages."""
        return "it is blocked"

    def _sample_free_point(self, name: str) -> np.ndarray:
        for _ in range(MAX_RESAMPLE_TRIES):
            point = self.np_random.uniform(-1.0, 1.0, size=2).astype(np.float32).astype(np.float64)
            if bool(self._is_free(point)):
                return point
        raise RuntimeError(f"could not sample a free random {name} in {MAX_RESAMPLE_TRIES} tries; pass a fixed {name}")


def _l1_distance(achieved_goal: np.ndarray, desired_goal: np.ndarray) -> np.ndarray:
    achieved = np.asarray(achieved_goal, dtype=np.float64)
    desired = np.asarray(desired_goal, dtype=np.float64)
    if achieved.shape[-1:] != (2,) or desired.shape[-1:] != (2,):
        raise ValueError(f"goals must have a last axis of size 2, got {achieved.shape} and {desired.shape}")
    return np.abs(achieved - desired).sum(axis=-1)


def _check_pair_shapes(first: np.ndarray, second: np.ndarray, first_name: str, second_name: str) -> None:
    if first.shape != second.shape or first.shape[-1:] != (2,):
        raise ValueError(
            f"{first_name} and {second_name} must have the same shape [B, 2] or [2], got {first.shape} and {second.shape}"
        )


__all__ = ["ACTION_SCALE", "PointGoalEnv"]
