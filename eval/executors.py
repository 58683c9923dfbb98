"""Executors run a list of independent jobs and return their results in the same order.

``LocalExecutor`` uses a process pool on this machine. A distributed engine plugs in behind the same
``Executor`` protocol: it only has to ship a picklable ``Job`` to ``run_job`` and bring the picklable
``JobResult`` back. ``executor_from_name("ray")`` imports ``eval.ray_executor.RayExecutor`` (Ray tasks, the
``ray`` extra) lazily, so that nothing else imports Ray.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import traceback
from collections.abc import Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from typing import Any, Protocol, runtime_checkable

import torch
from tqdm.auto import tqdm

from eval.code_version import code_version, pin_code_version
from eval.jobs import Job, JobResult, Runner
from eval.run import run_job
from eval.stop import install_worker_handlers, stop_received, sweep_stop


@runtime_checkable
class Executor(Protocol):
    """Runs jobs and returns one result per job, in the order of the jobs."""

    def map(self, jobs: Sequence[Job], progress: bool = True) -> list[JobResult]:
        """Run every job.

        :param jobs: the jobs, independent of each other.
        :param progress: show a progress bar over jobs.
        :return: the results, ``results[i]`` for ``jobs[i]``; a job that failed gives a failed result.
        """
        ...


def _limit_threads(threads: int) -> None:
    """One torch thread per worker, so that ``--jobs`` workers do not fight over the cores."""

    torch.set_num_threads(threads)


def _start_worker(threads: int, version: dict[str, Any]) -> None:
    """Pool initializer: limit torch's threads, remember stop signals rather than die of them (``eval.stop``), and take
    the sweep's code version, so that a worker spawned after a library change refuses its runs
    (``eval.code_version``)."""

    _limit_threads(threads)
    install_worker_handlers()
    pin_code_version(version)


def _pool_job(runner: Runner, job: Job) -> JobResult:
    """Run ``job`` in a pool worker, unless the worker has received a stop signal."""

    if stop_received() is not None:
        return _not_started(job)
    return runner(job)


class LocalExecutor:
    """Runs jobs on this machine: in this process for ``jobs=1``, else in a pool of spawned processes.

    :param jobs: number of jobs run at once (worker processes).
    :param runner: the function run per job; it must be importable by name (picklable) for ``jobs > 1``.
    :param threads_per_job: torch threads of each run: of each worker process, or of this process for ``jobs=1``
        and for the figures that run in it (None: 1 per worker, and torch's own setting in-process, every core by
        default). Several processes on the
        same cores, each with torch's default, oversubscribe them: give each 1.
    """

    def __init__(self, jobs: int = 1, runner: Runner = run_job, threads_per_job: int | None = None) -> None:
        if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
            raise ValueError(f"jobs must be a positive integer (parallel worker processes), got {jobs!r}")
        self.jobs = jobs
        self.runner = runner
        if threads_per_job is not None and (
            isinstance(threads_per_job, bool) or not isinstance(threads_per_job, int) or threads_per_job < 1
        ):
            raise ValueError(f"threads_per_job must be a positive integer or None, got {threads_per_job!r}")
        self.threads_per_job = threads_per_job

    def limit_this_process(self) -> None:
        """Give this process ``threads_per_job`` torch threads (nothing when it is None).

        For the work that runs in this process: the runs of ``jobs=1``, and the figure parts of ``ebm-eval
        --experiment`` (``eval.paper.runner.run_parts``), which would otherwise take every core beside other
        processes that were told to share them.
        """
        if self.threads_per_job is not None:
            _limit_threads(self.threads_per_job)

    def map(self, jobs: Sequence[Job], progress: bool = True) -> list[JobResult]:
        """Run every job; see ``Executor.map``.

        :param jobs: the jobs.
        :param progress: show a progress bar over jobs.
        :return: one result per job, in order.
        """
        jobs = list(jobs)
        if not jobs:
            return []
        code_version()  # the version this sweep runs, read at its start (eval.code_version)
        with tqdm(total=len(jobs), desc="ebm-eval jobs", unit="job", disable=not progress) as bar:
            if self.jobs == 1:
                self.limit_this_process()
                results: list[JobResult] = []
                # A signal anywhere in the sweep (in a run, in its final evaluation, between runs) stops it: the run
                # in progress finishes or writes its checkpoint, and no further run starts.
                with sweep_stop() as stop:
                    for job in jobs:
                        stopped = stop.requested or any(result.status == "stopped" for result in results)
                        results.append(_not_started(job) if stopped else self._run_in_process(job, bar))
                return results
            return self._run_in_pool(jobs, bar)

    def _run_in_process(self, job: Job, bar: Any) -> JobResult:
        bar.set_postfix_str(_describe(job))
        try:
            result = self.runner(job)
        except Exception:  # a runner other than run_job may raise; the sweep goes on
            result = JobResult(job=job, status="failed", error=traceback.format_exc())
        bar.update(1)
        return result

    def _run_in_pool(self, jobs: list[Job], bar: Any) -> list[JobResult]:

        # spawn, not fork: torch and MuJoCo state must not be copied into children mid-flight.
        context = multiprocessing.get_context("spawn")
        results: list[JobResult | None] = [None] * len(jobs)
        workers = min(self.jobs, len(jobs))
        with ProcessPoolExecutor(
            workers,
            mp_context=context,
            initializer=_start_worker,
            initargs=(self.threads_per_job or 1, code_version()),
        ) as pool:
            futures: dict[Future[JobResult], int] = {pool.submit(_pool_job, self.runner, job): i for i, job in enumerate(jobs)}

            def stop_workers(signal_name: str) -> None:
                # SIGTERM or Ctrl-C to this process: no new job starts, and the running ones are asked to stop
                # (inside learn, each writes its checkpoint at its next step; elsewhere, it finishes its job).
                # SIGTERM is passed on; a Ctrl-C in a terminal reaches the workers already, and a second signal
                # would stop them at once.
                for future in futures:
                    future.cancel()
                if signal_name != "SIGTERM":
                    return
                for process in multiprocessing.active_children():
                    if process.pid is not None:
                        with contextlib.suppress(ProcessLookupError):
                            os.kill(process.pid, signal.SIGTERM)

            with sweep_stop(on_request=stop_workers):
                for future in as_completed(futures):
                    index = futures[future]
                    if future.cancelled():
                        results[index] = _not_started(jobs[index])
                        continue
                    try:
                        results[index] = future.result()
                    except Exception:  # the worker died or the job could not be pickled
                        results[index] = JobResult(job=jobs[index], status="failed", error=traceback.format_exc())
                    bar.set_postfix_str(_describe(jobs[index]))
                    bar.update(1)
        return [result for result in results if result is not None]


def _not_started(job: Job) -> JobResult:
    """The result of a job a signal kept from starting: stopped, with nothing to resume yet."""
    return JobResult(job=job, status="stopped", error="not started: the sweep was stopped by a signal; run it again")


def _describe(job: Job) -> str:
    return f"{job.env_short}/{job.agent}/seed {job.seed}"


EXECUTORS = ("local", "ray")
"""Executor names understood by ``executor_from_name``."""


def executor_from_name(name: str, **kwargs: Any) -> Executor:
    """Build an executor by name.

    :param name: "local" (process pool on this machine) or "ray" (Ray tasks; needs the ``ray`` extra).
    :param kwargs: constructor arguments of the executor (e.g. ``jobs=4`` for local; ``address="auto"``,
        ``num_cpus_per_job=1``, ``num_gpus_per_job=0`` for ray, see ``eval.ray_executor.RayExecutor``).
    :return: the executor.
    """
    if name == "local":
        return LocalExecutor(**kwargs)
    if name == "ray":
        try:
            from eval.ray_executor import RayExecutor  # type: ignore[import-not-found]
        except ImportError as error:
            raise ValueError(
                f"the ray executor is not available ({error}); install the extra with `pip install ebm-agent[ray]` "
                "or use --executor local"
            ) from None
        return RayExecutor(**kwargs)  # type: ignore[no-any-return]
    raise ValueError(f"unknown executor {name!r}; choose one of: {', '.join(EXECUTORS)}")


__all__ = ["EXECUTORS", "Executor", "LocalExecutor", "executor_from_name"]
