"""scripts/sawyer_ff_fit.py: a pretrained Action FF's dataset actions, its one-step fit, and its own torques."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401

pytest.importorskip("mujoco")


def test_it_reports_the_dataset_the_fit_and_the_episode(load_script, tmp_path, capsys):
    from baselines.action_ff import ActionFFAgent
    from eval.plan_trace import sawyer_real_transitions

    states, next_states, actions = sawyer_real_transitions(30, seed=5)
    actions = np.clip(actions * 10.0, -1.0, 1.0)  # a dataset with torques at the limit, as the directed one
    dataset = tmp_path / "data.npz"
    np.savez(dataset, states=states, next_states=next_states, actions=actions)
    planner = {"num_samples": 8, "iterations": 2}
    model = tmp_path / "ff.zip"
    ActionFFAgent("MultiInputPolicy", gym.make("ebm/SawyerReach-v0"), seed=0, device="cpu", planner_config=planner).save(model)

    script = load_script("sawyer_ff_fit")
    results = script.main([str(dataset), str(model), "--samples", "20", "--steps", "3"])
    limit = results["dataset_actions"]["at_limit"]
    assert len(limit) == 7 and np.allclose(limit, (np.abs(actions) >= 0.99).mean(axis=0))
    assert set(results["fit"]) == {"dataset", "real exploration", "real uniform"}
    for groups in (*results["fit"].values(), results["episode"]["fit"]):
        assert set(groups) == {"joint angles", "joint velocities", "finger xyz"}
        assert all(g["error"] > 0 and g["change"] >= 0 for g in groups.values())
    assert results["episode"]["return"] < 0 and len(results["episode"]["actions"]["mean_abs"]) == 7
    out = capsys.readouterr().out
    assert "| dataset | at the limit |" in out and "| FF evaluation episode |" in out and "first 3 steps" in out


def test_real_transitions_keep_to_one_kind_of_action_when_asked():
    from eval.plan_trace import sawyer_real_transitions

    _, _, uniform = sawyer_real_transitions(20, actions="uniform")
    _, _, exploration = sawyer_real_transitions(20, actions="exploration")
    _, _, mixed = sawyer_real_transitions(20)  # the first 250 steps explore
    np.testing.assert_array_equal(mixed, exploration)
    assert not np.allclose(uniform, exploration)
    with pytest.raises(ValueError, match="'mixed', 'exploration' or 'uniform'"):
        sawyer_real_transitions(2, actions="random")
