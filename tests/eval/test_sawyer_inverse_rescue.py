"""scripts/sawyer_inverse_rescue.py: stalled samples and the rescue's gain, on real and on planned transitions."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401
from ebm_agent import EBMPlannerAgent

pytest.importorskip("mujoco")


def test_it_compares_the_rescue_with_the_ceiling_on_both_sets(load_script, tmp_path, capsys):
    script = load_script("sawyer_inverse_rescue")
    env = gym.make("ebm/SawyerReach-v0")
    agent = EBMPlannerAgent("MultiInputPolicy", env, seed=0, device="cpu", planner_config={"num_samples": 8, "iterations": 2})
    agent.save(tmp_path / "sawyer.zip")
    results = script.main([str(tmp_path / "sawyer.zip"), "--plan-steps", "3", "--real", "40"])
    real, planned = results["real"], results["planned"]
    assert real["error_all"] < 0.1  # real transitions are recovered, with or without the ceiling
    assert planned["stalled"] == 3 and planned["residual_p10"] > 0.1  # an untrained plan is out of reach
    assert 0.0 <= planned["gain_p50"] <= planned["gain_max"] <= 1.0
    assert "error_all" not in planned and planned["ms_all"] > 0 and planned["ms_ceiling"] > 0
    out = capsys.readouterr().out
    assert "| real | 40 |" in out and "| planned | 3 |" in out
    assert np.isfinite(real["ms_all"])
