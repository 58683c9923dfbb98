"""Reacher: gymnasium's Reacher-v4 MuJoCo model seen through the paper's normalised joint state (paper Sec. 4.1).

The physics is Reacher-v4's own (its XML, RK4 at 10 ms, 2 physics steps per env step, torque motors with gear 200,
Reacher-v4's reset noise). What changes is what the agent sees and is scored on, following the original code's
wrapper (reference/original_code.md §6): the state is [th1_hat, th2_hat, th1dot / 10, th2dot / 10] with
th_hat = ((th mod 2 pi) - pi) / pi in [-1, 1), the goal is a pair of normalised joint angles, and the reward is the
negative wrapped L1 distance of the angles to the goal. The gym target and fingertip coordinates are dropped from
the state; the red target ball is drawn at the fingertip position of the goal angles so renders show the goal.
"""

from __future__ import annotations

import functools
import os
from typing import Any, ClassVar

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from envs.mujoco_inverse import FrameSkipInverseDynamics
from envs.torque_step import step_torques

DEFAULT_GOAL = (0.7, 0.5)
"""The paper's Reacher goal in normalised joint angles (original code, ``train.py`` flags)."""

_RESCUE_COST = 1e-12
"""Squared residual above which an inverse-dynamics fit counts as poor."""

INVERSE_ANGLE_WEIGHT = 1.0
"""Weight of the angle dims against the velocity dims (both normalised) in ``ReacherEnv.inverse_dynamics``'s fit.

One env step of full torque moves a normalised angle by about 0.0126 and a velocity / 10 by about 0.40, so with equal
weights a wanted state that the torques cannot reach is fitted almost entirely on its velocity dims: a plan that moves
the angles towards the goal without the matching velocities yields torques near 0 (measured by the retired probe
reacher_plan_gap, docs/notes/probes.md#probereacher_plan_gap)."""

_LINK_LENGTHS = (0.1, 0.11)  # shoulder-to-elbow and elbow-to-fingertip (Reacher-v4 XML).


class ReacherEnv(gym.Env):
    """Two-link planar reacher with a joint-space goal, state [th1_hat, th2_hat, th1dot / 10, th2dot / 10].

    :param goal: the goal (th1_hat, th2_hat) in [-1, 1]^2; ``None`` draws a new reachable goal at every reset.
    :param success_threshold: wrapped-L1 distance below which the episode counts as a success.
    :param terminate_on_success: end the episode on success (the original wrapper's ``done``).
    :param inverse_angle_weight: weight of the angle dims against the velocity dims in ``inverse_dynamics``; see
        ``INVERSE_ANGLE_WEIGHT``. Reachable transitions are recovered exactly with any weight.
    :param render_mode: ``None`` or ``"rgb_array"``.
    :param width: render width in pixels.
    :param height: render height in pixels.
    """

    # gymnasium annotates metadata as an instance attribute; it is class-level data.
    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 50}  # type: ignore[misc]

    frame_skip: int = 2
    """Physics steps per env step (Reacher-v4)."""

    def __init__(
        self,
        goal: tuple[float, float] | np.ndarray | None = DEFAULT_GOAL,
        success_threshold: float = 0.01,
        terminate_on_success: bool = True,
        inverse_angle_weight: float = INVERSE_ANGLE_WEIGHT,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 480,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}.")
        if success_threshold <= 0:
            raise ValueError(f"success_threshold must be > 0, got {success_threshold}.")
        if not (np.isfinite(inverse_angle_weight) and inverse_angle_weight > 0):
            raise ValueError(f"inverse_angle_weight must be finite and > 0, got {inverse_angle_weight}.")
        self.inverse_angle_weight = float(inverse_angle_weight)
        self.fixed_goal = None if goal is None else _validate_goal(goal)
        self.success_threshold = float(success_threshold)
        self.terminate_on_success = bool(terminate_on_success)
        self.render_mode = render_mode
        self.width, self.height = int(width), int(height)

        self.model = _reacher_model()
        self.data = mujoco.MjData(self.model)
        self.dt = self.frame_skip * self.model.opt.timestep
        """Seconds per env step (0.02)."""
        self.physics_steps = 0
        """Physics steps taken since construction."""
        self._inverse = FrameSkipInverseDynamics(self.model, self.frame_skip)
        self._renderer: mujoco.Renderer | None = None
        self._goal = np.array(DEFAULT_GOAL if self.fixed_goal is None else self.fixed_goal)  # [2]

        self.goal_indices = np.array([0, 1])
        self.target_indices = np.array([], dtype=int)
        self.goal_period: float | None = 2.0
        # None: the angles are periodic (wrap them, never clip) and the velocities are unbounded.
        self.state_low: np.ndarray | None = None
        self.state_high: np.ndarray | None = None

        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        angle_box = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float64)
        self.observation_space = spaces.Dict(
            {
                "observation": spaces.Box(
                    low=np.array([-1.0, -1.0, -np.inf, -np.inf]), high=np.array([1.0, 1.0, np.inf, np.inf]), dtype=np.float64
                ),
                "achieved_goal": angle_box,
                "desired_goal": angle_box,
            }
        )

    # ----------------------------------------------------------------------------------------------------- gym API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict[str, np.ndarray], dict]:
        """Reset with Reacher-v4's noise (joints U(-0.1, 0.1) rad, velocities U(-0.005, 0.005) rad/s).

        :param seed: seeds ``self.np_random``.
        :param options: ``{"goal": (g1, g2)}`` overrides the goal for this episode.
        :return: observation dict and info.
        """
        super().reset(seed=seed)
        if options is not None and options.get("goal") is not None:
            self._goal = _validate_goal(options["goal"])
        elif self.fixed_goal is not None:
            self._goal = self.fixed_goal.copy()
        else:
            self._goal = self._sample_goal()
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[:2] = self.np_random.uniform(-0.1, 0.1, size=2)
        self.data.qvel[:2] = self.np_random.uniform(-0.005, 0.005, size=2)
        self.data.qpos[2:] = fingertip_position(self._goal)  # the (passive, massless) target ball marks the goal
        self.data.qvel[2:] = 0.0
        mujoco.mj_forward(self.model, self.data)
        obs = self._get_obs()
        return obs, self._info(obs)

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict]:
        """Hold the torque ``action`` (in [-1, 1]^2, gear 200) for two RK4 steps.

        :param action: [2] normalised torques; clipped to the action bounds (NaN/inf raise ValueError).
        :return: observation, reward, terminated, truncated (always False: TimeLimit truncates), info.
        """
        step_torques("Reacher", self.model, self.data, action, self.frame_skip)
        self.physics_steps += self.frame_skip
        obs = self._get_obs()
        info = self._info(obs)
        reward = float(self.compute_reward(obs["achieved_goal"], obs["desired_goal"], info))
        terminated = bool(self.compute_terminated(obs["achieved_goal"], obs["desired_goal"], info))
        return obs, reward, terminated, False, info

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any = None) -> np.ndarray:
        """Negative wrapped L1 distance of normalised angles (vectorised over leading axes).

        :param achieved_goal: [..., 2] normalised angles.
        :param desired_goal: [..., 2] goal angles.
        :param info: unused (GoalEnv signature).
        :return: [...] rewards.
        """
        return -wrapped_l1_distance(achieved_goal, desired_goal)

    def compute_terminated(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any = None) -> np.ndarray:
        """Success (distance below the threshold) when ``terminate_on_success``, else False.

        :return: [...] booleans.
        """
        success = wrapped_l1_distance(achieved_goal, desired_goal) < self.success_threshold
        return success & self.terminate_on_success

    def compute_truncated(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any = None) -> np.ndarray:
        """Never: the 50-step limit comes from the registration's TimeLimit.

        :return: [...] False.
        """
        return np.zeros(np.shape(wrapped_l1_distance(achieved_goal, desired_goal)), dtype=bool)

    def render(self) -> np.ndarray | None:
        """Top-down RGB frame [H, W, 3] uint8 (``render_mode="rgb_array"``), else None."""
        if self.render_mode != "rgb_array":
            return None
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.model, height=self.height, width=self.width)
        camera = mujoco.MjvCamera()
        camera.lookat[:] = (0.0, 0.0, 0.0)
        camera.distance, camera.elevation, camera.azimuth = 0.75, -90.0, 90.0
        self._renderer.update_scene(self.data, camera=camera)
        return self._renderer.render()

    def close(self) -> None:
        """Release the renderer."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # ------------------------------------------------------------------------------------------- agent helpers
    @property
    def goal(self) -> np.ndarray:
        """The current goal (th1_hat, th2_hat) [2]."""
        return self._goal.copy()

    def sample_exploration_action(self) -> np.ndarray:
        """Uniform random torques in [-1, 1]^2 (the original's Reacher data), drawn from ``self.np_random``.

        :return: [2] action.
        """
        return self.np_random.uniform(-1.0, 1.0, size=2).astype(np.float32)

    def inverse_dynamics(self, states: np.ndarray, next_states: np.ndarray) -> np.ndarray:
        """Torques that carry each state to its next state over one env step (MuJoCo inverse dynamics, refined).

        Starts from ``mj_inverse`` with the mean acceleration of the step and refines it on the simulator (see
        ``envs.mujoco_inverse``): exact to ~1e-6 for reachable transitions; otherwise the in-bounds action whose
        outcome is closest to ``next_states`` (wrapped angles weighted by ``inverse_angle_weight``, velocities / 10).

        :param states: [B, 4] (or [4]) normalised states.
        :param next_states: [B, 4] (or [4]) wanted next states.
        :return: [B, 2] (or [2]) actions in [-1, 1].
        """
        states, next_states, single = _check_state_pair(states, next_states, 4)
        qpos, qvel = state_to_physics(states)
        _, next_qvel = state_to_physics(next_states)
        residual = functools.partial(_reacher_residual, angle_weight=self.inverse_angle_weight)
        actions, cost = self._inverse.solve(qpos, qvel, next_qvel, next_states, residual)
        # The elbow can be pushed a little past its +-3 rad limit, and past +-pi the normalised angle cannot say on
        # which side of the limit it is; where the fit is poor, try the other side and keep the better fit.
        beyond = np.flatnonzero((np.abs(qpos[:, 1]) > self.model.jnt_range[1, 1]) & (cost > _RESCUE_COST))
        if beyond.size:
            other_qpos = qpos[beyond].copy()
            other_qpos[:, 1] -= np.sign(other_qpos[:, 1]) * 2.0 * np.pi
            other_actions, other_cost = self._inverse.solve(
                other_qpos, qvel[beyond], next_qvel[beyond], next_states[beyond], residual
            )
            better = other_cost < cost[beyond]
            actions[beyond[better]] = other_actions[better]
        actions = actions.astype(self.action_space.dtype)
        return actions[0] if single else actions

    # --------------------------------------------------------------------------------------------------- internals
    def _get_obs(self) -> dict[str, np.ndarray]:
        state = np.concatenate([normalize_angle(self.data.qpos[:2]), self.data.qvel[:2] / 10.0])  # [4]
        return {"observation": state, "achieved_goal": state[:2].copy(), "desired_goal": self._goal.copy()}

    def _info(self, obs: dict[str, np.ndarray]) -> dict[str, Any]:
        distance = float(wrapped_l1_distance(obs["achieved_goal"], obs["desired_goal"]))
        return {"is_success": distance < self.success_threshold, "distance": distance}

    def _sample_goal(self) -> np.ndarray:
        # The elbow is limited to |th2| <= 3 rad, so angles beyond it are unreachable goals.
        elbow_limit = self.model.jnt_range[1, 1]
        elbow = self.np_random.uniform(-elbow_limit, elbow_limit)
        return np.array([self.np_random.uniform(-1.0, 1.0), float(normalize_angle(elbow))])


# ------------------------------------------------------------------------------------------------------- helpers
def normalize_angle(angle: np.ndarray | float) -> np.ndarray:
    """Map radians to the paper's normalised angle ((th mod 2 pi) - pi) / pi in [-1, 1).

    :param angle: [...] radians.
    :return: [...] normalised angles.
    """
    normalized = (np.mod(angle, 2.0 * np.pi) - np.pi) / np.pi
    # mod can round a tiny negative angle up to exactly 2 pi, i.e. +1, which belongs at -1.
    return np.where(normalized >= 1.0, normalized - 2.0, normalized)


def denormalize_angle(normalized: np.ndarray) -> np.ndarray:
    """Inverse of ``normalize_angle`` into MuJoCo's range [-pi, pi).

    :param normalized: [...] normalised angles.
    :return: [...] radians in [-pi, pi).
    """
    return np.mod(np.pi * (np.asarray(normalized) + 1.0) + np.pi, 2.0 * np.pi) - np.pi


def wrap_difference(difference: np.ndarray) -> np.ndarray:
    """Signed difference of normalised angles mapped to [-1, 1) (period 2).

    :param difference: [...] raw differences.
    :return: [...] wrapped differences.
    """
    return np.mod(difference + 1.0, 2.0) - 1.0


def wrapped_l1_distance(achieved: np.ndarray, desired: np.ndarray) -> np.ndarray:
    """The original's wrapped L1: sum_j min(|a - g|, |g + 2 - a|, |g - 2 - a|) over the last axis.

    :param achieved: [..., 2] normalised angles.
    :param desired: [..., 2] normalised goal angles.
    :return: [...] distances.
    """
    achieved, desired = np.asarray(achieved, dtype=np.float64), np.asarray(desired, dtype=np.float64)
    per_joint = np.minimum(np.abs(achieved - desired), np.abs(desired + 2.0 - achieved))
    per_joint = np.minimum(per_joint, np.abs(desired - 2.0 - achieved))
    return per_joint.sum(axis=-1)


def fingertip_position(goal: np.ndarray) -> np.ndarray:
    """Planar fingertip (x, y) for normalised joint angles (forward kinematics of the two links).

    :param goal: [..., 2] normalised angles.
    :return: [..., 2] metres.
    """
    shoulder, elbow = np.moveaxis(denormalize_angle(goal), -1, 0)
    upper, fore = _LINK_LENGTHS
    x = upper * np.cos(shoulder) + fore * np.cos(shoulder + elbow)
    y = upper * np.sin(shoulder) + fore * np.sin(shoulder + elbow)
    return np.stack([x, y], axis=-1)


def state_to_physics(states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """MuJoCo qpos [B, 4] and qvel [B, 4] for normalised states [B, 4] (target slides at rest at 0).

    :param states: [B, 4] normalised states.
    :return: qpos and qvel.
    """
    qpos = np.zeros((states.shape[0], 4))
    qvel = np.zeros((states.shape[0], 4))
    qpos[:, :2] = denormalize_angle(states[:, :2])
    qvel[:, :2] = 10.0 * states[:, 2:4]
    return qpos, qvel


def _reacher_residual(
    qpos_end: np.ndarray, qvel_end: np.ndarray, targets: np.ndarray, *, angle_weight: float = 1.0
) -> np.ndarray:
    """Mismatch [B, M, 4] of rolled-out end states with wanted states [B, 1, 4]: wrapped angles times
    ``angle_weight``, velocities / 10."""
    angle_error = angle_weight * wrap_difference(normalize_angle(qpos_end[..., :2]) - targets[..., :2])
    return np.concatenate([angle_error, qvel_end[..., :2] / 10.0 - targets[..., 2:]], axis=-1)


def _check_state_pair(states: np.ndarray, next_states: np.ndarray, dim: int) -> tuple[np.ndarray, np.ndarray, bool]:
    states = np.asarray(states, dtype=np.float64)
    next_states = np.asarray(next_states, dtype=np.float64)
    if states.shape != next_states.shape:
        raise ValueError(f"states and next_states must have the same shape, got {states.shape} and {next_states.shape}.")
    if states.ndim not in (1, 2) or states.shape[-1] != dim:
        raise ValueError(f"Expected states of shape [B, {dim}] or [{dim}], got {states.shape}.")
    if not (np.all(np.isfinite(states)) and np.all(np.isfinite(next_states))):
        raise ValueError("states and next_states must be finite (no NaN or inf).")
    single = states.ndim == 1
    return np.atleast_2d(states), np.atleast_2d(next_states), single


def _validate_goal(goal: Any) -> np.ndarray:
    goal_array = np.asarray(goal, dtype=np.float64)
    if goal_array.shape != (2,) or not np.all(np.isfinite(goal_array)):
        raise ValueError(f"The Reacher goal must be 2 finite normalised angles (th1_hat, th2_hat), got {goal!r}.")
    if np.any(np.abs(goal_array) > 1.0):
        raise ValueError(f"Normalised goal angles lie in [-1, 1]; got {goal!r} (use ((th mod 2pi) - pi) / pi).")
    return goal_array


@functools.cache
def _reacher_model() -> mujoco.MjModel:
    """Reacher-v4's MuJoCo model, loaded once per process (envs share it read-only; each has its own MjData)."""
    import gymnasium.envs.mujoco as gym_mujoco

    path = os.path.join(os.path.dirname(gym_mujoco.__file__), "assets", "reacher.xml")
    return mujoco.MjModel.from_xml_path(path)
