"""Reacher: the paper's normalised joint state over Reacher-v4's model, its wrapped reward and its inverse dynamics."""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import envs  # noqa: F401  (registers the ebm/ ids)
from envs.reacher import (
    DEFAULT_GOAL,
    ReacherEnv,
    denormalize_angle,
    fingertip_position,
    normalize_angle,
    wrapped_l1_distance,
)


def _random_transitions(env: ReacherEnv, episodes: int, steps: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    states, next_states, actions = [], [], []
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed + episode)
        for _ in range(steps):
            action = rng.uniform(-1.0, 1.0, size=2)
            states.append(obs["observation"])
            obs, *_ = env.step(action)
            next_states.append(obs["observation"])
            actions.append(action)
    return np.array(states), np.array(next_states), np.array(actions)


def test_gymnasium_and_sb3_env_checkers_pass():
    env = gym.make("ebm/Reacher-v0")
    gym_check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=True)
    assert env.spec.max_episode_steps == 50
    env.close()


def test_normalize_angle_matches_the_paper_formula():
    angles = np.array([0.0, np.pi, -np.pi / 2, np.pi / 2, 2 * np.pi + 0.3, -1e-18])
    expected = np.array([-1.0, 0.0, 0.5, -0.5, (0.3 - np.pi) / np.pi, -1.0])
    np.testing.assert_allclose(normalize_angle(angles), expected, atol=1e-12)
    assert np.all(normalize_angle(np.linspace(-10, 10, 1001)) < 1.0)
    # Round trip through MuJoCo's [-pi, pi) range.
    normalized = np.linspace(-1.0, 0.999, 50)
    radians = denormalize_angle(normalized)
    assert np.all((radians >= -np.pi) & (radians < np.pi))
    np.testing.assert_allclose(normalize_angle(radians), normalized, atol=1e-12)


def test_wrapped_l1_distance_wraps_across_the_seam():
    assert wrapped_l1_distance(np.array([0.95, 0.0]), np.array([-0.95, 0.0])) == pytest.approx(0.1)
    assert wrapped_l1_distance(np.array([0.2, -0.3]), np.array([0.5, 0.1])) == pytest.approx(0.7)
    assert wrapped_l1_distance(np.array([-1.0, 0.0]), np.array([1.0, 0.0])) == pytest.approx(0.0)
    batch = wrapped_l1_distance(np.zeros((5, 3, 2)), np.full((5, 3, 2), 0.25))
    assert batch.shape == (5, 3)
    np.testing.assert_allclose(batch, 0.5)


def test_step_reward_equals_batched_compute_reward_and_goal_is_fixed():
    env = ReacherEnv()
    obs, _ = env.reset(seed=3)
    np.testing.assert_array_equal(obs["desired_goal"], DEFAULT_GOAL)
    achieved, desired, rewards = [], [], []
    for _ in range(15):
        obs, reward, _, truncated, info = env.step(env.action_space.sample())
        assert not truncated and info["is_success"] == (info["distance"] < 0.01)
        achieved.append(obs["achieved_goal"])
        desired.append(obs["desired_goal"])
        rewards.append(reward)
        assert reward == pytest.approx(-info["distance"])
    np.testing.assert_allclose(env.compute_reward(np.array(achieved), np.array(desired), None), rewards, atol=1e-12)


def test_success_terminates_only_when_asked():
    goal = np.array([0.7, 0.5])
    near, far = goal + 0.004, goal + 0.1
    assert ReacherEnv().compute_terminated(near, goal, None)
    assert not ReacherEnv().compute_terminated(far, goal, None)
    assert not ReacherEnv(terminate_on_success=False).compute_terminated(near, goal, None)
    flags = ReacherEnv().compute_terminated(np.stack([near, far]), np.stack([goal, goal]), None)
    np.testing.assert_array_equal(flags, [True, False])


def test_seeding_reproduces_trajectories():
    def rollout(seed: int) -> np.ndarray:
        env = ReacherEnv(goal=None)
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(0)
        states = [obs["observation"], obs["desired_goal"]]
        for _ in range(10):
            obs, *_ = env.step(rng.uniform(-1, 1, 2))
            states.append(obs["observation"])
        return np.concatenate(states)

    np.testing.assert_array_equal(rollout(7), rollout(7))
    assert not np.allclose(rollout(7), rollout(8))


def test_random_goals_are_valid_and_the_target_marks_the_goal():
    env = ReacherEnv(goal=None)
    goals = []
    for seed in range(20):
        obs, _ = env.reset(seed=seed)
        goals.append(obs["desired_goal"])
        # The elbow cannot pass its 3 rad limit, so random goals stay inside it.
        assert abs(denormalize_angle(obs["desired_goal"][1])) <= 3.0
        # The red target ball sits where the fingertip would be at the goal angles.
        np.testing.assert_allclose(env.data.body("target").xpos[:2], fingertip_position(obs["desired_goal"]), atol=1e-9)
    assert np.unique(np.round(goals, 6), axis=0).shape[0] == 20

    # Forward kinematics agrees with MuJoCo's fingertip body.
    env.data.qpos[:2] = denormalize_angle(np.array([0.3, -0.4]))
    mujoco.mj_forward(env.model, env.data)
    np.testing.assert_allclose(env.data.body("fingertip").xpos[:2], fingertip_position(np.array([0.3, -0.4])), atol=1e-9)


def test_bad_input_raises_clear_errors():
    with pytest.raises(ValueError, match="lie in"):
        ReacherEnv(goal=(2.0, 0.0))
    with pytest.raises(ValueError, match="2 finite"):
        ReacherEnv(goal=(0.1, 0.2, 0.3))
    with pytest.raises(ValueError, match="render_mode"):
        ReacherEnv(render_mode="human")
    env = ReacherEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3))
    with pytest.raises(ValueError, match="same shape"):
        env.inverse_dynamics(np.zeros((2, 4)), np.zeros((3, 4)))
    with pytest.raises(ValueError, match=r"\[B, 4\]"):
        env.inverse_dynamics(np.zeros((2, 5)), np.zeros((2, 5)))
    with pytest.raises(ValueError, match="finite"):
        env.inverse_dynamics(np.full((2, 4), np.nan), np.zeros((2, 4)))
    assert env.inverse_dynamics(np.zeros((0, 4)), np.zeros((0, 4))).shape == (0, 2)


@pytest.mark.parametrize("angle_weight", [1.0, 30.0])
def test_inverse_dynamics_recovers_random_actions_and_reproduces_next_states(angle_weight):
    env = ReacherEnv(goal=None, inverse_angle_weight=angle_weight)
    states, next_states, actions = _random_transitions(env, episodes=6, steps=50, seed=100)
    recovered = env.inverse_dynamics(states, next_states)
    assert recovered.shape == actions.shape and recovered.dtype == np.float32
    errors = np.abs(recovered - actions).max(axis=1)
    assert errors.max() < 0.1
    assert np.quantile(errors, 0.95) < 1e-4

    # Round trip: stepping the simulator from s with the recovered action lands on s'.
    env.reset(seed=0)
    for index in range(0, len(states), 25):
        env.data.qpos[:2] = denormalize_angle(states[index, :2])
        env.data.qvel[:2] = 10.0 * states[index, 2:]
        obs, *_ = env.step(recovered[index])
        np.testing.assert_allclose(obs["observation"], next_states[index], atol=1e-5)

    # A single pair gives a single action.
    assert env.inverse_dynamics(states[0], next_states[0]).shape == (2,)


def test_inverse_dynamics_clips_unreachable_targets_to_the_action_bounds():
    env = ReacherEnv()
    obs, _ = env.reset(seed=0)
    state = obs["observation"]
    far = state + np.array([0.0, 0.0, 5.0, -5.0])  # far more velocity change than full torque gives in 20 ms
    action = env.inverse_dynamics(state, far)
    np.testing.assert_allclose(action, [1.0, -1.0])


def test_the_angle_weight_decides_how_a_plan_that_jumps_its_angles_is_followed():
    """One step of full torque moves an angle by ~0.013 and a velocity / 10 by ~0.4: a wanted angle jump without the
    velocity to match is fitted on the velocity dims at weight 1 (almost no torque), on the angles at weight 30."""
    jump = np.array([0.3, -0.3, 0.0, 0.0])
    actions = {}
    for weight in (1.0, 30.0):
        env = ReacherEnv(inverse_angle_weight=weight)
        state = env.reset(seed=0)[0]["observation"]
        actions[weight] = env.inverse_dynamics(state, state + jump)
    assert np.abs(actions[1.0]).max() < 0.05
    np.testing.assert_allclose(actions[30.0], [1.0, -1.0])
    for weight in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="inverse_angle_weight"):
            ReacherEnv(inverse_angle_weight=weight)


def test_exploration_action_is_uniform_in_the_action_space():
    env = ReacherEnv()
    env.reset(seed=0)
    samples = np.array([env.sample_exploration_action() for _ in range(500)])
    assert all(sample in env.action_space for sample in samples)
    assert samples.min() < -0.9 and samples.max() > 0.9


@pytest.mark.render
def test_render_rgb_array(gl_backend):
    env = ReacherEnv(render_mode="rgb_array", width=64, height=48)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (48, 64, 3) and frame.dtype == np.uint8
    assert frame.std() > 0  # not a blank image
    env.close()
    assert ReacherEnv().render() is None
    checked = gym.make("ebm/Reacher-v0", render_mode="rgb_array", width=32, height=32)
    gym_check_env(checked.unwrapped)
    checked.close()


def test_bench_reports_reacher_throughput():
    from benchmarks.envs import bench_env, format_table

    result = bench_env("ebm/Reacher-v0", steps=60, inverse_batch=8)
    assert result.env_steps_per_s > 0 and result.inverse_per_s > 0
    assert result.physics_steps_per_s == pytest.approx(2 * result.env_steps_per_s, rel=0.05)  # frame_skip 2
    assert "ebm/Reacher-v0" in format_table([result])
    with pytest.raises(ValueError, match="steps"):
        bench_env("ebm/Reacher-v0", steps=0)
