"""Inverse dynamics: ground-truth pass-through, the learned MLP and recursive least squares."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from ebm_agent.inverse_dynamics import (
    GroundTruthInverseDynamics,
    InverseDynamics,
    MLPInverseDynamics,
    RLSInverseDynamics,
    make_inverse_dynamics,
)

LOW, HIGH = -np.ones(2, dtype=np.float32), np.ones(2, dtype=np.float32)


def _particle_batch(rng: np.random.Generator, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Particle-like data: s' = clip(s + a / 20) with a ~ U(-1, 1)^2."""
    states = rng.uniform(-1, 1, (size, 2)).astype(np.float32)
    actions = rng.uniform(-1, 1, (size, 2)).astype(np.float32)
    return states, np.clip(states + actions / 20, -1, 1), actions


def test_ground_truth_passes_through_and_clips() -> None:
    model = GroundTruthInverseDynamics(lambda s, s2: 20 * (s2 - s), LOW, HIGH)
    states = np.zeros((3, 2))
    next_states = np.array([[0.01, -0.02], [0.2, 0.0], [-0.1, 0.04]])
    np.testing.assert_allclose(model(states, next_states), [[0.2, -0.4], [1.0, 0.0], [-1.0, 0.8]], rtol=1e-6)
    assert model.update(states, next_states, np.zeros((3, 2))) == {}
    assert model.state_dict() == {}
    assert isinstance(model, InverseDynamics)


def test_ground_truth_rejects_unbatched_fn_output() -> None:
    model = GroundTruthInverseDynamics(lambda s, s2: np.zeros(2), LOW, HIGH)
    with pytest.raises(ValueError, match="batched"):
        model(np.zeros((3, 2)), np.zeros((3, 2)))


def test_mlp_learns_the_particle_inverse_map() -> None:
    rng = np.random.default_rng(0)
    model = MLPInverseDynamics(2, 2, LOW, HIGH, seed=0)
    assert isinstance(model, InverseDynamics)
    assert sum(p.numel() for p in model.module.parameters()) == 4 * 32 + 32 + 2 * (32 * 32 + 32) + 32 * 2
    first = model.update(*_particle_batch(rng, 256))["id_loss"]
    for _ in range(400):
        stats = model.update(*_particle_batch(rng, 256))
    states, next_states, _ = _particle_batch(rng, 2000)
    predicted = model(states, next_states)
    expected = np.clip(20 * (next_states - states), -1, 1)  # the exact inverse (clipping at the walls included)
    mse = float(np.mean((predicted - expected) ** 2))
    assert mse < 0.01, mse
    assert stats["id_loss"] < first / 10
    assert predicted.dtype == np.float32 and np.all(np.abs(predicted) <= 1.0)


def test_mlp_clips_outputs_seeds_init_and_round_trips(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    a = MLPInverseDynamics(2, 2, LOW * 0.1, HIGH * 0.1, seed=3)
    b = MLPInverseDynamics(2, 2, LOW * 0.1, HIGH * 0.1, seed=3)
    states, next_states, actions = _particle_batch(rng, 64)
    np.testing.assert_array_equal(a(states, next_states), b(states, next_states))
    big = a(states * 50, next_states * 80)  # far outside the data: raw outputs exceed 0.1
    assert np.all(np.abs(big) <= 0.1 + 1e-7) and np.any(np.isclose(np.abs(big), 0.1))
    for _ in range(5):
        a.update(states, next_states, actions)
    path = tmp_path / "id.pt"
    torch.save(a.state_dict(), path)
    c = MLPInverseDynamics(2, 2, LOW * 0.1, HIGH * 0.1, seed=4)
    c.load_state_dict(torch.load(path))
    np.testing.assert_array_equal(c(states, next_states), a(states, next_states))
    # The optimiser state came along: one more identical step stays identical.
    a.update(states, next_states, actions)
    c.update(states, next_states, actions)
    np.testing.assert_allclose(c(states, next_states), a(states, next_states), atol=1e-6)


def test_mlp_masked_dims_are_ignored() -> None:
    model = MLPInverseDynamics(3, 2, LOW, HIGH, seed=0, masked_dims=(-1,))
    states = np.zeros((4, 3), dtype=np.float32)
    next_states = np.full((4, 3), 0.02, dtype=np.float32)
    moved = next_states.copy()
    moved[:, 2] = 5.0
    np.testing.assert_array_equal(model(states, next_states), model(states, moved))


def _linear_system(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    state_matrix = np.eye(3) + 0.1 * rng.standard_normal((3, 3))
    action_matrix = rng.standard_normal((3, 2))
    offset = 0.05 * rng.standard_normal(3)
    return state_matrix, action_matrix, offset


def _step(system: tuple[np.ndarray, ...], states: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """s' = A s + B a + c on dims 0..2; dim 3 is a target that never moves."""
    state_matrix, action_matrix, offset = system
    next_states = states.copy()
    next_states[:, :3] = states[:, :3] @ state_matrix.T + actions @ action_matrix.T + offset
    return next_states


def test_rls_recovers_a_linear_systems_actions() -> None:
    rng = np.random.default_rng(0)
    system = _linear_system(0)
    model = RLSInverseDynamics(4, 2, LOW, HIGH, ridge=0.0, state_dims=(0, 1, 2))
    assert isinstance(model, InverseDynamics)
    for _ in range(10):
        states = rng.uniform(-1, 1, (16, 4))
        actions = rng.uniform(-1, 1, (16, 2))
        model.update(states, _step(system, states, actions), actions)
    states = rng.uniform(-1, 1, (100, 4))
    actions = rng.uniform(-0.9, 0.9, (100, 2))
    recovered = model(states, _step(system, states, actions))
    assert np.max(np.abs(recovered - actions)) < 1e-3
    np.testing.assert_allclose(model.weights[:, 3:5], system[1], atol=1e-4)


def test_rls_default_ridge_is_accurate_on_a_strongly_actuated_system() -> None:
    rng = np.random.default_rng(1)
    state_matrix, _, offset = _linear_system(1)
    system = (state_matrix, 60.0 * np.array([[1.0, 0.2], [0.1, 1.0], [0.3, -0.4]]), offset)
    model = RLSInverseDynamics(4, 2, LOW, HIGH, state_dims=(0, 1, 2))  # ridge 0.3, as the original
    for _ in range(10):
        states = rng.uniform(-1, 1, (16, 4))
        actions = rng.uniform(-1, 1, (16, 2))
        model.update(states, _step(system, states, actions), actions)
    states = rng.uniform(-1, 1, (50, 4))
    actions = rng.uniform(-0.9, 0.9, (50, 2))
    assert np.max(np.abs(model(states, _step(system, states, actions)) - actions)) < 1e-3


def test_rls_warms_up_with_seeded_random_actions_then_solves() -> None:
    # A fresh fit has W_a = 0 and would answer 0 for everything, so an agent acting on it would never move.
    model = RLSInverseDynamics(4, 2, LOW * 0.5, HIGH * 0.5, state_dims=(0, 1, 2), seed=7)
    assert model.warmup == 10 * (3 + 2 + 1)
    states, next_states = np.zeros((40, 4)), np.ones((40, 4))
    explored = model(states, next_states)
    assert explored.shape == (40, 2) and np.all(np.abs(explored) <= 0.5)
    assert explored.std(axis=0).min() > 0.1  # every action direction is excited
    twin = RLSInverseDynamics(4, 2, LOW * 0.5, HIGH * 0.5, state_dims=(0, 1, 2), seed=7)
    np.testing.assert_array_equal(twin(states, next_states), explored)
    # The warm-up ends once `warmup` transitions are folded in: the solve takes over.
    rng = np.random.default_rng(4)
    system = _linear_system(4)
    for _ in range(4):
        states = rng.uniform(-1, 1, (16, 4))
        actions = rng.uniform(-0.5, 0.5, (16, 2))
        model.update(states, _step(system, states, actions), actions)
    assert model.num_updates >= model.warmup
    actions = rng.uniform(-0.4, 0.4, (20, 2))
    states = rng.uniform(-1, 1, (20, 4))
    np.testing.assert_allclose(model(states, _step(system, states, actions)), actions, atol=0.05)
    with pytest.raises(ValueError, match="warmup"):
        RLSInverseDynamics(4, 2, LOW, HIGH, warmup=-1)


def test_rls_warmup_generator_survives_the_state_dict() -> None:
    model = RLSInverseDynamics(2, 2, LOW, HIGH, seed=3)
    model(np.zeros((5, 2)), np.ones((5, 2)))  # advance the generator
    twin = RLSInverseDynamics(2, 2, LOW, HIGH, seed=99)
    twin.load_state_dict(model.state_dict())
    np.testing.assert_array_equal(twin(np.zeros((5, 2)), np.ones((5, 2))), model(np.zeros((5, 2)), np.ones((5, 2))))


def test_rls_ridge_pulls_towards_the_prior_action() -> None:
    model = RLSInverseDynamics(2, 2, LOW, HIGH, ridge=0.3, warmup=0)  # untrained: W = 0, so the prior decides
    prior = np.array([[0.5, -0.25]])
    np.testing.assert_allclose(model(np.zeros((1, 2)), np.ones((1, 2)), prior_actions=prior), prior, atol=1e-6)
    np.testing.assert_allclose(model(np.zeros((1, 2)), np.ones((1, 2))), np.zeros((1, 2)), atol=1e-6)


def test_rls_block_update_equals_sequential_updates_with_forgetting() -> None:
    rng = np.random.default_rng(2)
    forgetting, init_cov = 0.9, 10.0
    model = RLSInverseDynamics(3, 2, LOW, HIGH, forgetting=forgetting, init_cov=init_cov)
    states, next_states, actions = rng.normal(size=(7, 3)), rng.normal(size=(7, 3)), rng.uniform(-1, 1, (7, 2))
    model.update(states, next_states, actions)
    # Textbook per-sample RLS with forgetting.
    weights, covariance = np.zeros((3, 6)), np.eye(6) * init_cov
    for s, s_next, a in zip(states, next_states, actions):
        x = np.concatenate([s, a, [1.0]]).astype(np.float32).astype(np.float64)
        y = s_next.astype(np.float32).astype(np.float64)
        gain = covariance @ x / (forgetting + x @ covariance @ x)
        weights += np.outer(y - weights @ x, gain)
        covariance = (covariance - np.outer(gain, x @ covariance)) / forgetting
    np.testing.assert_allclose(model.weights, weights, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(model.covariance, covariance, rtol=1e-8, atol=1e-8)


def test_rls_state_dict_round_trip_and_clipping() -> None:
    rng = np.random.default_rng(3)
    system = _linear_system(3)
    model = RLSInverseDynamics(4, 2, LOW * 0.5, HIGH * 0.5, ridge=0.0, state_dims=(0, 1, 2))
    states = rng.uniform(-1, 1, (32, 4))
    actions = rng.uniform(-0.5, 0.5, (32, 2))
    model.update(states, _step(system, states, actions), actions)
    twin = RLSInverseDynamics(4, 2, LOW * 0.5, HIGH * 0.5, ridge=0.0, state_dims=(0, 1, 2))
    twin.load_state_dict(model.state_dict())
    far = _step(system, states, rng.uniform(-3, 3, (32, 2)))
    np.testing.assert_array_equal(twin(states, far), model(states, far))
    assert np.all(np.abs(model(states, far)) <= 0.5)


@pytest.mark.parametrize("kind", ["ground_truth", "mlp", "rls", "rls_tracking"])
def test_make_inverse_dynamics(kind: str) -> None:
    model = make_inverse_dynamics(kind, LOW, HIGH, state_dim=2, fn=lambda s, s2: 20 * (s2 - s))
    assert isinstance(model, InverseDynamics)
    assert model(np.zeros((5, 2)), np.zeros((5, 2))).shape == (5, 2)


def test_make_inverse_dynamics_errors() -> None:
    with pytest.raises(ValueError, match="ground_truth"):
        make_inverse_dynamics("oracle", LOW, HIGH, state_dim=2)
    with pytest.raises(ValueError, match="needs fn"):
        make_inverse_dynamics("ground_truth", LOW, HIGH)
    with pytest.raises(ValueError, match="state_dim"):
        make_inverse_dynamics("mlp", LOW, HIGH)
    with pytest.raises(ValueError, match="shape"):
        MLPInverseDynamics(2, 3, LOW, HIGH)
    with pytest.raises(ValueError, match=r"\[B, 2\]"):
        MLPInverseDynamics(2, 2, LOW, HIGH)(np.zeros((4, 3)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match="state_dims entry 4 is out of range"):
        RLSInverseDynamics(4, 2, LOW, HIGH, state_dims=(0, 4))
    with pytest.raises(ValueError, match="forgetting"):
        RLSInverseDynamics(4, 2, LOW, HIGH, forgetting=0.0)


# ------------------------------------------------------------------------------------- following the rest of a plan
def _fitted_point_mass_model(track_steps: int | None) -> tuple[RLSInverseDynamics, Any]:
    """RLS fitted on 600 random-action transitions of the damped point mass (tests/agent/point_mass.py)."""
    from point_mass import PointMassEnv  # tests/agent is on sys.path

    env, rng = PointMassEnv(), np.random.default_rng(0)
    model = RLSInverseDynamics(4, 2, LOW, HIGH, ridge=1e-6, warmup=0, track_steps=track_steps)
    obs, _ = env.reset(seed=0)
    states, next_states, actions = [], [], []
    for step in range(600):
        action = rng.uniform(-1, 1, 2)
        states.append(obs["observation"])
        obs, *_ = env.step(action)
        next_states.append(obs["observation"])
        actions.append(action)
        if step % 100 == 99:
            obs, _ = env.reset(seed=step)
    model.update(np.array(states), np.array(next_states), np.array(actions))
    return model, env


def _reach_rate(env: Any, policy: Any, episodes: int = 10) -> float:
    """Fraction of episodes (reset seeds 100..) that reach the goal within 100 steps."""
    reached = []
    for episode in range(episodes):
        obs, _ = env.reset(seed=100 + episode)
        for _ in range(100):
            obs, _reward, _terminated, _truncated, info = env.step(policy(obs))
            if info["is_success"]:
                break
        reached.append(info["is_success"])
    return float(np.mean(reached))


def _straight_plan(obs: dict[str, np.ndarray], steps: int = 10) -> np.ndarray:
    """[steps, 4] positions on the straight line to the goal with zero velocities: a plan whose velocities disagree
    with its positions, as an untrained energy's plans do."""
    state, goal = obs["observation"], obs["desired_goal"]
    fractions = np.linspace(0.0, 1.0, steps + 1)[1:, None]
    positions = state[:2] + fractions * (goal - state[:2])
    return np.hstack([positions, np.zeros_like(positions)])


def test_following_the_plan_reaches_goals_that_the_one_step_solve_zero_and_random_actions_do_not() -> None:
    follower, env = _fitted_point_mass_model(track_steps=None)
    one_step, _ = _fitted_point_mass_model(track_steps=1)
    rng = np.random.default_rng(1)

    def follows(model: RLSInverseDynamics) -> Any:
        return lambda obs: model.follow(obs["observation"][None], [_straight_plan(obs)])[0]

    assert _reach_rate(env, follows(follower)) >= 0.9
    # Controls: the next planned state alone asks for zero velocity, i.e. to brake; zero torque and random ones.
    assert _reach_rate(env, follows(one_step)) <= 0.1
    assert _reach_rate(env, lambda obs: np.zeros(2)) <= 0.1
    assert _reach_rate(env, lambda obs: rng.uniform(-1, 1, 2)) <= 0.1


def test_following_a_feasible_plan_recovers_its_first_action_exactly() -> None:
    rng = np.random.default_rng(2)
    system = _linear_system(0)
    model = RLSInverseDynamics(4, 2, LOW, HIGH, ridge=0.0, state_dims=(0, 1, 2), warmup=0, track_steps=None)
    for _ in range(10):
        states, actions = rng.uniform(-1, 1, (16, 4)), rng.uniform(-1, 1, (16, 2))
        model.update(states, _step(system, states, actions), actions)
    starts = rng.uniform(-1, 1, (3, 4))
    sequences = rng.uniform(-0.9, 0.9, (3, 5, 2))
    plans, state = [], starts
    for step in range(5):
        state = _step(system, state, sequences[:, step])
        plans.append(state)
    ahead = [np.stack(plans, axis=1)[row, : 5 - row] for row in range(3)]  # 5, 4 and 3 states ahead
    np.testing.assert_allclose(model.follow(starts, ahead), sequences[:, 0], atol=1e-3)


def test_following_with_one_step_is_the_one_step_solve_draw_for_draw() -> None:
    rng = np.random.default_rng(3)
    states, next_states, actions = _particle_batch(rng, 64)
    twin_a = RLSInverseDynamics(2, 2, LOW, HIGH, seed=5)
    twin_b = RLSInverseDynamics(2, 2, LOW, HIGH, seed=5)
    plans = [np.stack([next_states[row], next_states[row] + 0.01]) for row in range(8)]
    for _ in range(2):  # in the warm-up (random draws) and after it
        np.testing.assert_array_equal(twin_a.follow(states[:8], plans), twin_b(states[:8], next_states[:8]))
        twin_a.update(states, next_states, actions)
        twin_b.update(states, next_states, actions)


def test_follow_checks_its_plans_and_keeps_its_move_statistics() -> None:
    model = make_inverse_dynamics("rls_tracking", LOW, HIGH, state_dim=2)
    assert isinstance(model, RLSInverseDynamics) and model.track_steps is None
    with pytest.raises(ValueError, match="2 plans for 1 states"):
        model.follow(np.zeros((1, 2)), [np.zeros((1, 2)), np.zeros((1, 2))])
    with pytest.raises(ValueError, match="at least one planned state"):
        model.follow(np.zeros((1, 2)), [np.zeros((0, 2))])
    with pytest.raises(ValueError, match="track_steps"):
        RLSInverseDynamics(2, 2, LOW, HIGH, track_steps=0)
    states, next_states, actions = _particle_batch(np.random.default_rng(4), 32)
    model.update(states, next_states, actions)
    twin = make_inverse_dynamics("rls_tracking", LOW, HIGH, state_dim=2)
    twin.load_state_dict(model.state_dict())
    assert twin.moves.count == 32
    np.testing.assert_array_equal(twin.moves.std, model.moves.std)
    np.testing.assert_array_equal(twin.moves.largest, np.abs(next_states - states).max(axis=0))
    saved_before = {key: value for key, value in model.state_dict().items() if not key.startswith("moves_")}
    twin.load_state_dict(saved_before)
    assert twin.moves.count == 0
