"""scripts/sawyer_inverse_offline.py: a fresh MLP inverse model trained offline on real Sawyer transitions."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")


def test_bang_bang_transitions_keep_every_torque_at_a_limit(load_script):
    script = load_script("sawyer_inverse_offline")
    states, next_states, actions = script.bang_bang_transitions(12, seed=3)
    assert states.shape == next_states.shape == (12, 20) and actions.shape == (12, 7)
    assert set(np.unique(actions).tolist()) == {-1.0, 1.0}
    np.testing.assert_array_equal(states[1:], next_states[:-1])  # one episode, consecutive steps
    again = script.bang_bang_transitions(12, seed=3)
    np.testing.assert_array_equal(again[2], actions)  # seeded


def test_training_lowers_the_held_out_error_and_the_table_prints(load_script, capsys):
    script = load_script("sawyer_inverse_offline")
    results = script.main(["--train", "300", "--test", "100", "--steps", "200", "--batch", "64"])
    assert set(results["rows"]) == {(s, i) for s in ("mixed", "bang-bang") for i in ("raw", "standardized")}
    assert results["ground_truth"] < 0.01 < results["zero"]
    mixed = results["rows"][("mixed", "standardized")]
    assert [step for step, _ in mixed] == [50, 100, 150, 200]
    assert mixed[-1][1] < results["zero"]  # 200 steps on the same kind of data already beat zero torque
    out = capsys.readouterr().out
    assert "| mixed | raw |" in out and "| bang-bang | standardized |" in out and "| zero torque |" in out
