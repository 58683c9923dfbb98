"""scripts/sawyer_learned_inverse.py: a learned inverse model on real transitions, on the plans, and swapped out."""

from __future__ import annotations

import gymnasium as gym
import pytest

import envs  # noqa: F401

pytest.importorskip("mujoco")


def _save(tmp_path, inverse_dynamics: str):
    from ebm_agent import EBMPlannerAgent

    env = gym.make("ebm/SawyerReach-v0")
    planner = {"num_samples": 8, "iterations": 2}
    agent = EBMPlannerAgent(
        "MultiInputPolicy", env, seed=0, device="cpu", planner_config=planner, inverse_dynamics=inverse_dynamics
    )
    path = tmp_path / f"{inverse_dynamics}.zip"
    agent.save(path)
    return path


def test_it_compares_the_learned_model_with_the_ground_truth(load_script, tmp_path, capsys):
    script = load_script("sawyer_learned_inverse")
    results = script.main([str(_save(tmp_path, "rls")), "--steps", "4", "--every", "2", "--real", "20"])
    assert results["kind"] == "rls"
    real = results["real"]
    assert real["truth_error"] < 0.01 < real["learned_error"]  # an unfitted RLS answers with random warm-up torques
    assert [row["step"] for row in results["learned"]["rows"]] == [0, 2]
    assert all(row["action_gap"] > 0 and 0 <= row["max_torque"] <= 1 for row in results["learned"]["rows"])
    assert results["learned"]["return"] < 0 and results["ground_truth_return"] < 0
    assert results["learned"]["return"] != results["ground_truth_return"]
    out = capsys.readouterr().out
    assert "| learned (rls) |" in out and "| ground truth |" in out and "| 2 |" in out


def test_it_refuses_a_model_that_already_acts_with_the_ground_truth(load_script, tmp_path):
    script = load_script("sawyer_learned_inverse")
    with pytest.raises(SystemExit):
        script.main([str(_save(tmp_path, "ground_truth")), "--steps", "2", "--real", "4"])
