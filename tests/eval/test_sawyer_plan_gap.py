"""scripts/sawyer_plan_gap.py: the real finger distance beside the one the plans claim, along an episode."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401
from eval.jobs import EVAL_SEED_OFFSET

pytest.importorskip("mujoco")


def test_it_prints_the_real_and_the_planned_distance(load_script, untrained_sawyer_model, capsys):
    script = load_script("sawyer_plan_gap")
    rows = script.main([str(untrained_sawyer_model), "--steps", "4", "--every", "2", "--finger-weight", "0"])
    assert [row["step"] for row in rows] == [0, 2]
    start = gym.make("ebm/SawyerReach-v0").reset(seed=EVAL_SEED_OFFSET)[0]
    first = np.linalg.norm(start["observation"][14:17] - start["desired_goal"])  # the finger's dims
    assert rows[0]["distance"] == pytest.approx(first)
    assert all(0 <= row["max_torque"] <= 1 and np.isfinite(row["plan_error"]) for row in rows)
    assert all(row["plan_inconsistency"] >= 0 for row in rows) and rows[-1]["return"] < 0
    out = capsys.readouterr().out
    assert "| 2 |" in out and "return over 4 steps" in out
