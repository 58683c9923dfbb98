"""Cost estimates and measured times of the paper's experiments (``ebm-eval --experiment list``)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from eval.paper.estimates import (
    MeasuredCost,
    estimate_collection_seconds,
    estimate_job_seconds,
    estimate_jobs_seconds,
    estimate_part_seconds,
    format_duration,
    measured_part_cost,
)
from eval.paper.experiments import build_parts, describe_experiments, make_context


def _part(out: Path, name: str):
    return next(p for p in build_parts(["all"], make_context("paper", str(out))) if p.name == name)


def _finish(run_dir: Path, seconds: float) -> None:
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "metrics.json").write_text(json.dumps({"timesteps": 50_000, "wall_time_s": seconds}))


def test_measured_cost_sums_the_finished_runs_from_the_first_folder_holding_each(tmp_path):
    out, records = tmp_path / "runs", tmp_path / "records"
    part = _part(out, "table1/particle/online")
    jobs = part.jobs
    assert measured_part_cost(part, [out, records]) is None  # nothing finished yet
    _finish(jobs[0].run_dir, 600.0)
    _finish(records / jobs[0].run_dir.relative_to(out), 9_999.0)  # shadowed by the results folder's own run
    _finish(records / jobs[1].run_dir.relative_to(out), 900.0)
    (jobs[2].run_dir).mkdir(parents=True)
    (jobs[2].run_dir / "metrics.json").write_text("{not json")  # an unreadable file counts as not finished
    assert measured_part_cost(part, [out, records]) == MeasuredCost(1_500.0, 2, len(jobs))
    assert MeasuredCost(1_500.0, 2, 6).describe() == "measured 25 min (2/6 runs)"


def test_a_figure_is_measured_by_the_wall_time_of_its_command(tmp_path):
    part = _part(tmp_path, "plan_diversity/particle")
    part.figure_dir.mkdir(parents=True)
    (part.figure_dir / "provenance.json").write_text(json.dumps({"wall_time_s": 1_147.4}))
    cost = measured_part_cost(part, [tmp_path])
    assert cost == MeasuredCost(1_147.4, 1, 1, "figure")
    assert cost.describe() == "measured 19 min (1/1 figure)"


def test_runs_and_figures_made_under_earlier_defaults_are_measured_and_named_to_rerun(tmp_path):
    from eval.paper.figures.common import figure_digest
    from eval.provenance import defaults_digest, job_fingerprint

    part = _part(tmp_path, "table2/sawyer/pretrained_directed")
    current, old, other = part.jobs[0], part.jobs[1], part.jobs[2]
    for job, digest in ((current, defaults_digest(current)), (old, "0" * 16), (other, "0" * 16)):
        job.run_dir.mkdir(parents=True)
        fingerprint = job_fingerprint(job) if job is not other else "another configuration"
        metrics = {"wall_time_s": 600.0, "fingerprint": fingerprint, "defaults_digest": digest}
        (job.run_dir / "metrics.json").write_text(json.dumps(metrics))
    cost = measured_part_cost(part, [tmp_path])
    assert cost == MeasuredCost(1_800.0, 3, len(part.jobs), retired=1)  # the same job under other defaults only
    assert cost.describe() == "measured 30 min (3/6 runs, 1 under earlier defaults: to rerun)"

    figure = _part(tmp_path, "obstacle/particle")
    figure.figure_dir.mkdir(parents=True)
    record = {"wall_time_s": 17_280.0, "defaults_digest": figure_digest("obstacle_generalisation")}
    (figure.figure_dir / "provenance.json").write_text(json.dumps(record))
    assert measured_part_cost(figure, [tmp_path]) == MeasuredCost(17_280.0, 1, 1, "figure")
    (figure.figure_dir / "provenance.json").write_text(json.dumps({**record, "defaults_digest": "0" * 16}))
    retired = measured_part_cost(figure, [tmp_path])
    assert retired is not None and retired.describe() == "measured 4.8 h (1/1 figure, 1 under earlier defaults: to rerun)"


def test_the_listing_prints_measured_times_beside_the_estimates(tmp_path):
    part = _part(tmp_path, "table1/maze/online")
    for job in part.jobs:
        _finish(job.run_dir, 1_000.0)
    text = describe_experiments(make_context("paper", str(tmp_path)), [tmp_path])
    line = next(line for line in text.splitlines() if "table1/maze/online" in line)
    assert f"~{format_duration(estimate_part_seconds(part))}" in line
    assert line.endswith("measured 1.7 h (6/6 runs)")
    assert "measured" not in next(line for line in text.splitlines() if "table1/reacher/online" in line)


def test_the_listing_names_unfinished_runs_that_kept_a_checkpoint(tmp_path):
    from eval.jobs import RESUME_FOLDER, STATE_FILE

    part = _part(tmp_path, "table1/maze/online")
    job = part.jobs[0]
    (job.run_dir / RESUME_FOLDER).mkdir(parents=True)
    (job.run_dir / RESUME_FOLDER / STATE_FILE).write_text('{"num_timesteps": 20000}')
    text = describe_experiments(make_context("paper", str(tmp_path)), [tmp_path])
    line = next(line for line in text.splitlines() if "table1/maze/online" in line)
    assert line.endswith(f"; resumes {job.agent} seed {job.seed} at 20000/{job.timesteps}")
    _finish(job.run_dir, 1_000.0)  # a finished run is not in progress, whatever its folder still holds
    text = describe_experiments(make_context("paper", str(tmp_path)), [tmp_path])
    assert "resumes" not in next(line for line in text.splitlines() if "table1/maze/online" in line)


def test_the_action_ff_sawyer_run_is_priced_without_the_inverse_dynamics(tmp_path):
    part = _part(tmp_path, "table2/sawyer/online_fixed")
    by_agent = {job.agent: estimate_job_seconds(job) for job in part.jobs if job.seed == 0}
    # Measured 2026-12-02: about 21 min for the Action FF's run, 63 min for the EBM's (with the rescue ceiling).
    assert 15 * 60 < by_agent["action-ff"] < 30 * 60
    assert 45 * 60 < by_agent["ebm"] < 90 * 60


def test_a_directed_seed_is_priced_at_least_its_measured_collection(tmp_path):
    # Measured 2026-12-03: the Sawyer's 100,000 directed transitions of seed 0 took 10,715 s of one core. The two
    # agents of a seed share the collection, so their two jobs together carry it, on top of their own learning.
    part = _part(tmp_path, "table2/sawyer/pretrained_directed")
    seed0 = [job for job in part.jobs if job.seed == 0]
    assert sorted(job.agent for job in seed0) == ["action-ff", "ebm"]
    total = estimate_jobs_seconds(seed0)
    assert 10_000 < total < 16_000
    random = _part(tmp_path, "table2/sawyer/pretrained_random")
    assert estimate_jobs_seconds(job for job in random.jobs if job.seed == 0) < total / 5  # nothing to collect


def test_the_directed_parts_share_one_collection_per_seed(tmp_path):
    # The directed and directed + sequential parts learn from the same cached collection (eval.pretraining): each
    # part alone is charged it, the two together once, and so are the experiment's and the listing's totals.
    directed = _part(tmp_path, "table2/sawyer/pretrained_directed")
    sequential = _part(tmp_path, "table2/sawyer/pretrained_directed_sequential")
    collections = sum(estimate_collection_seconds(job) for job in directed.jobs if job.agent == "ebm")
    assert collections > 3 * 10_000  # three seeds of 100,000 directed Sawyer steps
    both = estimate_jobs_seconds([*directed.jobs, *sequential.jobs])
    alone = estimate_part_seconds(directed) + estimate_part_seconds(sequential)
    assert both == pytest.approx(alone - collections)
    text = describe_experiments(make_context("paper", str(tmp_path)))
    table2 = next(line for line in text.splitlines() if line.startswith("table2 "))
    parts = sum(estimate_part_seconds(part) for part in build_parts(["table2"], make_context("paper", str(tmp_path))))
    assert table2.endswith(f"~{format_duration(parts - collections)}")


def test_the_obstacle_figure_is_priced_at_its_measured_seeds(tmp_path):
    # Measured 2026-12-04: 89.6 and 91 min per seed (one torch thread beside another process).
    part = _part(tmp_path, "obstacle/particle")
    per_seed = estimate_part_seconds(part) / len(part.seeds)
    assert 75 * 60 < per_seed < 105 * 60


def test_an_untrained_part_costs_only_its_evaluations(tmp_path):
    untrained = _part(tmp_path, "table2/sawyer/untrained_fixed").jobs[0]
    online = next(job for job in _part(tmp_path, "table2/sawyer/online_fixed").jobs if job.agent == "ebm")
    evaluation = untrained.eval_episodes * 1000  # 10 episodes of the Sawyer's 1,000 steps
    assert 0 < estimate_job_seconds(untrained) < estimate_job_seconds(online) / 5
    assert estimate_job_seconds(untrained) > evaluation * 0.01  # acting costs at least a hundredth of a second a step


def test_the_listing_names_an_unfinished_directed_collection_once_per_seed(tmp_path):
    from eval.jobs import STATE_FILE
    from eval.pretraining import collection_checkpoint_dir

    part = _part(tmp_path, "table2/sawyer/pretrained_directed")
    job = next(job for job in part.jobs if job.seed == 1)
    folder = collection_checkpoint_dir(job)
    folder.mkdir(parents=True)
    (folder / STATE_FILE).write_text('{"num_timesteps": 30000}')
    text = describe_experiments(make_context("paper", str(tmp_path)), [tmp_path])
    line = next(line for line in text.splitlines() if "table2/sawyer/pretrained_directed " in line)
    # The EBM and Action FF runs of seed 1 share the dataset: it is named once.
    assert line.endswith(f"; resumes the directed dataset of seed 1 at 30000/{job.timesteps}")
