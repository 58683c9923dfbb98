"""SIGTERM and Ctrl-C inside ``stop_at_next_step`` set a flag; the executors stop starting jobs and pass the signal
on to their workers. A stopped online run and a stopped directed collection: tests/eval/test_resume.py and
test_directed_resume.py."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from eval.executors import LocalExecutor
from eval.jobs import Job, JobResult
from eval.stop import StopFlag, stop_at_next_step, sweep_stop

pytest.importorskip("envs.particle")

REPO = Path(__file__).resolve().parents[2]

# ---- the flag ------------------------------------------------------------------------------------------------------


def test_a_signal_inside_the_block_sets_the_flag_and_the_handlers_are_put_back():
    before = {signum: signal.getsignal(signum) for signum in (signal.SIGTERM, signal.SIGINT)}
    calls: list[str] = []
    with stop_at_next_step(on_request=calls.append, quiet=True) as flag:
        assert not flag.requested
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.01)  # the handler runs at the next bytecode boundary of the main thread
        assert flag.requested and flag.signal_name == "SIGTERM" and calls == ["SIGTERM"]
        with pytest.raises(KeyboardInterrupt):  # a second signal, Ctrl-C, stops at once
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)
    assert {signum: signal.getsignal(signum) for signum in before} == before


def test_a_second_sigterm_ends_the_process_by_sigterm():
    code = (
        "import os, signal, time\n"
        "from eval.stop import stop_at_next_step\n"
        "with stop_at_next_step(quiet=True) as flag:\n"
        "    os.kill(os.getpid(), signal.SIGTERM)\n"
        "    time.sleep(0.05)\n"
        "    print('first:', flag.signal_name, flush=True)\n"
        "    os.kill(os.getpid(), signal.SIGTERM)\n"
        "    time.sleep(5)\n"
        "print('survived', flush=True)\n"
    )
    completed = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert completed.returncode == -signal.SIGTERM, completed.stderr[-2000:]
    assert completed.stdout == "first: SIGTERM\n"


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

    before = signal.getsignal(signal.SIGTERM)  # SIG_DFL, or another test's (ray.init installs one for the process)
    sender = threading.Thread(target=send_sigterm_once_two_run, daemon=True)
    sender.start()
    results = LocalExecutor(jobs=2, runner=waits_for_a_stop).map(jobs, progress=False)
    sender.join()
    assert [result.status for result in results] == ["stopped"] * 4
    assert [result.error for result in results[:2]] == ["SIGTERM", "SIGTERM"]  # forwarded to both workers
    assert all("not started" in result.error for result in results[2:])
    assert signal.getsignal(signal.SIGTERM) == before


# ---- a stop outlives the run it arrived in ---------------------------------------------------------------------------


def finishes_after_a_sigterm_in_its_evaluation(job: Job) -> JobResult:
    """Seed 0 receives SIGTERM after ``learn`` (its final evaluation: outside any run block) and still finishes."""
    if job.seed == 0:
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.01)
    return JobResult(job=job, status="ok")


def finishes_after_a_sigterm_at_its_last_step(job: Job) -> JobResult:
    """Seed 0 receives SIGTERM inside its ``learn`` block at the last step: nothing is left to stop, so it is ok."""
    with stop_at_next_step(quiet=True) as flag:
        if job.seed == 0:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(0.01)
            assert flag.requested
    return JobResult(job=job, status="ok")


@pytest.mark.parametrize("runner", [finishes_after_a_sigterm_in_its_evaluation, finishes_after_a_sigterm_at_its_last_step])
def test_in_process_a_stop_that_arrives_while_a_run_finishes_ends_the_sweep(tmp_path, runner):
    before = signal.getsignal(signal.SIGTERM)
    results = LocalExecutor(jobs=1, runner=runner).map(_jobs(3, tmp_path), progress=False)
    assert [result.status for result in results] == ["ok", "stopped", "stopped"]  # the finished run is kept
    assert all("not started" in (result.error or "") for result in results[1:])
    assert signal.getsignal(signal.SIGTERM) == before


def test_a_run_started_after_a_stop_in_the_sweep_starts_stopped():
    with sweep_stop() as sweep:
        with stop_at_next_step(quiet=True) as first:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(0.01)
        assert first.requested and sweep.signal_name == "SIGTERM"
        with stop_at_next_step(quiet=True) as second:
            assert second.signal_name == "SIGTERM"  # a later signal is the second: it stops at once
    with stop_at_next_step(quiet=True) as after:
        assert not after.requested  # the sweep's request ends with the sweep


def test_a_second_sigterm_in_the_next_run_of_a_sweep_ends_the_process():
    code = (
        "import os, signal, time\n"
        "from eval.stop import stop_at_next_step, sweep_stop\n"
        "with sweep_stop():\n"
        "    with stop_at_next_step(quiet=True):\n"
        "        os.kill(os.getpid(), signal.SIGTERM)\n"
        "        time.sleep(0.05)\n"
        "    print('first run finished', flush=True)\n"
        "    with stop_at_next_step(quiet=True):\n"
        "        os.kill(os.getpid(), signal.SIGTERM)\n"
        "        time.sleep(5)\n"
        "print('survived', flush=True)\n"
    )
    completed = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert completed.returncode == -signal.SIGTERM, completed.stderr[-2000:]
    assert completed.stdout == "first run finished\n"
