"""A directed collection cut short goes on from its checkpoint and yields the dataset of an uninterrupted one."""

from __future__ import annotations

import json
import signal

import numpy as np
import pytest

from eval.jobs import Job
from eval.pretraining import (
    collect_directed_transitions,
    collection_checkpoint_dir,
    dataset_path,
    load_or_build_dataset,
)
from eval.resume import STATE_FILE
from eval.run import run_job
from eval.stop import RunStopped

pytest.importorskip("envs.particle")

AGENT = {"horizon": 3, "planner_config": {"num_samples": 8, "iterations": 2}, "image_log_interval": 0}


def _collect(folder, every: int = 25, **kwargs):
    return collect_directed_transitions(
        "ebm/Particle-v0",
        {},
        70,
        seed=3,
        agent_kwargs=AGENT,
        device="cpu",
        checkpoint_dir=folder,
        checkpoint_every=every,
        **kwargs,
    )


def _same_data(got, want) -> None:
    for name in ("states", "next_states", "actions", "episode_ids"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name))


def test_a_collection_killed_midway_resumes_to_the_dataset_of_an_uninterrupted_one(tmp_path, monkeypatch, kill_training_after):
    whole = _collect(tmp_path / "whole")
    assert len(whole) == 70 and whole.info["resumed_at"] == []
    assert sorted(path.name for path in (tmp_path / "whole").iterdir()) == ["agent_50.zip", "envs_50.pkl", STATE_FILE]

    cut = tmp_path / "cut"
    with monkeypatch.context() as patch:
        kill_training_after(patch, "ebm", 60)
        with pytest.raises(RuntimeError, match="killed"):
            _collect(cut)
    state = json.loads((cut / STATE_FILE).read_text())
    assert state["num_timesteps"] == 50  # the last checkpoint before the kill, the one at 25 dropped
    assert sorted(path.name for path in cut.iterdir()) == ["agent_50.zip", "envs_50.pkl", STATE_FILE]

    resumed = _collect(cut)
    assert resumed.info["resumed_at"] == [50]
    # No checkpoint after the resume: the next one was due at 75, past the end.
    assert sorted(path.name for path in cut.iterdir()) == ["agent_50.zip", "envs_50.pkl", STATE_FILE]
    assert resumed.info["collect_time_s"] >= state["collect_time_s"]
    _same_data(resumed, whole)


def test_a_checkpoint_of_another_collection_is_dropped(tmp_path, monkeypatch, kill_training_after):
    folder = tmp_path / "collect"
    with monkeypatch.context() as patch:
        kill_training_after(patch, "ebm", 30)
        with pytest.raises(RuntimeError, match="killed"):
            _collect(folder)
    assert json.loads((folder / STATE_FILE).read_text())["num_timesteps"] == 25
    other = collect_directed_transitions(
        "ebm/Particle-v0", {}, 70, seed=4, agent_kwargs=AGENT, device="cpu", checkpoint_dir=folder, checkpoint_every=25
    )  # another seed: started afresh, not continued
    assert other.info["resumed_at"] == []
    with pytest.raises(ValueError, match="checkpoint_every"):
        _collect(folder, every=0)


def test_a_job_resumes_its_directed_dataset_and_removes_the_checkpoint_once_saved(tmp_path, monkeypatch, kill_training_after):
    job = Job(
        env_id="ebm/Particle-v0",
        agent="ebm",
        seed=2,
        timesteps=40,
        eval_freq=40,
        eval_episodes=1,
        mode="pretrained",
        dataset="directed",
        dataset_kwargs=AGENT,
        device="cpu",
        out_dir=str(tmp_path),
    )
    monkeypatch.setattr("eval.pretraining.COLLECT_CHECKPOINT_EVERY", 25)
    with monkeypatch.context() as patch:
        kill_training_after(patch, "ebm", 30)
        with pytest.raises(RuntimeError, match="killed"):
            load_or_build_dataset(job)
    assert not dataset_path(job).exists()
    state = json.loads((collection_checkpoint_dir(job) / STATE_FILE).read_text())
    assert state["num_timesteps"] == 25

    result = run_job(job)  # finishes the collection, then pretrains and evaluates
    assert result.ok, result.error
    assert not collection_checkpoint_dir(job).exists()  # saved: the checkpoint is spent
    # The killed process's collecting time counts in the run's times, as an online run's earlier processes do.
    metrics = json.loads((job.run_dir / "metrics.json").read_text())
    earlier = metrics["pretraining"]["collect_time_earlier_processes_s"]
    assert earlier == pytest.approx(state["collect_time_s"]) and earlier > 0
    assert metrics["wall_time_s"] > earlier and metrics["learn_time_s"] > earlier

    dataset, path = load_or_build_dataset(job)  # from the cache now
    assert path == dataset_path(job) and path.exists() and len(dataset) == 40
    assert dataset.info["resumed_at"] == [25] and dataset.info["policy"] == "directed"
    assert dataset.info["collect_time_s"] > earlier and "collect_time_before_s" not in dataset.info


def test_a_collection_stopped_by_ctrl_c_checkpoints_that_step_and_resumes_to_the_same_dataset(
    tmp_path, monkeypatch, signal_training_after
):
    whole = _collect(tmp_path / "whole", every=50)
    with monkeypatch.context() as patch:
        signal_training_after(patch, "ebm", 30, signal.SIGINT)
        with pytest.raises(RunStopped, match=r"of 70 ebm/Particle-v0 transitions \(seed 3\) stopped by SIGINT at"):
            _collect(tmp_path / "cut", every=50)
    step = json.loads((tmp_path / "cut" / STATE_FILE).read_text())["num_timesteps"]
    assert 30 < step < 40  # the step where the signal came (no periodic checkpoint before 50)
    resumed = _collect(tmp_path / "cut", every=50)
    assert resumed.info["resumed_at"] == [step]
    _same_data(resumed, whole)
