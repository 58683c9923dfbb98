"""LocalExecutor in-process and with a spawned pool, on trivial picklable jobs; executor names."""

from __future__ import annotations

import os

import pytest

from eval.executors import Executor, LocalExecutor, executor_from_name
from eval.jobs import Job, JobResult


def seed_runner(job: Job) -> JobResult:
    """A trivial job: reports its seed times 10 as timesteps, and its process id as wall time."""
    return JobResult(job=job, status="ok", timesteps=job.seed * 10, wall_time_s=float(os.getpid()))


def failing_runner(job: Job) -> JobResult:
    """Raises for seed 1, works for the others."""
    if job.seed == 1:
        raise RuntimeError("seed 1 always fails")
    return seed_runner(job)


def _jobs(n: int) -> list[Job]:
    return [Job("ebm/Particle-v0", "random", seed, timesteps=10, eval_freq=5, eval_episodes=1) for seed in range(n)]


def test_in_process_executor_keeps_order_and_runs_here():
    results = LocalExecutor(jobs=1, runner=seed_runner).map(_jobs(3), progress=False)
    assert [r.timesteps for r in results] == [0, 10, 20]
    assert [r.job.seed for r in results] == [0, 1, 2]
    assert all(r.wall_time_s == os.getpid() for r in results)


def test_in_process_failing_job_is_reported_and_the_others_kept():
    results = LocalExecutor(jobs=1, runner=failing_runner).map(_jobs(3), progress=False)
    assert [r.status for r in results] == ["ok", "failed", "ok"]
    assert "seed 1 always fails" in (results[1].error or "")
    assert results[2].timesteps == 20


def threads_runner(job: Job) -> JobResult:
    """Reports the torch threads of the process it runs in as its timesteps."""
    import torch

    return JobResult(job=job, status="ok", timesteps=torch.get_num_threads())


def test_threads_per_job_sets_torch_threads_in_process_and_defaults_to_one_per_worker():
    import torch

    before = torch.get_num_threads()
    try:
        assert LocalExecutor(jobs=1, runner=threads_runner).map(_jobs(1), progress=False)[0].timesteps == before
        assert LocalExecutor(jobs=1, runner=threads_runner, threads_per_job=1).map(_jobs(1), progress=False)[0].timesteps == 1
    finally:
        torch.set_num_threads(before)
    with pytest.raises(ValueError, match="threads_per_job"):
        LocalExecutor(jobs=1, threads_per_job=0)


def test_pool_executor_keeps_order_runs_elsewhere_and_survives_a_failure():
    # One pool for all three checks: spawning workers costs seconds.
    results = LocalExecutor(jobs=2, runner=failing_runner).map(_jobs(4), progress=True)
    assert [r.status for r in results] == ["ok", "failed", "ok", "ok"]
    assert [r.job.seed for r in results] == [0, 1, 2, 3]
    assert [r.timesteps for r in results if r.ok] == [0, 20, 30]
    assert "seed 1 always fails" in (results[1].error or "")
    assert all(r.wall_time_s != os.getpid() for r in results if r.ok)


def test_empty_job_list():
    assert LocalExecutor(jobs=2).map([], progress=False) == []


def test_executor_from_name():
    executor = executor_from_name("local", jobs=3)
    assert isinstance(executor, LocalExecutor) and executor.jobs == 3
    assert isinstance(executor, Executor)
    with pytest.raises(ValueError, match="unknown executor 'dask'; choose one of: local, ray"):
        executor_from_name("dask")


@pytest.mark.parametrize("jobs", [0, -1, 1.5, True])
def test_bad_worker_count_raises(jobs):
    with pytest.raises(ValueError, match="positive integer"):
        LocalExecutor(jobs=jobs)
