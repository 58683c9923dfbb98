"""results.csv, results.md and learning-curve PNGs from hand-made JobResults (no training)."""

from __future__ import annotations

import csv
import dataclasses

import numpy as np
import pytest

from eval.anchors import EnvAnchors
from eval.jobs import Job, JobResult
from eval.plots import aggregate_curves, load_curve, plot_learning_curves
from eval.report import CSV_COLUMNS, render_markdown, summarize, write_csv, write_markdown


def _result(out_dir, agent: str, seed: int, scores: list[float], timesteps: int = 1000, success=0.5) -> JobResult:
    job = Job("ebm/Particle-v0", agent, seed, timesteps=1000, eval_freq=500, eval_episodes=len(scores), out_dir=str(out_dir))
    return JobResult(
        job=job,
        status="ok",
        timesteps=timesteps,
        score_mean=float(np.mean(scores)),
        score_std=float(np.std(scores)),
        episode_scores=tuple(scores),
        episode_lengths=tuple(100 for _ in scores),
        success_rate=success,
        wall_time_s=1.25,
    )


def _failed(out_dir, agent: str, seed: int) -> JobResult:
    job = Job("ebm/Particle-v0", agent, seed, timesteps=1000, eval_freq=500, eval_episodes=2, out_dir=str(out_dir))
    return JobResult(job=job, status="failed", error="Traceback (most recent call last):\nRuntimeError: boom\n")


@pytest.fixture
def results(tmp_path):
    return [
        # EBM, 3 seeds: per-seed means -5, -6, -7 -> mean -6, population std sqrt(2/3).
        _result(tmp_path, "ebm", 0, [-4.0, -6.0]),
        _result(tmp_path, "ebm", 1, [-6.0, -6.0]),
        _result(tmp_path, "ebm", 2, [-7.0, -7.0], success=None),
        # PPO, 2 seeds + 1 failure; seed 1 used fewer transitions.
        _result(tmp_path, "ppo", 0, [-50.0, -30.0], success=0.0),
        _result(tmp_path, "ppo", 1, [-20.0, -20.0], timesteps=996, success=0.0),
        _failed(tmp_path, "ppo", 2),
    ]


def test_summary_numbers_by_hand(results):
    ebm, ppo = summarize(results)
    assert (ebm.env, ebm.agent, ebm.seeds, ebm.failed) == ("particle", "ebm", (0, 1, 2), ())
    assert ebm.seed_mean == pytest.approx(-6.0)
    assert ebm.seed_std == pytest.approx(np.sqrt(2 / 3))
    # Pooled episodes -4, -6, -6, -6, -7, -7: mean -6, population std sqrt((4 + 0 + 0 + 0 + 1 + 1) / 6) = 1.
    assert ebm.episode_mean == pytest.approx(-6.0)
    assert ebm.episode_std == pytest.approx(1.0)
    assert ebm.iqm == pytest.approx(-6.0)  # 3 seeds: nothing trimmed
    assert ebm.iqm_ci is not None and ebm.iqm_ci[0] <= -6.0 <= ebm.iqm_ci[1]
    assert ebm.iqm_ci[0] >= -7.0 and ebm.iqm_ci[1] <= -5.0
    assert ebm.success_rate == pytest.approx(0.5)  # the seed without a success flag is left out
    assert ebm.steps_used == (1000, 1000)
    # Fewer than 3 finished seeds: no IQM.
    assert ppo.seeds == (0, 1) and ppo.failed == (2,)
    assert ppo.seed_mean == pytest.approx(-30.0) and ppo.seed_std == pytest.approx(10.0)
    assert ppo.iqm is None and ppo.iqm_ci is None
    assert ppo.steps_used == (996, 1000)


def test_csv_has_one_row_per_run_and_the_required_columns(results, tmp_path):
    path = write_csv(results, tmp_path / "results.csv")
    with open(path, newline="") as file:
        rows = list(csv.DictReader(file))
    assert tuple(rows[0].keys()) == CSV_COLUMNS
    for required in ("env", "agent", "seed", "timesteps", "score_mean", "score_std", "success_rate"):
        assert required in rows[0]
    assert len(rows) == len(results)
    assert rows[0]["env"] == "particle" and rows[0]["agent"] == "ebm" and rows[0]["seed"] == "0"
    assert float(rows[0]["score_mean"]) == pytest.approx(-5.0)
    assert float(rows[0]["score_std"]) == pytest.approx(1.0)
    assert rows[2]["success_rate"] == ""
    assert rows[4]["timesteps"] == "996"
    assert rows[5]["status"] == "failed" and rows[5]["error"] == "RuntimeError: boom"
    assert rows[5]["score_mean"] == ""


def test_markdown_table_anchors_failures_and_command(results, tmp_path):
    anchors = {"particle": EnvAnchors("ebm/Particle-v0", -4.5, "original_code.md §6", -105.5, 33.9, 10, -100.0)}
    text = write_markdown(results, tmp_path / "results.md", anchors, ["ebm-eval", "--baseline", "ppo"])
    assert (tmp_path / "results.md").read_text() == text
    table_rows = [line for line in text.splitlines() if line.startswith("| particle |")]
    ebm_row, ppo_row, anchor_row = table_rows
    assert "| ebm | 3 | -6.00 ± 0.82 | -6.00 ± 1.00 | -6.00 [" in ebm_row
    assert "| 1000 / 1000 |" in ebm_row
    assert "| ppo | 2 (1 failed) | -30.00 ± 10.00 |" in ppo_row
    assert "| - |" in ppo_row  # no IQM below 3 seeds
    assert "996-1000 / 1000" in ppo_row
    assert "-4.50" in anchor_row and "-105.50 ± 33.90" in anchor_row and "-100.00" in anchor_row
    assert "ppo / seed 2: RuntimeError: boom" in text
    assert "ebm-eval --baseline ppo" in text


def test_markdown_of_only_failed_runs_does_not_crash(tmp_path):
    text = render_markdown([_failed(tmp_path, "ebm", 0)])
    assert "| particle | ebm | 0 (1 failed) | - |" in text


def test_a_stopped_run_is_counted_apart_from_the_failed_ones(tmp_path):
    stopped = dataclasses.replace(_failed(tmp_path, "ebm", 1), status="stopped", error="run x stopped by SIGTERM at 5/10")
    (summary,) = summarize([_failed(tmp_path, "ebm", 0), stopped])
    assert (summary.failed, summary.stopped) == ((0,), (1,))
    text = render_markdown([_failed(tmp_path, "ebm", 0), stopped])
    assert "| particle | ebm | 0 (1 failed, 1 stopped) | - |" in text
    assert "ebm / seed 1: stopped: run x stopped by SIGTERM at 5/10" in text


def _write_npz(result: JobResult, timesteps, results) -> None:
    result.run_dir.mkdir(parents=True, exist_ok=True)
    np.savez(
        result.run_dir / "evaluations.npz",
        timesteps=np.asarray(timesteps),
        results=np.asarray(results),
        ep_lengths=np.full(np.shape(results), 100),
    )


def test_curves_load_and_aggregate_by_hand(results):
    _write_npz(results[0], [500, 1000], [[-10.0, -20.0], [-4.0, -6.0]])
    timesteps, means = load_curve(results[0].run_dir / "evaluations.npz")
    np.testing.assert_allclose(timesteps, [500, 1000])
    np.testing.assert_allclose(means, [-15.0, -5.0])
    grid, mean, low, high = aggregate_curves([(timesteps, means), (np.array([500.0, 1000.0]), np.array([-25.0, -7.0]))])
    np.testing.assert_allclose(grid, [500, 1000])
    np.testing.assert_allclose(mean, [-20.0, -6.0])
    np.testing.assert_allclose(low, [-25.0, -7.0])
    np.testing.assert_allclose(high, [-15.0, -5.0])


def test_learning_curve_png_is_written(results, tmp_path):
    for k, result in enumerate(results):
        if result.ok:
            _write_npz(result, [500, 1000], [[-10.0 - k, -20.0], [-4.0, -6.0 + k]])
    anchors = {"particle": EnvAnchors("ebm/Particle-v0", -4.5, "src", -105.5, 33.9, 10, -100.0)}
    (path,) = plot_learning_curves(results, tmp_path, anchors)
    assert path == tmp_path / "learning_curves_particle.png"
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000


def test_load_curve_rejects_a_file_not_in_sb3_format(tmp_path):
    np.savez(tmp_path / "bad.npz", timesteps=np.array([1, 2, 3]), results=np.zeros((2, 4)), ep_lengths=np.zeros((2, 4)))
    with pytest.raises(ValueError, match="SB3's format"):
        load_curve(tmp_path / "bad.npz")


def test_one_markdown_table_writer_formats_every_table():
    from eval.report import markdown_table

    table = markdown_table(["a", "b", "c"], [[1.234, None, "x"], [2, 0.5, ""]], missing="—")
    assert table.splitlines() == ["| a | b | c |", "|---|---|---|", "| 1.23 | — | x |", "| 2 | 0.50 |  |"]
    assert markdown_table(["a"], [[None]]).splitlines()[-1] == "| - |"
