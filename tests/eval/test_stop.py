"""SIGTERM and Ctrl-C during ``learn``: a checkpoint at the next step, a "stopped" run, and a resume to the numbers
of an uninterrupted run; the executors stop starting jobs and pass the signal on to their workers."""

from __future__ import annotations

import json
import os
import signal
import threading
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from eval.executors import LocalExecutor
from eval.jobs import Job, JobResult, run_job
from eval.pretraining import collect_directed_transitions
from eval.resume import RESUME_FOLDER, STATE_FILE
from eval.stop import RunStopped, StopFlag, stop_at_next_step

pytest.importorskip("envs.particle")

FAST = {
    "horizon": 3,
    "planner_config": {"num_samples": 8, "iterations": 2},
    "online": {"pos_buffer_size": 1_000, "neg_buffer_size": 500},
    "image_log_interval": 0,
}


# ---- the flag ------------------------------------------------------------------------------------------------------


def test_a_signal_inside_the_block_sets_the_flag_and_the_handlers_are_put_back():
    before = {signum: signal.getsignal(signum) for signum in (signal.SIGTERM, signal.SIGINT)}
    calls: list[str] = []
    with stop_at_next_step(on_request=lambda: calls.append("forwarded"), quiet=True) as flag:
        assert not flag.requested
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.01)  # the handler runs at the next bytecode boundary of the main thread
        assert flag.requested and flag.signal_name == "SIGTERM"
        os.kill(os.getpid(), signal.SIGTERM)  # a second SIGTERM changes nothing
        time.sleep(0.01)
        assert calls == ["forwarded"]
        with pytest.raises(KeyboardInterrupt):  # a second Ctrl-C stops at once
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)
    assert {signum: signal.getsignal(signum) for signum in before} == before


def test_the_first_ctrl_c_sets_the_flag_and_says_so(capsys):
    with stop_at_next_step() as flag:
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.01)
    assert flag.signal_name == "SIGINT"
    assert "SIGINT received: writing a checkpoint after the current step" in capsys.readouterr().err


def test_outside_the_main_thread_no_handler_is_set():
    seen: list[StopFlag | object] = []

    def body() -> None:
        with stop_at_next_step() as flag:
            seen.extend([flag, signal.getsignal(signal.SIGTERM)])

    thread = threading.Thread(target=body)
    thread.start()
    thread.join()
    flag, handler = seen
    assert isinstance(flag, StopFlag) and not flag.requested
    assert handler == signal.getsignal(signal.SIGTERM)  # unchanged (read from the main thread too)


# ---- an online run --------------------------------------------------------------------------------------------------


def _job(out_dir: Path) -> Job:
    return Job(
        env_id="ebm/Particle-v0",
        agent="ebm",
        seed=1,
        timesteps=300,
        eval_freq=110,
        eval_episodes=2,
        hyperparams=FAST,
        device="cpu",
        out_dir=str(out_dir),
    )


def _weights(run_dir: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(run_dir / "model.zip") as archive:
        return {name: archive.read(name) for name in archive.namelist() if name.endswith(".pth")}


def test_sigterm_mid_run_checkpoints_that_step_and_the_rerun_ends_as_an_uninterrupted_run(
    tmp_path, monkeypatch, signal_training_after
):
    whole = run_job(_job(tmp_path / "whole"))
    assert whole.ok, whole.error

    job = _job(tmp_path / "cut")
    with monkeypatch.context() as patch:
        signal_training_after(patch, "ebm", 150, signal.SIGTERM)
        stopped = run_job(job)
    assert stopped.status == "stopped" and not stopped.ok
    assert "stopped by SIGTERM at" in stopped.error and "run the same command again to resume" in stopped.error
    assert not (job.run_dir / "error.txt").exists() and not (job.run_dir / "metrics.json").exists()
    step = json.loads((job.run_dir / RESUME_FOLDER / STATE_FILE).read_text())["num_timesteps"]
    assert 150 < step < 160 and step % 110  # the step where the signal came, not the last evaluation's (110)
    assert f"at {step}/300 transitions" in stopped.error
    assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL  # the handler is gone with the learn call

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


def test_a_directed_collection_stopped_by_ctrl_c_resumes_to_the_same_dataset(tmp_path, monkeypatch, signal_training_after):
    agent = {"horizon": 3, "planner_config": {"num_samples": 8, "iterations": 2}, "image_log_interval": 0}

    def collect(folder: Path):
        return collect_directed_transitions(
            "ebm/Particle-v0", {}, 70, seed=3, agent_kwargs=agent, device="cpu", checkpoint_dir=folder, checkpoint_every=50
        )

    whole = collect(tmp_path / "whole")
    with monkeypatch.context() as patch:
        signal_training_after(patch, "ebm", 30, signal.SIGINT)
        with pytest.raises(
            RunStopped, match=r"directed collection of 70 ebm/Particle-v0 transitions \(seed 3\) stopped by SIGINT"
        ):
            collect(tmp_path / "cut")
    step = json.loads((tmp_path / "cut" / STATE_FILE).read_text())["num_timesteps"]
    assert 30 < step < 40  # not the periodic checkpoint (none before 50)
    resumed = collect(tmp_path / "cut")
    assert resumed.info["resumed_at"] == [step]
    for name in ("states", "next_states", "actions", "episode_ids"):
        np.testing.assert_array_equal(getattr(resumed, name), getattr(whole, name))


# ---- the executors ---------------------------------------------------------------------------------------------------


def _jobs(n: int, out_dir: Path) -> list[Job]:
    return [
        Job("ebm/Particle-v0", "random", seed, timesteps=10, eval_freq=5, eval_episodes=1, out_dir=str(out_dir))
        for seed in range(n)
    ]


def stopped_at_seed_0(job: Job) -> JobResult:
    """Seed 0 comes back stopped, as a run that received SIGTERM does; the others finish."""
    return JobResult(job=job, status="stopped" if job.seed == 0 else "ok", error="stopped" if job.seed == 0 else None)


def test_in_process_no_job_starts_after_a_stopped_one(tmp_path):
    results = LocalExecutor(jobs=1, runner=stopped_at_seed_0).map(_jobs(3, tmp_path), progress=False)
    assert [result.status for result in results] == ["stopped"] * 3
    assert all("not started" in result.error for result in results[1:])


def waits_for_a_stop(job: Job) -> JobResult:
    """A worker's run: marks itself started, then waits (at most 60 s) for a stop as ``learn`` would."""
    with stop_at_next_step(quiet=True) as flag:
        (Path(job.out_dir) / f"started_{job.seed}").touch()
        deadline = time.monotonic() + 60
        while not flag.requested and time.monotonic() < deadline:
            time.sleep(0.05)
    return JobResult(job=job, status="stopped" if flag.requested else "ok", error=flag.signal_name)


def test_a_sigterm_to_the_pool_reaches_the_running_workers_and_cancels_the_rest(tmp_path):
    jobs = _jobs(4, tmp_path)

    def send_sigterm_once_two_run() -> None:
        deadline = time.monotonic() + 120
        while len(list(tmp_path.glob("started_*"))) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        os.kill(os.getpid(), signal.SIGTERM)

    sender = threading.Thread(target=send_sigterm_once_two_run, daemon=True)
    sender.start()
    results = LocalExecutor(jobs=2, runner=waits_for_a_stop).map(jobs, progress=False)
    sender.join()
    assert [result.status for result in results] == ["stopped"] * 4
    assert [result.error for result in results[:2]] == ["SIGTERM", "SIGTERM"]  # forwarded to both workers
    assert all("not started" in result.error for result in results[2:])
    assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL
