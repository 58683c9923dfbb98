"""scripts/reacher_plan_gap.py: the plans' velocity consistency beside what the arm does, along an episode."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401
from envs.reacher import wrapped_l1_distance
from eval.jobs import EVAL_SEED_OFFSET

pytest.importorskip("mujoco")


def test_velocity_inconsistency_is_zero_for_a_real_trajectory_and_sees_a_jump(load_script):
    script = load_script("reacher_plan_gap")
    env = gym.make("ebm/Reacher-v0")
    obs, _ = env.reset(seed=0)
    states = [obs["observation"]]
    for torque in ([0.5, -0.3], [0.2, 0.4], [-0.6, 0.1]):
        states.append(env.step(np.array(torque, dtype=np.float32))[0]["observation"])
    real = np.array(states)  # [4, 4]
    dt = env.unwrapped.dt
    assert script.velocity_inconsistency(real, dt) < 1e-3  # constant torque per step: the trapezoid is near exact
    jumped = real.copy()
    jumped[2:, 0] += 0.3  # the shoulder leaps 0.3 between states 1 and 2 with no velocity to carry it
    assert script.velocity_inconsistency(jumped, dt) == pytest.approx(0.3 / (3 * 2), abs=1e-3)
    wrapped = real.copy()
    wrapped[:, 0] = (wrapped[:, 0] + 2.0) % 2.0 - 1.0  # half a turn on, across the seam: the same motion
    assert script.velocity_inconsistency(wrapped, dt) == pytest.approx(script.velocity_inconsistency(real, dt), abs=1e-9)


def test_it_prints_the_distance_the_plans_and_their_count(load_script, untrained_reacher_model, capsys):
    script = load_script("reacher_plan_gap")
    rows = script.main([str(untrained_reacher_model), "--steps", "4", "--every", "2", "--angle-weight", "30"])
    assert [row["step"] for row in rows] == [0, 2]
    start = gym.make("ebm/Reacher-v0").reset(seed=EVAL_SEED_OFFSET)[0]
    assert rows[0]["distance"] == pytest.approx(float(wrapped_l1_distance(start["achieved_goal"], start["desired_goal"])))
    assert all(row["plan_error"] < 1.0 for row in rows)  # angles compared across the seam, not 2 apart
    assert rows[0]["new_plan"] == 1.0  # the episode's first step makes a plan
    assert all(0 <= row["max_torque"] <= 1 and row["plan_inconsistency"] >= 0 for row in rows)
    assert 1 <= rows[-1]["plans"] <= 4 and rows[-1]["return"] < 0
    out = capsys.readouterr().out
    assert "| 2 |" in out and "plans made:" in out
