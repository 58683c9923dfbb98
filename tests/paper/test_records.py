"""Records: finished runs kept in the repository, restored on a new machine, skipped and reported from there."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from eval.cli import main as ebm_eval
from eval.jobs import Job
from eval.paper.experiments import build_parts, make_context
from eval.paper.records import default_docs, default_records, finished_runs, main, restore_records, save_records
from eval.paper.results_doc import collect_cell
from eval.paper.runner import plan_jobs
from eval.provenance import append_session, job_fingerprint, write_provenance


def finish(job: Job, score: float) -> None:
    """A run folder as run_job leaves it: metrics with the job's fingerprint, curve, model and provenance."""
    job.run_dir.mkdir(parents=True, exist_ok=True)
    np.savez(job.run_dir / "evaluations.npz", timesteps=[job.timesteps], results=[[score]], ep_lengths=[[100]])
    metrics = {
        "timesteps": job.timesteps,
        "score_mean": score,
        "score_std": 0.0,
        "episode_scores": [score],
        "episode_lengths": [100],
        "fingerprint": job_fingerprint(job),
    }
    (job.run_dir / "metrics.json").write_text(json.dumps(metrics))
    (job.run_dir / "model.zip").write_bytes(b"weights")
    write_provenance(job.run_dir, "ebm-eval --experiment table1 -f runs/results", status="ok")


def particle_online(out: Path):
    part = next(p for p in build_parts(["table1"], make_context("paper", str(out))) if p.name == "table1/particle/online")
    return part, next(c for c in part.cells if c.agent == "ebm")


def test_records_hold_finished_runs_without_models_and_bring_them_back(tmp_path):
    out, records, fresh = tmp_path / "runs", tmp_path / "records", tmp_path / "fresh"
    _, ebm = particle_online(out)
    finish(ebm.jobs[0], -5.0)
    finish(ebm.jobs[1], -6.0)
    (ebm.jobs[2].run_dir).mkdir(parents=True)
    (ebm.jobs[2].run_dir / "model.zip").write_bytes(b"interrupted")  # no metrics: not finished, not recorded
    aside = ebm.jobs[0].run_dir.with_name("seed_0.replaced-0123")
    aside.mkdir()
    (aside / "metrics.json").write_text((ebm.jobs[0].run_dir / "metrics.json").read_text())
    (aside / "evaluations.npz").write_bytes((ebm.jobs[0].run_dir / "evaluations.npz").read_bytes())
    append_session(out, {"command": "ebm-eval --experiment table1", "started": "2026-11-20T09:00"})

    summary = save_records(out, records)
    assert len(summary.runs) == 2 and len(list(finished_runs(records))) == 2
    recorded = records / ebm.jobs[0].run_dir.relative_to(out)
    assert sorted(p.name for p in recorded.iterdir()) == ["evaluations.npz", "metrics.json", "provenance.json"]
    assert not list(records.rglob("*.zip")) and not list(records.rglob("*replaced*"))

    # A new machine: the recorded runs count as finished, are skipped, and are reported with their scores.
    restore_records(records, fresh)
    _, fresh_ebm = particle_online(fresh)
    to_run, finished = plan_jobs(fresh_ebm.jobs, log=lambda _: None)
    assert [job.seed for job in to_run] == [2] and len(finished) == 2
    assert collect_cell(fresh_ebm).scores.tolist() == [-5.0, -6.0]
    assert len((fresh / "sessions.jsonl").read_text().splitlines()) == 1


def test_restore_keeps_a_finished_run_of_its_own_and_sessions_merge_once(tmp_path):
    out, records = tmp_path / "runs", tmp_path / "records"
    _, ebm = particle_online(out)
    finish(ebm.jobs[0], -5.0)
    append_session(out, {"command": "first", "started": "2026-11-20T09:00"})
    save_records(out, records)
    finish(ebm.jobs[0], -4.0)  # rerun here: newer than the record
    append_session(out, {"command": "second", "started": "2026-11-21T09:00"})
    summary = restore_records(records, out)
    assert summary.runs == [] and summary.kept == [ebm.jobs[0].run_dir.relative_to(out).as_posix()]
    assert json.loads((ebm.jobs[0].run_dir / "metrics.json").read_text())["score_mean"] == -4.0
    save_records(out, records)  # the record follows the rerun; sessions are not duplicated
    recorded = records / ebm.jobs[0].run_dir.relative_to(out) / "metrics.json"
    assert json.loads(recorded.read_text())["score_mean"] == -4.0
    commands = [json.loads(line)["command"] for line in (records / "sessions.jsonl").read_text().splitlines()]
    assert commands == ["first", "second"]


def test_restore_leaves_a_run_in_progress_alone(tmp_path):
    """A process retraining a retired record holds its folder; a second process's restore must not refill it."""
    import os
    import socket

    out, records = tmp_path / "runs", tmp_path / "records"
    _, ebm = particle_online(out)
    finish(ebm.jobs[0], -5.0)
    finish(ebm.jobs[1], -6.0)
    save_records(out, records)
    for job in ebm.jobs[:2]:  # retired and being retrained: moved aside, the new run has begun
        job.run_dir.rename(job.run_dir.with_name(job.run_dir.name + ".replaced-0123"))
        job.run_dir.mkdir()
        (job.run_dir / "model.zip").write_bytes(b"checkpoint in progress")
    live = {"host": socket.gethostname(), "pid": os.getpid()}
    (ebm.jobs[0].run_dir / ".running").write_text(json.dumps(live))
    (ebm.jobs[1].run_dir / ".running").write_text(json.dumps({**live, "pid": 2**22 + 12345}))  # its process is gone
    summary = restore_records(records, out)
    assert summary.kept == [ebm.jobs[0].run_dir.relative_to(out).as_posix()]
    assert summary.runs == [ebm.jobs[1].run_dir.relative_to(out).as_posix()]  # a stale lock protects nothing
    assert sorted(p.name for p in ebm.jobs[0].run_dir.iterdir()) == [".running", "model.zip"]
    assert (ebm.jobs[0].run_dir / "model.zip").read_bytes() == b"checkpoint in progress"


def test_figures_are_recorded_with_their_images_only(tmp_path):
    out, records = tmp_path / "runs", tmp_path / "records"
    folder = out / "figures" / "obstacle"
    folder.mkdir(parents=True)
    (folder / "figure.json").write_text(json.dumps({"name": "obstacle", "pngs": ["paths.png"]}))
    (folder / "paths.png").write_bytes(b"\x89PNG")
    (folder / "raw.npz").write_bytes(b"arrays")
    summary = save_records(out, records)
    assert summary.figures == ["figures/obstacle"]
    assert sorted(p.name for p in (records / "figures" / "obstacle").iterdir()) == ["figure.json", "paths.png"]
    assert main(["restore", "-f", str(tmp_path / "fresh"), "--records", str(records)]) == 0
    assert (tmp_path / "fresh" / "figures" / "obstacle" / "paths.png").read_bytes() == b"\x89PNG"


def test_the_report_restores_the_records_and_names_them(tmp_path, capsys):
    out, records, fresh = tmp_path / "runs", tmp_path / "records", tmp_path / "fresh"
    _, ebm = particle_online(out)
    for seed, job in enumerate(ebm.jobs):
        finish(job, -5.0 - seed)
    save_records(out, records)
    docs = tmp_path / "results.md"
    argv = ["--report-only", "-f", str(fresh), "--docs", str(docs), "--records", str(records), "--no-progress"]
    assert ebm_eval(argv) == 0
    text = docs.read_text()
    assert "| online | particle | EBM | -6.00 ± 0.82 | 3 |" in text
    assert f"kept in `{records}/` (committed)" in text
    assert "restored 3 run(s)" in capsys.readouterr().err


def test_records_go_with_the_published_document_only():
    from eval.cli import resolve_experiment_settings
    from eval.flags import build_parser

    def records(*argv):
        return resolve_experiment_settings(build_parser().parse_args(["--report-only", *argv]))["records"]

    assert records() == "docs/records"  # docs/results.md at the paper's scale
    assert records("--docs", "elsewhere.md") is None
    assert records("-f", "runs/scratch") is None  # a scratch folder's runs stay out of the published records
    assert records("--scale", "smoke") is None
    assert records("--records", "none") is None
    assert records("--scale", "smoke", "--records", "my/records") == "my/records"
    assert default_records(None, "docs/results.md", "./runs/results") == "docs/records"  # the module command agrees


def test_a_scratch_folder_never_overwrites_the_published_document():
    from eval.cli import resolve_experiment_settings
    from eval.flags import build_parser

    def docs(*argv):
        return resolve_experiment_settings(build_parser().parse_args(["--report-only", *argv]))["docs"]

    assert docs() == "docs/results.md"
    assert docs("-f", "runs/scratch") == "runs/scratch/results.md"  # the paper's scale, but not the published runs
    assert docs("--scale", "smoke") == "runs/results/results.md"
    assert docs("-f", "runs/scratch", "--docs", "docs/results.md") == "docs/results.md"  # asked for explicitly
    assert default_docs(None, "paper", "./runs/results") == "docs/results.md"  # the module command agrees


def test_the_anchors_the_report_computed_are_recorded(tmp_path):
    out, records = tmp_path / "runs", tmp_path / "records"
    _, ebm = particle_online(out)
    finish(ebm.jobs[0], -5.0)
    argv = ["--report-only", "-f", str(out), "--docs", str(tmp_path / "r.md"), "--records", str(records), "--no-progress"]
    assert ebm_eval(argv) == 0
    assert json.loads((records / "anchors_cache.json").read_text())  # the particle's anchors, computed once


def test_the_finished_seeds_of_an_unfinished_figure_are_recorded_and_restored_on_a_new_machine(tmp_path):
    from eval.paper.records import FIGURE_STARTED, SEED_FOLDER, restore_records, save_records

    figure = Path("figures/obstacle_generalisation")
    started = json.dumps({"part": "obstacle/particle", "scale": "paper", "seeds": [0, 1, 2]})
    out, records, fresh = tmp_path / "out", tmp_path / "records", tmp_path / "fresh"
    (out / figure / SEED_FOLDER).mkdir(parents=True)
    (out / figure / FIGURE_STARTED).write_text(started)
    (out / figure / SEED_FOLDER / "obstacle_generalisation_seed0.json").write_text('{"seed": 0}')
    summary = save_records(out, records)
    assert summary.seeds == [f"{figure.as_posix()}/seeds/obstacle_generalisation_seed0.json"]
    assert "1 finished seed(s) of unfinished figures" in summary.describe("recorded", out, records)
    restored = restore_records(records, fresh)
    assert restored.seeds == summary.seeds and (fresh / figure / FIGURE_STARTED).read_text() == started
    # a folder that started another figure there (other seeds) is left alone
    other = tmp_path / "other"
    (other / figure).mkdir(parents=True)
    (other / figure / FIGURE_STARTED).write_text(json.dumps({"part": "obstacle/particle", "scale": "paper", "seeds": [5]}))
    assert restore_records(records, other).seeds == [] and not (other / figure / SEED_FOLDER).exists()


def test_a_started_figure_without_a_finished_seed_is_not_recorded(tmp_path):
    from eval.paper.records import FIGURE_STARTED, save_records

    (tmp_path / "out" / "figures" / "energy_maps").mkdir(parents=True)
    (tmp_path / "out" / "figures" / "energy_maps" / FIGURE_STARTED).write_text("{}")
    assert save_records(tmp_path / "out", tmp_path / "records").seeds == []
    assert not (tmp_path / "records" / "figures" / "energy_maps").exists()


def test_a_run_with_seeds_still_publishes_the_protocol_seeds(tmp_path, monkeypatch):
    """``--seeds 0`` splits the work; the published document (with records) keeps reporting every seed."""
    import eval.paper.runner as runner
    from eval.executors import LocalExecutor

    written = []
    monkeypatch.setattr(runner, "write_results", lambda out, docs, scale, seeds, records=None: written.append(seeds))
    base = {"experiments": ["table1"], "out": str(tmp_path / "runs"), "docs": str(tmp_path / "results.md")}
    base.update(scale="paper", seeds=[0], device="cpu")
    for records, report_only in ((str(tmp_path / "records"), False), (str(tmp_path / "records"), True), (None, False)):
        settings = {**base, "records": records, "report_only": report_only}
        assert runner.run_experiments(settings, [], LocalExecutor(), "ebm-eval", progress=False) == 0
    assert written == [None, [0], [0]]
