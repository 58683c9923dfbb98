"""SawyerReach: a torque-controlled 7-DoF Sawyer arm built from the model that ships inside Metaworld (paper Sec. 4.3).

Metaworld drives the Sawyer hand by a mocap weld; the paper's arm is driven by joint torques. The model here is
Metaworld's ``sawyer_reach_v3.xml`` edited with ``mujoco.MjSpec``: the mocap weld, the gripper actuators, the gripper
slide joints, the ``mocap`` body and the puck ``obj`` are removed, 7 torque motors are added on ``right_j0..6`` with
the real Sawyer's torque limits (80/80/40/40/9/9/9 N m) as gears, and the goal site becomes a mocap ball (a marker
with no dynamics). Metaworld's physics is kept: 2.5 ms semi-implicit Euler steps, Newton solver, joint damping 10,
the table and its walls (only the hand and fingers collide with them). Every body is gravity-compensated (``gravcomp``)
so that zero torque holds the arm still: without it the arm would sag onto its limits under gravity, and torque
plans would need to hold it up (the original arm had gravity off; see docs/mujoco_envs.md).

Observation (20) = qpos (7), qvel / 10 (7), finger xyz (3), target xyz (3), as in the original code; the finger is
Metaworld's ``tcp_center``, the midpoint of the two finger-pad sites. Reward = -10 * ||finger - target||_2.
"""

from __future__ import annotations

import functools
import importlib.util
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from envs.mujoco_inverse import FrameSkipInverseDynamics
from envs.torque_step import step_torques

TORQUE_LIMITS = np.array([80.0, 80.0, 40.0, 40.0, 9.0, 9.0, 9.0])
"""Peak joint torques of the real Sawyer (N m); action 1.0 is the full torque."""

RESET_QPOS = np.array([1.8893, -0.5758, -0.9767, 1.642, 0.9429, 1.0437, 2.2928])
"""Metaworld reach-v3's arm pose after reset (the all-zero pose violates joint 1's range [-3.8, -0.5])."""

FIXED_TARGET = np.array([-0.25, 0.8, 0.3])
"""The fixed-goal variant's target: 0.36 m from the start finger position (0.004, 0.601, 0.150), above the table."""

TARGET_LOW = np.array([-0.3, 0.45, 0.05])
TARGET_HIGH = np.array([0.3, 0.85, 0.35])
"""Box of variable-goal targets: in front of the arm, 5-35 cm above the table (all reachable; checked by IK)."""

GOAL_MODES = ("fixed", "variable", None)

INVERSE_FINGER_WEIGHT = 100.0
"""Default weight of the finger xyz (metres) against the joint dims (qpos rad, qvel / 10) in the ground-truth
inverse dynamics. A plan's finger dims can disagree with its joint dims (nothing but the learned energy ties them);
matching the joints only then moves the real finger away from where the plan puts it, and the EBM never reaches the
target (docs/agent.md). The original scored all 20 observation dims with equal weights."""

INVERSE_RESCUE_CEILING = 0.1
"""Default residual norm above which the inverse dynamics takes a wanted next state as out of reach and skips the
multi-start rescue (``envs.mujoco_inverse``). Real transitions that stall beside a joint limit stall below 0.03; a
plan's next state is off by 2-26, where the rescue removed a median 7 % of the squared residual at 25x the cost
(the retired probe sawyer_inverse_rescue, docs/notes/probes.md#probesawyer_inverse_rescue; docs/mujoco_envs.md)."""

FINGER_SENSORS = ("finger_right", "finger_left")
"""``framepos`` sensors of the two finger-pad sites (their mean is the finger); the inverse dynamics reads them."""


class SawyerReachEnv(gym.Env):
    """Torque-controlled 7-DoF Sawyer reaching for a target with its finger.

    :param goal: ``"fixed"`` (``FIXED_TARGET``), ``"variable"`` (a target drawn from the box per reset) or ``None``
        (exploration: no goal; the target is the finger itself, so the reward is 0 and nothing is a success).
    :param success_threshold: finger-target distance (m) below which a step counts as a success.
    :param reset_noise_scale: half-width (rad) of the uniform noise added to each joint of ``RESET_QPOS``.
    :param inverse_finger_weight: weight of the finger xyz against the joint dims in ``inverse_dynamics`` (0: match
        the joints only); see ``INVERSE_FINGER_WEIGHT``.
    :param inverse_rescue_ceiling: residual norm above which ``inverse_dynamics`` skips its multi-start rescue
        (``None``: rescue every stalled sample); see ``INVERSE_RESCUE_CEILING``.
    :param render_mode: ``None`` or ``"rgb_array"``.
    :param width: render width in pixels.
    :param height: render height in pixels.
    """

    # gymnasium annotates metadata as an instance attribute; it is class-level data.
    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 80}  # type: ignore[misc]

    frame_skip: int = 5
    """Physics steps (2.5 ms each) per env step, as in Metaworld."""

    def __init__(
        self,
        goal: str | None = "fixed",
        success_threshold: float = 0.05,
        reset_noise_scale: float = 0.01,
        inverse_finger_weight: float = INVERSE_FINGER_WEIGHT,
        inverse_rescue_ceiling: float | None = INVERSE_RESCUE_CEILING,
        render_mode: str | None = None,
        width: int = 256,
        height: int = 256,
    ) -> None:
        if goal not in GOAL_MODES:
            raise ValueError(f"goal must be one of {GOAL_MODES}, got {goal!r}.")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}.")
        if success_threshold <= 0:
            raise ValueError(f"success_threshold must be > 0 (metres), got {success_threshold}.")
        if reset_noise_scale < 0:
            raise ValueError(f"reset_noise_scale must be >= 0 (radians), got {reset_noise_scale}.")
        if not (np.isfinite(inverse_finger_weight) and inverse_finger_weight >= 0):
            raise ValueError(f"inverse_finger_weight must be finite and >= 0, got {inverse_finger_weight}.")
        if inverse_rescue_ceiling is not None and not inverse_rescue_ceiling > 0:
            raise ValueError(f"inverse_rescue_ceiling must be > 0 or None, got {inverse_rescue_ceiling}.")
        self.goal_mode = goal
        self.inverse_finger_weight = float(inverse_finger_weight)
        self.success_threshold = float(success_threshold)
        self.reset_noise_scale = float(reset_noise_scale)
        self.render_mode = render_mode
        self.width, self.height = int(width), int(height)

        self.model = sawyer_model()
        self.data = mujoco.MjData(self.model)
        self.dt = self.frame_skip * self.model.opt.timestep
        """Seconds per env step (0.0125)."""
        self.physics_steps = 0
        """Physics steps taken since construction."""
        self._finger_sites = [self.model.site("rightEndEffector").id, self.model.site("leftEndEffector").id]
        self._inverse = FrameSkipInverseDynamics(
            self.model,
            self.frame_skip,
            rescue_ceiling=inverse_rescue_ceiling,
            end_sensors=self.inverse_finger_weight > 0,
        )
        self._renderer: mujoco.Renderer | None = None
        self._target = FIXED_TARGET.copy()  # [3]
        self._exploration_qpos: np.ndarray | None = None

        self.goal_indices = np.array([14, 15, 16])
        self.target_indices = np.array([17, 18, 19])
        self.goal_period: float | None = None
        self.state_low: np.ndarray | None = None
        self.state_high: np.ndarray | None = None

        self.action_space = spaces.Box(-1.0, 1.0, shape=(7,), dtype=np.float32)
        self.observation_space = spaces.Dict(
            {
                "observation": spaces.Box(-np.inf, np.inf, shape=(20,), dtype=np.float64),
                "achieved_goal": spaces.Box(-np.inf, np.inf, shape=(3,), dtype=np.float64),
                "desired_goal": spaces.Box(-np.inf, np.inf, shape=(3,), dtype=np.float64),
            }
        )

    # ----------------------------------------------------------------------------------------------------- gym API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict[str, np.ndarray], dict]:
        """Reset the arm to ``RESET_QPOS`` (plus noise) at rest and place the target.

        :param seed: seeds ``self.np_random``.
        :param options: ``{"target": (x, y, z)}`` overrides the target for this episode (not in the no-goal variant).
        :return: observation dict and info.
        """
        super().reset(seed=seed)
        mujoco.mj_resetData(self.model, self.data)
        noise = self.np_random.uniform(-self.reset_noise_scale, self.reset_noise_scale, size=7)
        self.data.qpos[:] = RESET_QPOS + noise
        if options is not None and options.get("target") is not None:
            if self.goal_mode is None:
                raise ValueError("The no-goal SawyerReach variant takes no target; make it with goal='fixed'.")
            self._target = _validate_target(options["target"])
        elif self.goal_mode == "variable":
            self._target = self.np_random.uniform(TARGET_LOW, TARGET_HIGH)
        else:
            self._target = FIXED_TARGET.copy()
        # In the no-goal variant the marker is parked under the floor; the observed target is the finger.
        self.data.mocap_pos[0] = self._target if self.goal_mode is not None else (0.0, 0.0, -2.0)
        mujoco.mj_forward(self.model, self.data)
        self._exploration_qpos = None
        obs = self._get_obs()
        return obs, self._info(obs)

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict]:
        """Hold the joint torques ``action * TORQUE_LIMITS`` for 5 physics steps.

        :param action: [7] normalised torques; clipped to [-1, 1] (NaN/inf raise ValueError).
        :return: observation, reward, terminated (always False), truncated (False: TimeLimit truncates), info.
        """
        step_torques("SawyerReach", self.model, self.data, action, self.frame_skip)
        self.physics_steps += self.frame_skip
        obs = self._get_obs()
        info = self._info(obs)
        reward = float(self.compute_reward(obs["achieved_goal"], obs["desired_goal"], info))
        return obs, reward, False, False, info

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any = None) -> np.ndarray:
        """-10 times the Euclidean finger-target distance (vectorised over leading axes).

        :param achieved_goal: [..., 3] finger positions.
        :param desired_goal: [..., 3] targets.
        :param info: unused (GoalEnv signature).
        :return: [...] rewards.
        """
        return -10.0 * np.linalg.norm(np.asarray(achieved_goal) - np.asarray(desired_goal), axis=-1)

    def compute_terminated(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any = None) -> np.ndarray:
        """Never: reaching does not end the episode (the original arm ran its full horizon).

        :return: [...] False.
        """
        return np.zeros(np.shape(self.compute_reward(achieved_goal, desired_goal)), dtype=bool)

    def compute_truncated(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any = None) -> np.ndarray:
        """Never: the 1000-step limit comes from the registration's TimeLimit.

        :return: [...] False.
        """
        return self.compute_terminated(achieved_goal, desired_goal, info)

    def render(self) -> np.ndarray | None:
        """RGB frame [H, W, 3] uint8 of the arm, table and target from the front left (``render_mode="rgb_array"``)."""
        if self.render_mode != "rgb_array":
            return None
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.model, height=self.height, width=self.width)
        camera = mujoco.MjvCamera()
        camera.lookat[:] = (0.0, 0.55, 0.2)
        camera.distance, camera.azimuth, camera.elevation = 1.6, 45.0, -25.0
        self._renderer.update_scene(self.data, camera=camera)
        return self._renderer.render()

    def close(self) -> None:
        """Release the renderer."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # ------------------------------------------------------------------------------------------- agent helpers
    @property
    def target(self) -> np.ndarray:
        """The current target xyz [3] (the finger itself in the no-goal variant)."""
        return self._get_obs()["desired_goal"]

    @staticmethod
    def finger_position(states: np.ndarray) -> np.ndarray:
        """Finger xyz from observations.

        :param states: [..., 20] observations.
        :return: [..., 3] finger positions (``states[..., 14:17]``).
        """
        return np.asarray(states)[..., 14:17]

    def sample_exploration_action(self) -> np.ndarray:
        """A random-joint-target PD action for random datasets (uniform full-range torques pin the arm at its limits).

        Every step, with probability 1/25, a new joint target is drawn: ``RESET_QPOS`` + U(-0.8, 0.8) rad per joint,
        clipped 0.1 rad inside the joint range. The action is a PD pull toward it (``0.5 * gear``-scaled gains, about
        one second to settle) plus U(-0.1, 0.1) noise, clipped to [-1, 1]. Randomness comes from ``self.np_random``.

        :return: [7] action.
        """
        if self._exploration_qpos is None or self.np_random.uniform() < 1.0 / 25.0:
            low, high = self.model.jnt_range[:, 0] + 0.1, self.model.jnt_range[:, 1] - 0.1
            self._exploration_qpos = np.clip(RESET_QPOS + self.np_random.uniform(-0.8, 0.8, size=7), low, high)
        error = self._exploration_qpos - self.data.qpos
        action = 0.5 * error - 0.05 * self.data.qvel + self.np_random.uniform(-0.1, 0.1, size=7)
        return np.clip(action, -1.0, 1.0).astype(np.float32)

    def inverse_dynamics(self, states: np.ndarray, next_states: np.ndarray) -> np.ndarray:
        """Torques that carry each state to its next state over one env step (MuJoCo inverse dynamics, refined).

        Starts from ``mj_inverse`` with the mean acceleration of the step and refines it on the simulator (see
        ``envs.mujoco_inverse``); the fit uses the joint dims (qpos and qvel / 10, equally weighted) and the finger
        xyz weighted by ``inverse_finger_weight``; the target dims carry no dynamics. The finger follows from qpos
        for real states (any weight recovers their actions), but a plan's finger dims can disagree with its joints.

        :param states: [B, 20] (or [20]) observations.
        :param next_states: [B, 20] (or [20]) wanted next observations.
        :return: [B, 7] (or [7]) actions in [-1, 1].
        """
        states = np.asarray(states, dtype=np.float64)
        next_states = np.asarray(next_states, dtype=np.float64)
        if states.shape != next_states.shape:
            raise ValueError(f"states and next_states must have the same shape, got {states.shape} and {next_states.shape}.")
        if states.ndim not in (1, 2) or states.shape[-1] != 20:
            raise ValueError(f"Expected states of shape [B, 20] or [20], got {states.shape}.")
        if not (np.all(np.isfinite(states)) and np.all(np.isfinite(next_states))):
            raise ValueError("states and next_states must be finite (no NaN or inf).")
        single = states.ndim == 1
        actions, _ = self._solve_inverse(np.atleast_2d(states), np.atleast_2d(next_states))
        actions = actions.astype(self.action_space.dtype)
        return actions[0] if single else actions

    def _solve_inverse(self, states: np.ndarray, next_states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The solver's answer for checked [B, 20] float64 states: controls [B, 7] and squared residual norms [B]."""
        residual = (
            functools.partial(_joint_finger_residual, weight=self.inverse_finger_weight)
            if self.inverse_finger_weight > 0
            else _joint_residual
        )
        return self._inverse.solve(
            states[:, :7], 10.0 * states[:, 7:14], 10.0 * next_states[:, 7:14], next_states[:, :17], residual
        )

    # --------------------------------------------------------------------------------------------------- internals
    def _finger(self) -> np.ndarray:
        return 0.5 * (self.data.site_xpos[self._finger_sites[0]] + self.data.site_xpos[self._finger_sites[1]])

    def _get_obs(self) -> dict[str, np.ndarray]:
        finger = self._finger()
        target = self._target if self.goal_mode is not None else finger
        state = np.concatenate([self.data.qpos, self.data.qvel / 10.0, finger, target])  # [20]
        return {"observation": state, "achieved_goal": finger.copy(), "desired_goal": target.copy()}

    def _info(self, obs: dict[str, np.ndarray]) -> dict[str, Any]:
        distance = float(np.linalg.norm(obs["achieved_goal"] - obs["desired_goal"]))
        return {"is_success": self.goal_mode is not None and distance < self.success_threshold, "distance": distance}


def _joint_residual(qpos_end: np.ndarray, qvel_end: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Mismatch [B, M, 14] of rolled-out end states with the wanted joint states (targets [B, 1, 17]: qpos, qvel / 10,
    finger xyz)."""
    return np.concatenate([qpos_end - targets[..., :7], qvel_end / 10.0 - targets[..., 7:14]], axis=-1)


def _joint_finger_residual(
    qpos_end: np.ndarray, qvel_end: np.ndarray, targets: np.ndarray, sensors_end: np.ndarray, *, weight: float
) -> np.ndarray:
    """Mismatch [B, M, 17] of rolled-out end states with the wanted joint and finger states [B, 1, 17].

    ``sensors_end`` [B, M, 6] are the ``FINGER_SENSORS`` readings (right xyz, left xyz) at the end states; the finger
    mismatch is multiplied by ``weight``.
    """
    finger = 0.5 * (sensors_end[..., :3] + sensors_end[..., 3:6])  # [B, M, 3]
    return np.concatenate([_joint_residual(qpos_end, qvel_end, targets), weight * (finger - targets[..., 14:17])], axis=-1)


def _validate_target(target: Any) -> np.ndarray:
    target_array = np.asarray(target, dtype=np.float64)
    if target_array.shape != (3,) or not np.all(np.isfinite(target_array)):
        raise ValueError(f"A Sawyer target must be 3 finite coordinates (x, y, z) in metres, got {target!r}.")
    return target_array


def _metaworld_asset(relative_path: str) -> Path:
    # find_spec locates the installed package without importing it (importing metaworld registers all of its
    # envs: half a second and a page of log output).
    package = importlib.util.find_spec("metaworld")
    if package is None or package.origin is None:
        raise ModuleNotFoundError("SawyerReach builds its arm from Metaworld's assets: `pip install metaworld==3.1.1`.")
    return Path(package.origin).parent / "assets" / relative_path


@functools.cache
def sawyer_model() -> mujoco.MjModel:
    """Build the torque-driven Sawyer from Metaworld's reach scene (once per process; envs share it read-only).

    :return: the compiled model: nq = nv = nu = 7, one mocap body (the target marker).
    """
    spec = mujoco.MjSpec.from_file(str(_metaworld_asset("sawyer_xyz/sawyer_reach_v3.xml")))
    for equality in list(spec.equalities):  # the mocap -> hand weld
        equality.delete()
    for actuator in list(spec.actuators):  # the gripper's position servos
        actuator.delete()
    for joint_name in ("r_close", "l_close"):  # gripper slides: the fingers become rigid
        spec.joint(joint_name).delete()
    for body_name in ("mocap", "obj"):
        spec.detach_body(spec.body(body_name))
    spec.site("goal").delete()

    for index, limit in enumerate(TORQUE_LIMITS):
        motor = spec.add_actuator()
        motor.name = f"torque_j{index}"
        motor.target = f"right_j{index}"
        motor.trntype = mujoco.mjtTrn.mjTRN_JOINT
        motor.gear[0] = limit
        motor.ctrllimited = True
        motor.ctrlrange = [-1.0, 1.0]
    # Gravity compensation must be set before compiling (it is a body property baked into the model).
    for body in spec.bodies:
        body.gravcomp = 1.0

    for name, site in zip(FINGER_SENSORS, ("rightEndEffector", "leftEndEffector"), strict=True):
        spec.add_sensor(name=name, type=mujoco.mjtSensor.mjSENS_FRAMEPOS, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=site)
    target = spec.worldbody.add_body(name="target", mocap=True, pos=list(FIXED_TARGET))
    target.add_geom(
        name="target",
        type=mujoco.mjtGeom.mjGEOM_SPHERE,
        size=[0.02, 0.0, 0.0],
        contype=0,
        conaffinity=0,
        rgba=[0.9, 0.1, 0.1, 1.0],
    )
    model = spec.compile()
    if (model.nq, model.nv, model.nu) != (7, 7, 7):  # a Metaworld asset change would break the 20-D observation
        raise RuntimeError(f"Unexpected Sawyer model sizes nq={model.nq}, nv={model.nv}, nu={model.nu}; expected 7, 7, 7.")
    return model
