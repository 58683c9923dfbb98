"""A small point-mass GoalEnv with velocities (a damped double integrator), for tests of learned action inference.

The state is [x, y, vx, vy]; an action in [-1, 1]^2 is a force: v' = 0.9 v + 0.1 a, p' = p + 0.1 v'. The goal is a
position; an episode succeeds within 0.1 of it. It has no ``inverse_dynamics``, so an agent must learn how planned
states become actions, and a plan must keep its positions consistent with its velocities (PointMaze's, Fetch's and
Reacher's shape of state, in four dims).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from gymnasium_robotics.core import GoalEnv

DAMPING = 0.9
DT = 0.1
SUCCESS_DISTANCE = 0.1


class PointMassEnv(GoalEnv):
    """A damped point mass pushed towards a goal position (see the module docstring).

    :param max_speed: the velocity bound per axis (the state box's).
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": []}

    def __init__(self, max_speed: float = 1.0) -> None:
        self.max_speed = float(max_speed)
        high = np.array([1.0, 1.0, self.max_speed, self.max_speed], dtype=np.float32)
        self.observation_space = spaces.Dict(
            {
                "observation": spaces.Box(-high, high, dtype=np.float32),
                "achieved_goal": spaces.Box(-1.0, 1.0, (2,), dtype=np.float32),
                "desired_goal": spaces.Box(-1.0, 1.0, (2,), dtype=np.float32),
            }
        )
        self.action_space = spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self.goal_indices = np.array([0, 1])
        self._state = np.zeros(4)
        self._goal = np.zeros(2)

    def _obs(self) -> dict[str, np.ndarray]:
        state = self._state.astype(np.float32)
        return {"observation": state, "achieved_goal": state[:2].copy(), "desired_goal": self._goal.astype(np.float32)}

    def compute_reward(self, achieved_goal: Any, desired_goal: Any, info: Any) -> np.ndarray:
        """Minus the distance to the goal, batched over leading axes."""
        return -np.linalg.norm(np.asarray(achieved_goal) - np.asarray(desired_goal), axis=-1)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict, dict]:
        """Start at rest at a random position; the goal at least 0.8 away."""
        super().reset(seed=seed)
        start = self.np_random.uniform(-0.9, 0.9, 2)
        goal = self.np_random.uniform(-0.9, 0.9, 2)
        while np.linalg.norm(goal - start) < 0.8:
            goal = self.np_random.uniform(-0.9, 0.9, 2)
        self._state, self._goal = np.concatenate([start, np.zeros(2)]), goal
        return self._obs(), {"is_success": 0.0}

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        """One step of the damped double integrator, positions clipped to the box (velocity zeroed at a wall)."""
        force = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        velocity = np.clip(DAMPING * self._state[2:] + DT * force, -self.max_speed, self.max_speed)
        position = self._state[:2] + DT * velocity
        hit = np.abs(position) > 1.0
        velocity[hit] = 0.0
        self._state = np.concatenate([np.clip(position, -1.0, 1.0), velocity])
        obs = self._obs()
        distance = float(np.linalg.norm(obs["achieved_goal"] - obs["desired_goal"]))
        success = distance < SUCCESS_DISTANCE
        reward = float(self.compute_reward(obs["achieved_goal"], obs["desired_goal"], None))
        return obs, reward, False, False, {"is_success": float(success)}
