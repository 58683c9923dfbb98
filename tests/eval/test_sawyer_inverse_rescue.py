"""scripts/sawyer_inverse_rescue.py: stalled samples and the rescue's gain, on real and on planned transitions."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")


def test_it_compares_the_rescue_with_the_ceiling_on_both_sets(load_script, untrained_sawyer_model, capsys):
    script = load_script("sawyer_inverse_rescue")
    results = script.main([str(untrained_sawyer_model), "--plan-steps", "3", "--real", "40"])
    real, planned = results["real"], results["planned"]
    assert real["error_all"] < 0.1  # real transitions are recovered, with or without the ceiling
    assert planned["stalled"] == 3 and planned["residual_p10"] > 0.1  # an untrained plan is out of reach
    assert 0.0 <= planned["gain_p50"] <= planned["gain_max"] <= 1.0
    assert "error_all" not in planned and planned["ms_all"] > 0 and planned["ms_ceiling"] > 0
    out = capsys.readouterr().out
    assert "| real | 40 |" in out and "| planned | 3 |" in out
    assert np.isfinite(real["ms_all"])
