"""A sweep runs one version of the code from start to end, and each record says which (``eval.code_version``)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from eval import code_version as versions
from eval.executors import LocalExecutor
from eval.jobs import Job, JobResult
from eval.run import run_job

pytest.importorskip("envs.particle")


@pytest.fixture
def fresh_version():
    """This process's version is read anew for the test and forgotten after it."""
    versions.pin_code_version(None)
    yield
    versions.pin_code_version(None)


def _jobs(n: int, out_dir: Path) -> list[Job]:
    return [
        Job("ebm/Particle-v0", "random", seed, timesteps=20, eval_freq=10, eval_episodes=1, out_dir=str(out_dir))
        for seed in range(n)
    ]


def test_the_version_names_the_commit_whether_dirty_and_the_source():
    version = versions.read_code_version()
    assert set(version) == {"commit", "dirty", "source"} and len(version["source"]) == 16
    if version["commit"] is not None:  # a git checkout
        assert len(version["commit"]) == 40 and isinstance(version["dirty"], bool)


def test_the_source_digest_sees_a_change_to_any_source_file(tmp_path):
    for package in versions.SOURCE_PACKAGES:
        (tmp_path / package).mkdir()
        (tmp_path / package / "module.py").write_text("x = 1\n")
    before = versions.source_digest(tmp_path)
    (tmp_path / "envs" / "module.py").write_text("x = 2\n")
    assert versions.source_digest(tmp_path) != before
    (tmp_path / "envs" / "module.py").write_text("x = 1\n")
    (tmp_path / "docs.md").write_text("not code")
    assert versions.source_digest(tmp_path) == before


@pytest.mark.parametrize("jobs", [1, 2])
def test_a_sweeps_runs_record_the_version_it_started_with(tmp_path, fresh_version, jobs):
    results = LocalExecutor(jobs=jobs).map(_jobs(2, tmp_path), progress=False)
    assert [result.status for result in results] == ["ok", "ok"], [result.error for result in results]
    recorded = [json.loads((result.job.run_dir / "metrics.json").read_text())["code"] for result in results]
    assert recorded == [versions.code_version()] * 2


def test_a_run_refuses_to_start_when_the_source_is_not_the_sweeps(tmp_path, fresh_version):
    versions.pin_code_version({"commit": "0" * 40, "dirty": False, "source": "0" * 16})  # the sweep's, older
    result = run_job(_jobs(1, tmp_path)[0])
    assert result.status == "failed"
    assert "source changed since this sweep started" in (result.error or "")
    assert not (result.job.run_dir / "metrics.json").exists()


def test_a_change_during_an_in_process_sweep_keeps_the_later_runs_from_its_record(tmp_path, fresh_version, monkeypatch):
    real = versions.source_digest

    def changes_after_the_first_run(job: Job) -> JobResult:
        result = run_job(job)
        monkeypatch.setattr(versions, "source_digest", lambda root=versions.PROJECT_ROOT: "f" * 16)
        return result

    monkeypatch.setattr(versions, "source_digest", real)
    results = LocalExecutor(jobs=1, runner=changes_after_the_first_run).map(_jobs(2, tmp_path), progress=False)
    assert [result.status for result in results] == ["ok", "failed"]
    assert "source changed" in (results[1].error or "")
