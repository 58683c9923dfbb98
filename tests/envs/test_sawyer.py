"""SawyerReach: the torque-driven Sawyer from Metaworld's assets, its variants, gravity compensation, inverse dynamics."""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from scipy.optimize import least_squares
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import envs  # noqa: F401  (registers the ebm/ ids)
from envs.mujoco_inverse import FrameSkipInverseDynamics
from envs.sawyer import (
    FIXED_TARGET,
    INVERSE_FINGER_WEIGHT,
    RESET_QPOS,
    TARGET_HIGH,
    TARGET_LOW,
    TORQUE_LIMITS,
    SawyerReachEnv,
    sawyer_model,
)

GOAL_MODES = ["fixed", "variable", None]


def _finger_at(qpos: np.ndarray) -> np.ndarray:
    model = sawyer_model()
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    return 0.5 * (data.site("rightEndEffector").xpos + data.site("leftEndEffector").xpos)


@pytest.mark.parametrize("goal", GOAL_MODES)
def test_gymnasium_and_sb3_env_checkers_pass(goal):
    env = gym.make("ebm/SawyerReach-v0", goal=goal)
    gym_check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=True)
    assert env.spec.max_episode_steps == 1000
    env.close()


def test_model_is_the_torque_driven_metaworld_arm():
    model = sawyer_model()
    assert (model.nq, model.nv, model.nu, model.nmocap) == (7, 7, 7, 1)
    assert model.neq == 0  # the mocap weld is gone
    assert [model.joint(i).name for i in range(7)] == [f"right_j{i}" for i in range(7)]
    np.testing.assert_allclose(model.actuator_gear[:, 0], TORQUE_LIMITS)
    np.testing.assert_allclose(model.actuator_ctrlrange, np.tile([-1.0, 1.0], (7, 1)))
    assert model.opt.timestep == pytest.approx(0.0025)
    movable = np.flatnonzero(model.body_mocapid < 0)  # every body but the target marker
    assert np.all(model.body_gravcomp[movable] == 1.0)
    env = SawyerReachEnv()
    assert env.dt == pytest.approx(0.0125) and env.frame_skip == 5


def test_observation_layout_and_reward():
    env = SawyerReachEnv(goal="fixed", reset_noise_scale=0.0)
    obs, info = env.reset(seed=0)
    state = obs["observation"]
    np.testing.assert_allclose(state[:7], RESET_QPOS)
    np.testing.assert_allclose(state[7:14], 0.0)
    np.testing.assert_allclose(state[14:17], [0.0043, 0.6014, 0.1502], atol=2e-3)  # Metaworld's measured TCP
    np.testing.assert_array_equal(state[17:20], FIXED_TARGET)
    assert 0.3 < info["distance"] < 0.5
    for _ in range(5):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        finger, target = obs["observation"][14:17], obs["observation"][17:20]
        np.testing.assert_array_equal(obs["achieved_goal"], finger)
        np.testing.assert_array_equal(obs["desired_goal"], target)
        assert reward == pytest.approx(-10.0 * np.linalg.norm(finger - target))
        assert not terminated and not truncated
        assert env.data.qvel[0] / 10.0 == pytest.approx(obs["observation"][7])
    np.testing.assert_array_equal(SawyerReachEnv.finger_position(obs["observation"][None]), finger[None])
    assert env.physics_steps == 25


def test_step_rewards_equal_batched_compute_reward_and_success_flags():
    env = SawyerReachEnv(goal="variable")
    obs, _ = env.reset(seed=1)
    achieved, desired, rewards = [], [], []
    for _ in range(10):
        obs, reward, _, _, info = env.step(env.sample_exploration_action())
        achieved.append(obs["achieved_goal"])
        desired.append(obs["desired_goal"])
        rewards.append(reward)
        assert info["is_success"] == (info["distance"] < 0.05)
    np.testing.assert_allclose(env.compute_reward(np.array(achieved), np.array(desired), None), rewards, atol=1e-12)
    assert not np.any(env.compute_terminated(np.array(achieved), np.array(desired), None))
    # A finger on the target is a success.
    start_finger = env.reset(seed=0)[0]["achieved_goal"]
    _, info = env.reset(seed=0, options={"target": start_finger + 0.01})
    assert info["is_success"] and env.step(np.zeros(7))[4]["is_success"]


def test_zero_torque_holds_the_arm_for_two_seconds():
    env = SawyerReachEnv(reset_noise_scale=0.0)
    obs, _ = env.reset(seed=0)
    start = obs["achieved_goal"]
    for _ in range(int(2.0 / env.dt)):
        obs, *_ = env.step(np.zeros(7))
    assert np.linalg.norm(obs["achieved_goal"] - start) < 0.01
    np.testing.assert_allclose(obs["observation"][7:14], 0.0, atol=1e-6)


def test_targets_are_in_the_box_and_reachable():
    env = SawyerReachEnv(goal="variable")
    targets = np.array([env.reset(seed=seed)[0]["desired_goal"] for seed in range(20)])
    assert np.all((targets >= TARGET_LOW) & (targets <= TARGET_HIGH))
    assert np.unique(targets, axis=0).shape[0] == 20

    # Inverse kinematics inside the joint ranges reaches the fixed target and every corner of the box.
    model = sawyer_model()
    low, high = model.jnt_range[:, 0] + 0.05, model.jnt_range[:, 1] - 0.05
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)])
    for point in [FIXED_TARGET, *(TARGET_LOW + corners * (TARGET_HIGH - TARGET_LOW))]:
        solution = least_squares(lambda q, p=point: _finger_at(q) - p, RESET_QPOS, bounds=(low, high))
        assert np.linalg.norm(_finger_at(solution.x) - point) < 1e-3, point


def test_no_goal_variant_has_zero_reward_and_no_success():
    env = SawyerReachEnv(goal=None)
    obs, info = env.reset(seed=0)
    assert not info["is_success"]
    for _ in range(5):
        obs, reward, _, _, info = env.step(env.sample_exploration_action())
        np.testing.assert_array_equal(obs["desired_goal"], obs["achieved_goal"])
        np.testing.assert_array_equal(obs["observation"][17:20], obs["observation"][14:17])
        assert reward == 0.0 and not info["is_success"]
    with pytest.raises(ValueError, match="no-goal"):
        env.reset(options={"target": (0.0, 0.6, 0.2)})


def test_seeding_reproduces_trajectories():
    def rollout(seed: int) -> np.ndarray:
        env = SawyerReachEnv(goal="variable")
        obs, _ = env.reset(seed=seed)
        states = [obs["observation"]]
        for _ in range(10):
            obs, *_ = env.step(env.sample_exploration_action())
            states.append(obs["observation"])
        return np.concatenate(states)

    np.testing.assert_array_equal(rollout(5), rollout(5))
    assert not np.allclose(rollout(5), rollout(6))


def test_bad_input_raises_clear_errors():
    with pytest.raises(ValueError, match="goal must be one of"):
        SawyerReachEnv(goal="moving")
    with pytest.raises(ValueError, match="success_threshold"):
        SawyerReachEnv(success_threshold=0.0)
    for weight in (-1.0, float("nan")):
        with pytest.raises(ValueError, match="inverse_finger_weight"):
            SawyerReachEnv(inverse_finger_weight=weight)
    with pytest.raises(ValueError, match="inverse_rescue_ceiling"):
        SawyerReachEnv(inverse_rescue_ceiling=0.0)
    with pytest.raises(ValueError, match="needs a model with sensors"):
        FrameSkipInverseDynamics(mujoco.MjModel.from_xml_string(_ONE_MOTOR), 2, end_sensors=True)
    env = SawyerReachEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="3 finite"):
        env.reset(options={"target": (0.0, 0.6)})
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(6))
    with pytest.raises(ValueError, match=r"\[B, 20\]"):
        env.inverse_dynamics(np.zeros((2, 14)), np.zeros((2, 14)))
    with pytest.raises(ValueError, match="finite"):
        env.inverse_dynamics(np.full((2, 20), np.nan), np.zeros((2, 20)))
    assert env.inverse_dynamics(np.zeros((0, 20)), np.zeros((0, 20))).shape == (0, 7)


_ONE_MOTOR = """<mujoco><worldbody><body><joint name='j' type='hinge'/><geom size='0.1' mass='1'/></body></worldbody>
<actuator><motor joint='j'/></actuator></mujoco>"""


@pytest.mark.parametrize("finger_weight", [0.0, INVERSE_FINGER_WEIGHT])
@pytest.mark.parametrize("policy", ["exploration", "small_uniform"])
def test_inverse_dynamics_recovers_actions_and_reproduces_next_states(policy, finger_weight):
    env = SawyerReachEnv(goal="variable", inverse_finger_weight=finger_weight)
    rng = np.random.default_rng(0)
    states, next_states, actions = [], [], []
    for episode in range(2):
        obs, _ = env.reset(seed=episode)
        for _ in range(60):
            action = env.sample_exploration_action() if policy == "exploration" else rng.uniform(-0.3, 0.3, 7)
            states.append(obs["observation"])
            obs, *_ = env.step(action)
            next_states.append(obs["observation"])
            actions.append(action)
    states, next_states, actions = np.array(states), np.array(next_states), np.array(actions)
    recovered = env.inverse_dynamics(states, next_states)
    assert recovered.shape == actions.shape and recovered.dtype == np.float32
    errors = np.abs(recovered - actions).max(axis=1)
    assert errors.max() < 0.1
    assert np.quantile(errors, 0.95) < 1e-4

    # Round trip: stepping from s with the recovered action lands on s'.
    env.reset(seed=0)
    for index in range(0, len(states), 30):
        env.data.qpos[:] = states[index, :7]
        env.data.qvel[:] = 10.0 * states[index, 7:14]
        obs, *_ = env.step(recovered[index])
        np.testing.assert_allclose(obs["observation"][:14], next_states[index, :14], atol=1e-6)
    assert env.inverse_dynamics(states[0], next_states[0]).shape == (7,)


def test_finger_sensors_read_the_finger():
    env = SawyerReachEnv()
    obs, _ = env.reset(seed=0)
    for _ in range(20):
        obs, *_ = env.step(env.sample_exploration_action())
    sensors = env.data.sensordata  # [6]: right pad xyz, left pad xyz
    np.testing.assert_allclose(0.5 * (sensors[:3] + sensors[3:6]), obs["achieved_goal"], atol=1e-12)


def test_finger_weight_follows_a_plan_whose_finger_dims_disagree_with_its_joints():
    """A planned step that moves only the finger dims (joints held): the weighted fit moves the real finger that way."""
    moved = {}
    for weight in (0.0, INVERSE_FINGER_WEIGHT):
        env = SawyerReachEnv(inverse_finger_weight=weight)
        obs, _ = env.reset(seed=0)
        state = obs["observation"]
        wanted = state.copy()
        wanted[14] += 0.01  # the finger 1 cm along x, the joints where they are
        obs, *_ = env.step(env.inverse_dynamics(state, wanted))
        moved[weight] = obs["achieved_goal"][0] - state[14]
    assert abs(moved[0.0]) < 1e-3  # joints only: hold still
    assert moved[INVERSE_FINGER_WEIGHT] > 2e-3  # the finger goes where the plan puts it


def test_a_wanted_state_far_out_of_reach_gets_no_rescue(monkeypatch):
    """Above the ceiling Gauss-Newton's answer is kept; without a ceiling the same sample gets the multi-start."""
    rescued = []
    original = FrameSkipInverseDynamics._rescue

    def counting(self, start, *args):
        rescued.append(len(start))
        return original(self, start, *args)

    monkeypatch.setattr(FrameSkipInverseDynamics, "_rescue", counting)
    actions = {}
    for ceiling in (None, 0.1):
        env = SawyerReachEnv(inverse_rescue_ceiling=ceiling)
        obs, _ = env.reset(seed=0)
        wanted = obs["observation"].copy()
        wanted[:7] += 2.0  # every joint 2 rad further in one 12.5 ms step: no torque does that
        actions[ceiling] = env.inverse_dynamics(obs["observation"], wanted)
    assert rescued == [1]  # only the solver without a ceiling tried
    assert np.all(np.abs(actions[0.1]) <= 1.0)


def test_exploration_actions_stay_off_the_joint_limits():
    env = SawyerReachEnv(goal=None)
    env.reset(seed=0)
    low, high = env.model.jnt_range[:, 0], env.model.jnt_range[:, 1]
    near_limit, fingers = 0, []
    for _ in range(400):
        action = env.sample_exploration_action()
        assert action in env.action_space
        obs, *_ = env.step(action)
        qpos = obs["observation"][:7]
        near_limit += bool(np.any(np.minimum(qpos - low, high - qpos) < 0.05))
        fingers.append(obs["achieved_goal"])
    assert near_limit < 20
    assert np.all(np.ptp(np.array(fingers), axis=0) > 0.1)  # the finger does travel


@pytest.mark.render
def test_render_rgb_array(gl_backend):
    env = SawyerReachEnv(render_mode="rgb_array", width=64, height=48)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (48, 64, 3) and frame.dtype == np.uint8
    assert frame.std() > 0
    env.close()
    checked = gym.make("ebm/SawyerReach-v0", render_mode="rgb_array", width=32, height=32)
    gym_check_env(checked.unwrapped)
    checked.close()
