"""eval.reevaluate: a finished run evaluated again with its evaluation-time settings changed."""

from __future__ import annotations

import numpy as np
import pytest

from eval.jobs import Job
from eval.reevaluate import graph_transitions, main, parse_settings, reevaluate
from eval.run import run_job

TINY_PLANNER = {"horizon": 5, "planner_config": {"num_samples": 16, "iterations": 4}, "online": {"pos_buffer_size": 1000}}


def _run(tmp_path, agent: str, **hyperparams):
    job = Job(
        "ebm/Particle-v0",
        agent,
        0,
        timesteps=100,
        eval_freq=100,
        eval_episodes=2,
        device="cpu",
        out_dir=str(tmp_path),
        hyperparams={**TINY_PLANNER, **hyperparams} if agent != "random" else {},
    )
    result = run_job(job)
    assert result.ok, result.error
    return result.run_dir


def test_parse_settings_reads_yaml_values_and_refuses_other_sections():
    assert parse_settings(["online.arrival_threshold=0.025", "subgoal_graph.lookahead=15", "online.x=null"]) == {
        "online": {"arrival_threshold": 0.025, "x": None},
        "subgoal_graph": {"lookahead": 15},
    }
    with pytest.raises(ValueError, match=r"SECTION\.KEY=VALUE"):
        parse_settings(["arrival_threshold=0.1"])
    with pytest.raises(ValueError, match="not 'planner_config'"):
        parse_settings(["planner_config.iterations=3"])


def test_unchanged_settings_reproduce_the_recorded_evaluation_and_changes_apply(tmp_path, capsys):
    run_dir = _run(tmp_path, "action-ff")
    same = reevaluate(run_dir, {})
    # Deterministic planning, the same weights, env and seed: the run's own final evaluation again.
    assert same["score_mean"] == pytest.approx(same["recorded_score_mean"], abs=1e-6)
    changed = main([str(run_dir), "--set", "online.replan_threshold=1.0e-9", "--episodes", "1"])[0]
    assert changed["settings"] == {"online": {"replan_threshold": 1e-9}} and len(changed["episode_scores"]) == 1
    assert "| re-evaluated |" in capsys.readouterr().out
    with pytest.raises(ValueError, match="arrival_threshold must be None"):
        reevaluate(run_dir, {"online": {"arrival_threshold": -1.0}})
    with pytest.raises(TypeError, match="unknown keys"):
        reevaluate(run_dir, {"online": {"arrival": 0.1}})
    with pytest.raises(ValueError, match="need a run made with subgoal_graph"):
        reevaluate(run_dir, {"subgoal_graph": {"lookahead": 3}})
    with pytest.raises(ValueError, match="no evaluation 'pair1'"):
        reevaluate(run_dir, {}, evaluation="pair1")


def test_a_run_with_a_graph_is_evaluated_with_its_rebuilt_graph(tmp_path):
    run_dir = _run(tmp_path, "action-ff", subgoal_graph={"edges": "real"})
    assert (run_dir / "graph_transitions.npz").is_file()
    result = reevaluate(run_dir, {"subgoal_graph": {"lookahead": 2}, "online": {"arrival_threshold": 0.01}})
    assert len(result["episode_scores"]) == 2 and result["success_rate"] is not None


def test_agents_without_planning_settings_and_unfinished_runs_are_refused(tmp_path):
    run_dir = _run(tmp_path, "random")
    with pytest.raises(ValueError, match="no planning settings"):
        reevaluate(run_dir, {})
    with pytest.raises(FileNotFoundError, match="has no finished harness run"):
        reevaluate(tmp_path / "nothing", {})


def test_a_pretrained_run_rebuilds_its_graph_from_its_dataset(tmp_path):
    job = Job(
        "ebm/Particle-v0",
        "action-ff",
        0,
        mode="pretrained",
        timesteps=300,
        eval_freq=300,
        offline_kwargs={"epochs": 1},
        eval_episodes=1,
        device="cpu",
        out_dir=str(tmp_path),
        hyperparams={**TINY_PLANNER, "subgoal_graph": {"edges": "real"}},
    )
    result = run_job(job)
    assert result.ok, result.error
    assert not (result.run_dir / "graph_transitions.npz").exists()  # a pretrained run's graph is its dataset's
    states, next_states = graph_transitions(result.run_dir, job)
    assert states.shape == next_states.shape == (300, 2)
    same = reevaluate(result.run_dir, {})
    assert same["score_mean"] == pytest.approx(same["recorded_score_mean"], abs=1e-6)


def test_an_online_graph_run_without_its_transitions_is_refused(tmp_path):
    run_dir = _run(tmp_path, "action-ff", subgoal_graph={"edges": "real"})
    (run_dir / "graph_transitions.npz").unlink()
    with pytest.raises(FileNotFoundError, match=r"no graph_transitions\.npz"):
        reevaluate(run_dir, {})


def test_offline_settings_and_training_data_follow_the_dataset_kind():
    from ebm_agent.datasets import TransitionDataset
    from eval.pretraining import offline_settings, training_data

    def job(dataset, **offline):
        return Job("ebm/Particle-v0", "ebm", 0, 10, 10, 1, mode="pretrained", dataset=dataset, offline_kwargs=offline)

    assert offline_settings(job("random")) == {"epochs": 10, "batch_size": 256}
    assert offline_settings(job("directed+sequential", repeat=3))["repeat"] == 3
    with pytest.raises(ValueError, match=r"offline_kwargs \['repeat'\] are not understood"):
        offline_settings(job("random", repeat=3))
    assert offline_settings(job("random", num_candidates=8))["num_candidates"] == 8  # an EBM's own keyword
    ff = Job("ebm/Particle-v0", "action-ff", 0, 10, 10, 1, mode="pretrained", offline_kwargs={"num_candidates": 8})
    with pytest.raises(ValueError, match=r"\['num_candidates'\] are not understood for dataset 'random' and agent"):
        offline_settings(ff)
    zeros = np.zeros((4, 2), np.float32)
    base = TransitionDataset(zeros, zeros, zeros, np.arange(4))
    assert training_data(base, job("random")) is base
    assert len(training_data(base, job("directed+sequential", repeat=3))) == 12
