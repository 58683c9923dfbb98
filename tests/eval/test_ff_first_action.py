"""scripts/ff_first_action.py: the spread of a particle Action FF's first planned actions, and one episode."""

from __future__ import annotations

import gymnasium as gym
import pytest

import envs  # noqa: F401
from baselines.action_ff import ActionFFAgent


@pytest.fixture(scope="module")
def script(load_script):
    return load_script("ff_first_action")


def test_it_reports_each_plan_and_the_episode(script, tmp_path, capsys):
    env = gym.make("ebm/Particle-v0")
    agent = ActionFFAgent("MultiInputPolicy", env, seed=0, device="cpu", planner_config={"num_samples": 8, "iterations": 2})
    agent.save(tmp_path / "ff.zip")
    rows, summary = script.main([str(tmp_path / "ff.zip"), "--plans", "3", "--steps", "5"])
    assert len(rows) == 3
    assert all(len(row["first_action"]) == 2 and all(-1 <= a <= 1 for a in row["first_action"]) for row in rows)
    assert all(row["path_length"] >= 0 and row["final_distance"] >= 0 for row in rows)
    assert rows[0]["first_action"] != rows[1]["first_action"]  # the noise seeds differ
    assert summary["steps"] == 5 and summary["success"] == 0.0  # an untrained model does not reach the goal in 5 steps
    assert 0 < summary["path_length"] <= 5 * 0.05 * 2**0.5 + 1e-6  # at most 0.05 per axis per move
    out = capsys.readouterr().out
    assert "| noise seed | first action |" in out and "episode from [0.0, 0.0]: 5 steps" in out
