"""Online runs resume from their last checkpoint and end with the same numbers as an uninterrupted run."""

from __future__ import annotations

import json
import signal
import zipfile

import numpy as np
import pytest

from eval.jobs import Job
from eval.resume import RESUME_FOLDER, STATE_FILE, read_run_state
from eval.run import run_job

pytest.importorskip("envs.particle")

EBM_ONLY = ("image_log_interval", "training")
"""FAST's settings Action FF does not take."""

FAST = {
    "horizon": 3,
    "planner_config": {"num_samples": 8, "iterations": 2},
    "online": {"pos_buffer_size": 1_000},
    "training": {"neg_buffer_size": 500},
    "image_log_interval": 0,
}


def _job(out_dir, agent: str = "ebm", **overrides) -> Job:
    settings = {
        "env_id": "ebm/Particle-v0",
        "agent": agent,
        "seed": 1,
        "timesteps": 300,
        "eval_freq": 110,  # not a multiple of the horizon: the checkpoint falls mid-plan
        "eval_episodes": 2,
        "hyperparams": FAST if agent == "ebm" else {k: v for k, v in FAST.items() if k not in EBM_ONLY},
        "device": "cpu",
        "out_dir": str(out_dir),
    }
    settings.update(overrides)
    return Job(**settings)


def _weights(run_dir) -> dict[str, bytes]:
    with zipfile.ZipFile(run_dir / "model.zip") as archive:
        return {name: archive.read(name) for name in archive.namelist() if name.endswith(".pth")}


@pytest.mark.parametrize("agent", ["ebm", "action-ff"])
def test_a_run_killed_mid_learn_resumes_to_the_numbers_of_an_uninterrupted_run(
    tmp_path, monkeypatch, agent, kill_training_after
):
    whole = run_job(_job(tmp_path / "whole", agent))
    assert whole.ok, whole.error
    assert not (whole.run_dir / RESUME_FOLDER).exists()  # a finished run keeps no checkpoint

    # The same job, killed after transition 250: after the evaluation (and checkpoint) at 220.
    job = _job(tmp_path / "cut", agent)
    with monkeypatch.context() as patch:
        kill_training_after(patch, agent, 250)
        assert run_job(job).status == "failed"
    state = json.loads((job.run_dir / RESUME_FOLDER / STATE_FILE).read_text())
    assert state["num_timesteps"] == 220
    assert sorted(p.name for p in (job.run_dir / RESUME_FOLDER).iterdir()) == ["agent_220.zip", "envs_220.pkl", STATE_FILE]

    resumed = run_job(job)
    assert resumed.ok, resumed.error
    metrics = json.loads((job.run_dir / "metrics.json").read_text())
    reference = json.loads((whole.run_dir / "metrics.json").read_text())
    assert metrics["resumed_at"] == [220] and reference["resumed_at"] == []
    assert metrics["timesteps"] == 300 and metrics["budget_respected"]
    assert metrics["episode_scores"] == reference["episode_scores"]
    with np.load(job.run_dir / "evaluations.npz") as got, np.load(whole.run_dir / "evaluations.npz") as want:
        np.testing.assert_array_equal(got["timesteps"], [110, 220, 300])  # the curve before the kill is kept
        np.testing.assert_array_equal(got["results"], want["results"])
    assert _weights(job.run_dir) == _weights(whole.run_dir)  # bit-identical networks
    assert not (job.run_dir / RESUME_FOLDER).exists()


def test_a_checkpoint_of_another_configuration_or_torn_is_dropped(tmp_path, monkeypatch, kill_training_after):
    kill_training_after(monkeypatch, "ebm", 150)
    job = _job(tmp_path)
    assert run_job(job).status == "failed"
    assert read_run_state(job) is not None
    other = _job(tmp_path, eval_episodes=3)  # same folder, another fingerprint
    assert other.run_dir == job.run_dir
    assert read_run_state(other) is None
    assert not (job.run_dir / RESUME_FOLDER).exists()
    # A torn envs file is no checkpoint either: the run starts afresh.
    assert run_job(job).status == "failed"
    (job.run_dir / RESUME_FOLDER / "envs_110.pkl").write_bytes(b"torn")
    assert read_run_state(job) is None


def test_sigterm_mid_run_checkpoints_that_step_and_the_rerun_ends_as_an_uninterrupted_run(
    tmp_path, monkeypatch, signal_training_after
):
    whole = run_job(_job(tmp_path / "whole"))
    assert whole.ok, whole.error

    job = _job(tmp_path / "cut")
    before = signal.getsignal(signal.SIGTERM)  # SIG_DFL, or another test's (ray.init installs one for the process)
    with monkeypatch.context() as patch:
        signal_training_after(patch, "ebm", 150, signal.SIGTERM)
        stopped = run_job(job)
    assert stopped.status == "stopped" and not stopped.ok
    assert "stopped by SIGTERM at" in stopped.error and "run the same command again to resume" in stopped.error
    assert not (job.run_dir / "error.txt").exists() and not (job.run_dir / "metrics.json").exists()
    step = json.loads((job.run_dir / RESUME_FOLDER / STATE_FILE).read_text())["num_timesteps"]
    assert 150 < step < 160 and step % 110  # the step where the signal came, not the last evaluation's (110)
    assert f"at {step}/300 transitions" in stopped.error
    assert signal.getsignal(signal.SIGTERM) == before  # the run's handler is gone with the learn call

    resumed = run_job(job)
    assert resumed.ok, resumed.error
    metrics = json.loads((job.run_dir / "metrics.json").read_text())
    reference = json.loads((whole.run_dir / "metrics.json").read_text())
    assert metrics["resumed_at"] == [step]
    assert metrics["episode_scores"] == reference["episode_scores"]
    with np.load(job.run_dir / "evaluations.npz") as got, np.load(whole.run_dir / "evaluations.npz") as want:
        np.testing.assert_array_equal(got["timesteps"], [110, 220, 300])  # the evaluation after the stop falls at 220
        np.testing.assert_array_equal(got["results"], want["results"])
    assert _weights(job.run_dir) == _weights(whole.run_dir)


def test_the_one_checkpoint_callback_writes_when_due_once_per_step_and_never_at_the_budget():
    from types import SimpleNamespace

    from eval.resume import ResumeCheckpoint
    from eval.stop import StopFlag

    model = SimpleNamespace(num_timesteps=0)
    evaluations = SimpleNamespace(evaluations_timesteps=[])
    flag, written = StopFlag(), []
    callback = ResumeCheckpoint(lambda elapsed: written.append(model.num_timesteps), 10, every=4, after=evaluations, flag=flag)
    callback.model = model
    callback._init_callback()

    def step(evaluate: bool = False) -> bool:
        model.num_timesteps += 1
        if evaluate:
            evaluations.evaluations_timesteps.append(model.num_timesteps)
        return callback._on_step()

    assert all(step() for _ in range(3)) and written == []
    assert step() and written == [4]  # every 4 transitions
    assert step(evaluate=True) and written == [4, 5]  # right after an evaluation
    flag.signal_name = "SIGTERM"
    assert not step() and written == [4, 5, 6]  # a stop: a checkpoint at this step, then learn stops
    assert not callback._on_step() and written == [4, 5, 6]  # never twice for one step
    flag.signal_name = None
    model.num_timesteps = 9
    assert step(evaluate=True) and written == [4, 5, 6]  # at the budget: nothing (the run ends within seconds)
