"""Run the harness's jobs as Ray tasks, on this machine or on a Ray cluster (``pip install ebm-agent[ray]``).

Only ``executor_from_name("ray")`` (``ebm-eval --executor ray``) imports this module, so nothing else loads Ray.

Each ``Job`` becomes one Ray task with its own CPU/GPU request that runs ``eval.run.run_job``; the results are
gathered in completion order (``ray.wait``) and returned in the jobs' order. ``run_job`` never raises, so a
task fails only when its worker dies (killed, out of memory, segfault): Ray retries it ``max_retries`` times and
a task that still fails becomes a failed ``JobResult`` with Ray's error, the other results kept.

Run folders: a task on the driver's node writes ``<out>/<env>/<agent>/seed_<k>/`` in place (the out dir is
made absolute first, because a worker's working directory is not the driver's on a cluster). A task on another
node, or any task under Ray Client (``ray://``, where the driver itself runs on the head node), writes into a
scratch folder and ships the files back inside its result; the driver writes them under the out dir. So a
cluster needs no shared filesystem; with one, ``ship_files=False`` skips the copy.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import tempfile
import traceback
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path, PurePosixPath
from typing import Any

import ray
import yaml
from tqdm.auto import tqdm

from eval.jobs import Job, JobResult, Runner
from eval.run import run_job

RunFiles = dict[str, bytes]
"""A run's files: path relative to the sweep's out dir (POSIX) -> content."""


def run_on_worker(job: Job, runner: Runner, driver_node: str | None, ship_files: bool | None) -> tuple[JobResult, RunFiles]:
    """The body of one Ray task: run the job, in place or in a scratch folder whose files come back.

    :param job: the job, its ``out_dir`` absolute.
    :param runner: the function run per job (``run_job``).
    :param driver_node: the driver's Ray node id; None when unknown (Ray Client), which ships the files.
    :param ship_files: True: always ship; False: always write in place (shared filesystem); None: ship when this
        worker is not on the driver's node.
    :return: the result (its job the one given) and the files to write under the out dir (empty when in place).
    """
    _hide_unreserved_gpus()
    here = ray.get_runtime_context().get_node_id()
    ship = ship_files if ship_files is not None else (driver_node is None or here != driver_node)
    if not ship:
        return runner(job), {}
    scratch = Path(tempfile.mkdtemp(prefix="ebm-eval-"))
    try:
        local_job = replace(job, out_dir=str(scratch))
        result = runner(local_job)
        _record_out_dir(local_job.run_dir / "config.yaml", job.out_dir)
        return replace(result, job=job), pack_files(scratch)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def _hide_unreserved_gpus() -> None:
    """A task that reserved no GPU must not use one: recent Ray no longer empties ``CUDA_VISIBLE_DEVICES`` for it.

    Without this, ``--device auto`` would train on a GPU that Ray may have given to another task. It works when
    CUDA is not yet initialised in this worker process, which holds within a sweep (all its tasks reserve alike).
    """
    if not ray.get_gpu_ids():
        os.environ["CUDA_VISIBLE_DEVICES"] = ""


def _record_out_dir(config_path: Path, out_dir: str) -> None:
    """Make the run's ``config.yaml`` name the driver's out dir, not the worker's scratch folder."""
    if not config_path.is_file():
        return
    config = yaml.safe_load(config_path.read_text())
    if isinstance(config, dict) and "out_dir" in config:
        config["out_dir"] = out_dir
        config_path.write_text(yaml.safe_dump(config, sort_keys=False))


def pack_files(root: Path) -> RunFiles:
    """Read every file under ``root``.

    :param root: a folder.
    :return: POSIX path relative to ``root`` -> content.
    """
    return {path.relative_to(root).as_posix(): path.read_bytes() for path in sorted(root.rglob("*")) if path.is_file()}


def unpack_files(files: RunFiles, root: Path) -> None:
    """Write shipped files under ``root``, creating folders; an existing file is replaced.

    :param files: relative POSIX path -> content, from ``pack_files``.
    :param root: the sweep's out dir.
    """
    for name, content in files.items():
        relative = PurePosixPath(name)
        if relative.is_absolute() or ".." in relative.parts:
            raise ValueError(f"refusing to write shipped file {name!r} outside the out dir {root}")
        path = root.joinpath(*relative.parts)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(content)


_remote_run = ray.remote(run_on_worker)


class RayExecutor:
    """Runs jobs as Ray tasks: on a local Ray instance, or on the cluster at ``address``.

    :param address: None: start a local Ray instance (or use the one this process already started); "auto": the
        cluster this machine belongs to (``ray start`` ran here); "ray://<head>:10001": Ray Client; "<ip>:6379":
        a cluster's head.
    :param num_cpus_per_job: CPUs each task reserves; Ray also sets the task's ``OMP_NUM_THREADS`` (torch threads) to it.
    :param num_gpus_per_job: GPUs each task reserves (fractions share a GPU); with 0 Ray hides the GPUs from the
        task, so ``--device auto`` trains on the CPU.
    :param max_retries: times Ray re-runs a task whose worker died before the job is reported as failed.
    :param runtime_env: Ray runtime environment of the sweep (e.g. ``{"working_dir": "."}`` to ship this checkout
        to a cluster whose nodes lack it); passed to ``ray.init``, so it has no effect when Ray is already running.
    :param local_num_cpus: CPUs of a local Ray instance, i.e. how many jobs run at once times ``num_cpus_per_job``
        (None: all cores); ignored when connecting to a cluster or when Ray is already running.
    :param ship_files: see ``run_on_worker``: None (default) ships run folders back from other nodes; False when the
        out dir is on a filesystem every node shares at the same path; True always.
    :param runner: the function run per job; importable on the workers or picklable by value.
    """

    def __init__(
        self,
        address: str | None = None,
        num_cpus_per_job: float = 1,
        num_gpus_per_job: float = 0,
        max_retries: int = 1,
        runtime_env: dict[str, Any] | None = None,
        local_num_cpus: int | None = None,
        ship_files: bool | None = None,
        runner: Runner = run_job,
    ) -> None:
        if address is not None and (not isinstance(address, str) or not address.strip()):
            raise ValueError(
                f"address must be None (local Ray), 'auto', 'ray://<head>:10001' or '<ip>:<port>', got {address!r}"
            )
        _check_number("num_cpus_per_job", num_cpus_per_job, minimum=0, allow_zero=False)
        _check_number("num_gpus_per_job", num_gpus_per_job, minimum=0, allow_zero=True)
        if isinstance(max_retries, bool) or not isinstance(max_retries, int) or max_retries < 0:
            raise ValueError(f"max_retries must be an integer >= 0 (re-runs of a task whose worker died), got {max_retries!r}")
        if runtime_env is not None and not isinstance(runtime_env, dict):
            raise TypeError(
                f"runtime_env must be a dict such as {{'working_dir': '.'}} or None, got {type(runtime_env).__name__}"
            )
        if local_num_cpus is not None and (
            isinstance(local_num_cpus, bool) or not isinstance(local_num_cpus, int) or local_num_cpus < 1
        ):
            raise ValueError(f"local_num_cpus must be a positive integer or None (all cores), got {local_num_cpus!r}")
        if ship_files is not None and not isinstance(ship_files, bool):
            raise TypeError(f"ship_files must be True, False or None (automatic), got {ship_files!r}")
        self.address = address
        self.num_cpus_per_job = num_cpus_per_job
        self.num_gpus_per_job = num_gpus_per_job
        self.max_retries = max_retries
        self.runtime_env = runtime_env
        self.local_num_cpus = local_num_cpus
        self.ship_files = ship_files
        self.runner = runner
        self._started_ray = False

    def connect(self) -> None:
        """Start or join Ray, unless this process is already connected."""
        if ray.is_initialized():
            return
        options: dict[str, Any] = {"address": self.address, "ignore_reinit_error": True}
        if self.runtime_env is not None:
            options["runtime_env"] = self.runtime_env
        if self.address is None:
            # A local instance must be able to place at least one task.
            cpus = self.local_num_cpus
            options["num_cpus"] = None if cpus is None else max(cpus, math.ceil(self.num_cpus_per_job))
        ray.init(**options)
        self._started_ray = True

    def shutdown(self) -> None:
        """Stop Ray if this executor started it (a cluster's nodes keep running; only this driver disconnects)."""
        if self._started_ray and ray.is_initialized():
            ray.shutdown()
        self._started_ray = False

    def map(self, jobs: Sequence[Job], progress: bool = True) -> list[JobResult]:
        """Run every job as a Ray task; see ``eval.executors.Executor.map``.

        :param jobs: the jobs.
        :param progress: show a progress bar over jobs, updated as tasks finish, and a line per failed job.
        :return: one result per job, in the jobs' order; a task that failed after its retries gives a failed result.
        """
        jobs = list(jobs)
        if not jobs:
            return []
        self.connect()
        # A cluster worker's working directory is not the driver's: give it the absolute path.
        shipped_jobs = [replace(job, out_dir=str(Path(job.out_dir).resolve())) for job in jobs]
        driver_node = None if _is_ray_client() else ray.get_runtime_context().get_node_id()
        task = _remote_run.options(
            num_cpus=self.num_cpus_per_job, num_gpus=self.num_gpus_per_job, max_retries=self.max_retries
        )
        runner_ref = ray.put(self.runner)
        pending = {task.remote(job, runner_ref, driver_node, self.ship_files): index for index, job in enumerate(shipped_jobs)}
        results: list[JobResult | None] = [None] * len(jobs)
        try:
            with tqdm(total=len(jobs), desc="ebm-eval jobs (ray)", unit="job", disable=not progress) as bar:
                while pending:
                    done, _ = ray.wait(list(pending), num_returns=1)
                    index = pending.pop(done[0])
                    result = self._collect(done[0], jobs[index])
                    results[index] = result
                    bar.set_postfix_str(_describe(result.job))
                    bar.update(1)
                    if not result.ok and progress:
                        bar.write(f"ebm-eval: {_describe(result.job)} failed: {_last_line(result.error)}")
        except BaseException:  # Ctrl-C or a driver error: do not leave the sweep running on the cluster
            for ref in pending:
                with contextlib.suppress(Exception):  # a task that just finished cannot be cancelled; keep the error
                    ray.cancel(ref, force=True)
            raise
        return [result for result in results if result is not None]

    def _collect(self, ref: Any, job: Job) -> JobResult:
        """The job's result: its files written under the out dir, or a failed result when the task died."""
        try:
            result, files = ray.get(ref)
            unpack_files(files, Path(job.out_dir))
        except Exception as error:  # the worker died after its retries, or the runner itself raised
            text = str(error) or traceback.format_exc()
            _write_error(job, f"{type(error).__name__}: {text}")
            return JobResult(job=job, status="failed", error=f"{type(error).__name__}: {text}")
        return replace(result, job=job)  # the job as given: its out_dir as the caller wrote it


def _check_number(name: str, value: Any, minimum: float, allow_zero: bool) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise TypeError(f"{name} must be a number, got {value!r}")
    if value < minimum or (not allow_zero and value == 0):
        bound = f">= {minimum}" if allow_zero else f"> {minimum}"
        raise ValueError(f"{name} must be {bound} (Ray resources a task reserves), got {value!r}")


def _is_ray_client() -> bool:
    """True when connected through Ray Client (``ray://``): the driver's filesystem is then not on any node."""
    from ray.util.client import ray as client

    return bool(client.is_connected())


def _write_error(job: Job, error: str) -> None:
    """``error.txt`` in the run folder, as ``run_job`` writes for a failure it catches (best effort)."""
    try:
        job.run_dir.mkdir(parents=True, exist_ok=True)
        (job.run_dir / "error.txt").write_text(error)
    except OSError:
        pass


def _describe(job: Job) -> str:
    return f"{job.env_short}/{job.agent}/seed {job.seed}"


def _last_line(text: str | None) -> str:
    lines = [line for line in (text or "").strip().splitlines() if line.strip()]
    return lines[-1].strip() if lines else "no error text"


__all__ = ["RayExecutor", "RunFiles", "pack_files", "run_on_worker", "unpack_files"]
