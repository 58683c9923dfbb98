"""scripts/particle_goal_weight.py: one row per seed, chunk and evaluation goal weight."""

from __future__ import annotations

import numpy as np


def test_it_evaluates_each_weight_before_and_after_each_chunk(load_script, capsys):
    script = load_script("particle_goal_weight")
    rows = script.main(
        ["--goal-weight", "1", "--timesteps", "16", "--chunks", "1", "--seeds", "0", "--eval-goal-weights", "1", "10"]
    )
    assert [(seed, steps, weight) for seed, steps, weight, _, _ in rows] == [
        (0, 0, 1.0),
        (0, 0, 10.0),
        (0, 16, 1.0),
        (0, 16, 10.0),
    ]
    assert all(np.isfinite(score) and -200.0 < score < 0.0 and 1 <= length <= 100 for *_, score, length in rows)
    assert "| 0 | 16 | 10 |" in capsys.readouterr().out
