"""docs/results.md from a synthetic results folder, and the claims judged from the numbers."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from eval.jobs import Job
from eval.paper.claims import (
    CLAIMS,
    FAILS,
    HOLDS,
    INCONCLUSIVE,
    MISSING,
    Comparison,
    combine,
    compare_scores,
    evaluate_claims,
    exploration_numbers,
    per_seed_values,
)
from eval.paper.experiments import build_parts, make_context
from eval.paper.parts import Part
from eval.paper.results_doc import collect_cell, main, render_results, write_results
from eval.provenance import append_session, job_fingerprint, write_provenance


def _specs(kind: str):
    """The claims of ``paper.yaml`` of one kind, in order."""
    return [spec for spec in CLAIMS if spec.kind == kind]


DIRECTED_CLAIMS = [spec for spec in _specs("score") if "directed" in spec.text]
CHANGE_CLAIMS = _specs("change")
EXPLORATION_FIGURES = _specs("exploration")[0].comparisons
LEARNING_CONTROL = CLAIMS[-1].text


MACHINE = {"cpu": "Test CPU", "cores": 2, "torch_threads": 1, "gpu": None, "device": "cpu"}


def fake_run(job: Job, score: float, extra: dict | None = None, points: int = 1, fingerprint: str | None = None) -> None:
    """A finished-looking run folder: what run_job writes, with a chosen score."""
    job.run_dir.mkdir(parents=True, exist_ok=True)
    timesteps = np.linspace(job.timesteps / points, job.timesteps, points).astype(int)
    np.savez(
        job.run_dir / "evaluations.npz",
        timesteps=timesteps,
        results=np.full((points, 2), score),
        ep_lengths=np.full((points, 2), 100),
    )
    metrics = {
        "timesteps": job.timesteps,
        "score_mean": score,
        "score_std": 0.0,
        "episode_scores": [score, score],
        "episode_lengths": [100, 100],
        "success_rate": 0.5,
        "extra_evaluations": extra or {},
        "wall_time_s": 600.0,
        "finished_at": "2026-11-20T10:00:00+0000",
        "machine": MACHINE,
        "fingerprint": fingerprint or job_fingerprint(job),
    }
    (job.run_dir / "metrics.json").write_text(json.dumps(metrics))
    write_provenance(job.run_dir, "ebm-eval --experiment table1 -f runs/results")


def parts_of(tmp_path: Path, name: str) -> dict[str, Part]:
    return {p.name: p for p in build_parts([name], make_context("paper", str(tmp_path)))}


def cell(part: Part, agent: str):
    return next(c for c in part.cells if c.agent == agent)


@pytest.fixture
def results(tmp_path):
    """Table 1's particle online cells finished over 3 seeds, EBM ahead; everything else not run."""
    part = parts_of(tmp_path, "table1")["table1/particle/online"]
    for seed, job in enumerate(cell(part, "ebm").jobs):
        fake_run(job, -20.0 - seed, points=3)
    for seed, job in enumerate(cell(part, "action-ff").jobs):
        fake_run(job, -800.0 - 10 * seed, points=3)
    append_session(tmp_path, {"command": "ebm-eval --experiment table1", "started": "2026-11-20T09:00", "machine": MACHINE})
    return tmp_path


def test_the_document_puts_our_numbers_beside_the_papers(results):
    docs = results / "docs" / "results.md"
    text = write_results(results, docs).read_text()
    assert "| online | particle | EBM | -21.00 ± 0.82 | 3 | -21.00 [-22.00, -20.00] | 0.50 | -20.38 |" in text
    assert "| online | particle | Action FF | -810.00 ± 8.16 | 3 |" in text and "| -850.67 |" in text
    # Missing parts say so, with the command that runs exactly them; no number is invented.
    assert "| online | maze | EBM | not run yet | 0/3 | - | - | -162.97 |" in text
    assert "| table1/maze/online | not run yet | `ebm-eval --experiment table1 --part table1/maze/online -f " in text
    assert "Not run yet: `ebm-eval --experiment obstacle --part obstacle/particle -f" in text
    # Provenance of the finished part: command, machine, date, summed wall time.
    row = next(line for line in text.splitlines() if line.startswith("| table1/particle/online |"))
    assert "complete" in row and "`ebm-eval --experiment table1 -f runs/results`" in row
    assert "Test CPU (2 cores, 1 torch threads)" in row and "2026-11-20" in row and row.endswith("| 60 min |")
    # Anchors of the evaluation env, learning curves copied next to the document, the session log.
    assert "| particle (start=(0.0, 0.0), goal=(0.5, 0.5)) | -4.50" in text
    assert (docs.parent / "figures" / "table1_particle_online_learning_curves.png").exists()
    assert "figures/table1_particle_online_learning_curves.png" in text
    assert "## Sessions" in text and "`ebm-eval --experiment table1`" in text
    assert "| ran | skipped | failed | stopped |" in text and text.count("| 0 | 0 | 0 | 0 |") == 1
    assert "- particle: holds (EBM -21.00 [95% CI" in text


def test_runs_of_another_configuration_or_unfinished_ones_do_not_count(tmp_path):
    part = parts_of(tmp_path, "table1")["table1/maze/pretrained"]
    jobs = cell(part, "ebm").jobs
    fake_run(jobs[0], -70.0)
    fake_run(jobs[1], -70.0, fingerprint="0123456789abcdef")  # a run of another configuration
    fake_run(jobs[2], -70.0)
    (jobs[2].run_dir / "evaluations.npz").unlink()  # interrupted
    fake_run(replace(jobs[0], seed=7), -60.0)  # a seed beyond the defaults, same configuration
    result = collect_cell(cell(part, "ebm"))
    assert [job.seed for job, _ in result.runs] == [0, 7]
    assert result.missing_seeds == [1, 2]
    np.testing.assert_array_equal(result.scores, [-70.0, -60.0])


def test_runs_made_with_earlier_library_defaults_are_reported_as_rerun_pending(tmp_path):
    from eval.paper.results_doc import cells_table

    part = parts_of(tmp_path, "table1")["table1/maze/pretrained"]
    jobs = cell(part, "action-ff").jobs
    for job in jobs[:2]:
        fake_run(job, -70.0)
        metrics = json.loads((job.run_dir / "metrics.json").read_text())
        metrics["defaults_digest"] = "0000000000000000"  # made before a default changed
        (job.run_dir / "metrics.json").write_text(json.dumps(metrics))
    result = collect_cell(cell(part, "action-ff"))
    assert result.runs == [] and result.retired == 2
    assert "rerun pending (2 run(s) made with earlier library defaults)" in cells_table([result])
    fake_run(jobs[2], -65.0)  # one seed rerun: its number is shown
    assert "-65.00" in cells_table([collect_cell(cell(part, "action-ff"))])


def test_an_extra_evaluation_stands_for_the_fixed_on_variable_cell(tmp_path):
    fixed = parts_of(tmp_path, "table2")["table2/sawyer/online_fixed"]
    on_variable = parts_of(tmp_path, "fixed_on_variable")["fixed_on_variable/sawyer"]
    for job in cell(fixed, "ebm").jobs:
        fake_run(job, -3800.0, extra={"variable_goal": {"score_mean": -4500.0}})
    assert collect_cell(cell(fixed, "ebm")).scores.tolist() == [-3800.0] * 3
    assert collect_cell(cell(on_variable, "ebm")).scores.tolist() == [-4500.0] * 3


def test_a_figure_is_copied_and_linked(tmp_path):
    part = parts_of(tmp_path, "obstacle")["obstacle/particle"]
    folder = part.figure_dir
    folder.mkdir(parents=True)
    (folder / "paths.png").write_bytes(b"\x89PNG fake")
    figure = {
        "name": "obstacle_generalisation",
        "pngs": [str(folder / "paths.png")],
        "metrics": {"ebm": {"score_mean": -60.0}, "action_ff": {"score_mean": -90.0}},
        "table_md": "| agent | score |\n|---|---|\n| EBM | -60.00 |",
        "command": "ebm-eval --experiment obstacle",
    }
    (folder / "figure.json").write_text(json.dumps(figure))
    write_provenance(folder, "ebm-eval --experiment obstacle", scale="paper", seeds=[0, 1, 2], machine=MACHINE, wall_time_s=60)
    docs = tmp_path / "docs" / "results.md"
    text = render_results(tmp_path, docs)
    assert "Paper: EBM -61.94, Action FF -81.24." in text and "| EBM | -60.00 |" in text
    assert "![obstacle_generalisation: paths](figures/obstacle_particle_paths.png)" in text
    assert (docs.parent / "figures" / "obstacle_particle_paths.png").read_bytes() == b"\x89PNG fake"
    row = next(line for line in text.splitlines() if line.startswith("| obstacle/particle |"))
    assert "complete" in row and "Test CPU" in row and "60 s" in row


def test_the_module_command_writes_the_document(results, capsys):
    docs = results / "out.md"
    assert main(["-f", str(results), "--docs", str(docs)]) == 0
    assert docs.exists() and str(docs) in capsys.readouterr().out


# ---------------------------------------------------------------------------------------------------------- claims
def test_a_comparison_flips_when_the_numbers_flip():
    ahead = compare_scores("particle", "EBM", [-20, -21, -22], "Action FF", [-800, -810, -820])
    behind = compare_scores("particle", "EBM", [-800, -810, -820], "Action FF", [-20, -21, -22])
    assert ahead.verdict == HOLDS and "intervals separate" in ahead.evidence
    assert behind.verdict == FAILS
    close = compare_scores("maze", "EBM", [-10, -30, -20], "Action FF", [-21, -19, -22])
    assert close.verdict == INCONCLUSIVE and "intervals overlap" in close.evidence
    assert compare_scores("maze", "EBM", [-1.0], "Action FF", [-2.0]).evidence.endswith("no interval")
    missing = compare_scores("reacher", "EBM", [], "Action FF", [-40.0])
    assert missing.verdict == MISSING and "EBM not run yet" in missing.evidence
    pending = compare_scores("reacher", "EBM", [-40.0], "Action FF", [], retired=(0, 3))
    assert pending.verdict == MISSING
    assert pending.evidence == "Action FF rerun pending (3 run(s) made with earlier library defaults)"


def test_a_claim_holds_only_when_every_comparison_holds():
    def comparison(verdict):
        return Comparison("env", verdict, "")

    assert combine([comparison(HOLDS), comparison(HOLDS)]) == HOLDS
    assert combine([comparison(HOLDS), comparison(INCONCLUSIVE)]) == INCONCLUSIVE
    assert combine([comparison(INCONCLUSIVE), comparison(MISSING)]) == MISSING
    assert combine([comparison(MISSING), comparison(FAILS), comparison(HOLDS)]) == FAILS
    assert combine([]) == MISSING


def test_claims_follow_the_numbers_they_are_given():
    def lookup(ebm_score: float, ff_score: float, ppo_score: float | None, untrained_score: float | None = -1000.0):
        def scores(key):
            _part, agent, setting = key
            value = {"ebm": ebm_score, "action-ff": ff_score, "ppo": ppo_score, "sac-her": ppo_score}[agent]
            value = untrained_score if setting.startswith("untrained") else value
            return [] if value is None else [value, value - 1, value + 1]

        return scores

    def figures(part):
        numbers = {"mean": 0.9, "per_seed": [0.9, 0.8]}, {"mean": 0.3, "per_seed": [0.3, 0.2]}
        at_budget = {"occupancy_at_ebm_budget": numbers[1]}
        agents = {"ebm": {"coverage": numbers[0], "occupancy": numbers[0]}, "random": {"coverage": numbers[1]}}
        return {"agents": {**agents, "random_uniform": at_budget, "random_joint_targets": at_budget}}

    def verdicts(claims):  # the issue's claims, the exploration claim and the learning control (the last)
        return [c.verdict for c in (*claims[:3], claims[-1])]

    claims = evaluate_claims(lookup(-10.0, -100.0, -50.0), figures)
    assert verdicts(claims) == [HOLDS, HOLDS, HOLDS, HOLDS]
    assert claims[-1].text == LEARNING_CONTROL
    assert claims[-1].comparisons[0].evidence.startswith("EBM -10.00") and "vs untrained EBM -1000.00" in (
        claims[-1].comparisons[0].evidence
    )
    claims = evaluate_claims(lookup(-100.0, -10.0, -500.0), lambda part: None)
    assert verdicts(claims) == [FAILS, HOLDS, MISSING, HOLDS]
    claims = evaluate_claims(lookup(-10.0, -100.0, None, untrained_score=-9.0), lambda part: {"nothing": 1.0})
    assert claims[1].verdict == MISSING and claims[0].verdict == HOLDS
    assert "reports none of agents/ebm/coverage/mean, agents/random/coverage/mean" in claims[2].comparisons[0].evidence
    assert claims[-1].verdict == FAILS  # the untrained agent scores higher: the win is not the learned energy's
    assert evaluate_claims(lookup(-10.0, -100.0, None, untrained_score=None), figures)[-1].verdict == MISSING


def _table2_lookup(cells: dict[tuple[str, str], list[float]]):
    """Per-seed scores of the Table 2 pretrained cells, by (setting, agent); every other cell has not run."""

    def scores(key):
        return cells.get((key[2], key[1]), [])

    return scores


def _sawyer_pretrained(ebm_directed, ebm_sequential, ff_directed, ff_sequential, ebm_random=(-350.0, -340.0, -355.0)):
    return _table2_lookup(
        {
            ("pretrained random", "ebm"): list(ebm_random),
            ("pretrained directed", "ebm"): list(ebm_directed),
            ("pretrained directed + sequential", "ebm"): list(ebm_sequential),
            ("pretrained directed", "action-ff"): list(ff_directed),
            ("pretrained directed + sequential", "action-ff"): list(ff_sequential),
        }
    )


@pytest.mark.parametrize(
    ("ff_sequential", "verdict"),
    [
        ([-900.0, -880.0, -910.0], HOLDS),  # Action FF drops by ~290, the EBM by ~10: the paper's finding
        ([-700.0, -500.0, -900.0], INCONCLUSIVE),  # it drops more on average, but its seeds spread too wide
        ([-500.0, -510.0, -490.0], FAILS),  # it gains more than the EBM does
    ],
)
def test_the_sequential_ablation_compares_the_two_agents_drops(ff_sequential, verdict):
    scores = _sawyer_pretrained([-270.0, -262.0, -280.0], [-258.0, -257.0, -259.0], [-617.0, -600.0, -620.0], ff_sequential)
    claims = {c.text: c for c in evaluate_claims(scores, lambda part: None)}
    change = claims[CHANGE_CLAIMS[0].text]
    assert change.verdict == verdict and change.comparisons[0].label == "sawyer"
    evidence = change.comparisons[0].evidence
    assert evidence.startswith("change from pretrained directed to pretrained directed + sequential: EBM +12.67 [95% CI")
    assert "(-270.67 to -258.00; 3 and 3 seeds)" in evidence
    directed_vs_random, directed_ebm_vs_ff = (claims[spec.text] for spec in DIRECTED_CLAIMS)
    assert directed_vs_random.verdict == HOLDS and directed_ebm_vs_ff.verdict == HOLDS
    assert directed_vs_random.comparisons[0].evidence.startswith("EBM (pretrained directed) -270.67")
    assert "vs EBM (pretrained random) -348.33" in directed_vs_random.comparisons[0].evidence


def test_the_sequential_ablation_waits_for_its_four_cells_and_decides_by_means_below_three_seeds():
    scores = _sawyer_pretrained([-270.0, -262.0], [-258.0], [-617.0], [])
    change = {c.text: c for c in evaluate_claims(scores, lambda part: None)}[CHANGE_CLAIMS[0].text]
    assert change.verdict == MISSING
    assert change.comparisons[0].evidence == "Action FF pretrained directed + sequential not run yet"
    change = {c.text: c for c in evaluate_claims(scores, lambda part: None, lambda key: 1)}[CHANGE_CLAIMS[0].text]
    assert "Action FF pretrained directed + sequential rerun pending (1 run(s)" in change.comparisons[0].evidence
    scores = _sawyer_pretrained([-270.0, -262.0], [-258.0], [-617.0], [-895.0])
    change = {c.text: c for c in evaluate_claims(scores, lambda part: None)}[CHANGE_CLAIMS[0].text]
    assert change.verdict == HOLDS and change.comparisons[0].evidence.endswith("fewer than 3 seeds in a cell, no interval")


def _agents(**agents):
    return {"seeds": [0, 1], "agents": agents}


def test_exploration_compares_at_equal_budget_against_the_strongest_random_explorer():
    maze, sawyer = EXPLORATION_FIGURES
    maze_metrics = _agents(
        ebm={"coverage": {"mean": 0.8, "std": 0.01, "per_seed": [0.79, 0.81]}},
        random={"coverage": {"mean": 0.3, "std": 0.9, "per_seed": [0.2, 0.4]}},
    )
    assert exploration_numbers(maze_metrics, maze) == ("agents/ebm/coverage/mean", 0.8, "agents/random/coverage/mean", 0.3)
    sawyer_metrics = _agents(
        ebm={"occupancy": {"mean": 60.0, "std": 2.0}},
        random_uniform={"occupancy": {"mean": 116.0}, "occupancy_at_ebm_budget": {"mean": 20.0}},
        random_joint_targets={"occupancy": {"mean": 116.0}, "occupancy_at_ebm_budget": {"mean": 70.0}},
    )
    _key, ours, partner, theirs = exploration_numbers(sawyer_metrics, sawyer)
    assert (ours, partner, theirs) == (60.0, "agents/random_joint_targets/occupancy_at_ebm_budget/mean", 70.0)
    claims = evaluate_claims(
        lambda key: [], {"maze_exploration/maze": maze_metrics, "sawyer_exploration/sawyer": sawyer_metrics}.get
    )
    assert [c.verdict for c in claims[2].comparisons] == [HOLDS, FAILS] and claims[2].verdict == FAILS
    assert "no interval" in claims[2].comparisons[0].evidence  # 2 seeds a side: the means decide
    assert "no per-seed values" in claims[2].comparisons[1].evidence


def _sawyer_occupancy(ebm: list[float], uniform: list[float]) -> dict:
    def numbers(values):
        return {"mean": float(np.mean(values)), "std": float(np.std(values)), "per_seed": values}

    return _agents(
        ebm={"occupancy": numbers(ebm)},
        random_uniform={"occupancy": {"mean": 400.0}, "occupancy_at_ebm_budget": numbers(uniform)},
        random_joint_targets={"occupancy": {"mean": 99.0}, "occupancy_at_ebm_budget": numbers([74.0, 70.0, 78.0, 75.0])},
    )


@pytest.mark.parametrize(
    ("ebm", "uniform", "verdict"),
    [
        ([408.0, 236.0, 365.0, 249.0], [300.0, 296.0, 320.0, 332.0], INCONCLUSIVE),  # a higher mean, wide seeds
        ([408.0, 396.0, 415.0, 401.0], [300.0, 296.0, 320.0, 332.0], HOLDS),
        ([208.0, 196.0, 215.0, 201.0], [300.0, 296.0, 320.0, 332.0], FAILS),
    ],
)
def test_exploration_with_per_seed_values_is_judged_by_intervals(ebm, uniform, verdict):
    metrics = _sawyer_occupancy(ebm, uniform)
    assert per_seed_values(metrics, "agents/random_uniform/occupancy_at_ebm_budget/mean") == uniform
    assert per_seed_values(metrics, "agents/random_uniform/occupancy/mean") is None
    claims = evaluate_claims(lambda key: [], {"sawyer_exploration/sawyer": metrics}.get)
    comparison = claims[2].comparisons[1]
    assert comparison.label == "sawyer" and comparison.verdict == verdict
    assert "agents/random_uniform/occupancy_at_ebm_budget/mean" in comparison.evidence  # the strongest random explorer
    assert "[95% CI" in comparison.evidence and "(4 seeds)" in comparison.evidence


def test_a_figure_made_under_earlier_defaults_is_reported_as_rerun_pending(tmp_path):
    part = parts_of(tmp_path, "obstacle")["obstacle/particle"]
    folder = part.figure_dir
    folder.mkdir(parents=True)
    (folder / "figure.json").write_text(json.dumps({"name": "obstacle_generalisation", "table_md": "| old |"}))
    provenance = {"scale": "paper", "seeds": list(part.seeds), "defaults_digest": "0000000000000000"}
    (folder / "provenance.json").write_text(json.dumps({"command": "ebm-eval old", **provenance}))
    text = write_results(tmp_path, tmp_path / "docs" / "results.md").read_text()
    assert "Rerun pending (the figure was made with earlier library defaults): `ebm-eval --experiment obstacle" in text
    assert "| old |" not in text
    assert "Seeds already made" not in text  # none kept yet

    from eval.paper.figures.common import figure_digest

    (folder / "seeds").mkdir()
    current = figure_digest("obstacle_generalisation")
    for seed, digest in ((0, current), (1, "0000000000000000"), (2, current), (7, current)):
        record = {"seed": seed, "defaults_digest": digest}
        (folder / "seeds" / f"obstacle_generalisation_seed{seed}.json").write_text(json.dumps(record))
    text = write_results(tmp_path, tmp_path / "docs" / "results.md").read_text()
    # Seed 1 was made under other defaults and seed 7 is not one of the part's: neither counts.
    assert "Seeds already made under today's defaults and kept for it: 0, 2 (of 0, 1, 2)." in text


def test_a_claim_names_the_runs_that_wait_for_a_rerun(results):
    part = parts_of(results, "table1")["table1/particle/online"]
    for job in cell(part, "action-ff").jobs:
        metrics = json.loads((job.run_dir / "metrics.json").read_text())
        metrics["defaults_digest"] = "0000000000000000"  # made before a default changed
        (job.run_dir / "metrics.json").write_text(json.dumps(metrics))
    text = write_results(results, results / "docs" / "results.md").read_text()
    expected = "  - particle: not measured (Action FF rerun pending (3 run(s) made with earlier library defaults))"
    assert expected in text


def test_a_comparison_that_does_not_hold_carries_its_reason_and_one_that_holds_none():
    from eval.paper.claims import render_claims

    def lookup(ebm: float):
        def scores(key):
            if key[0] == "table1/reacher/online":
                return [ebm, ebm - 1, ebm - 2] if key[1] == "ebm" else [-25.0, -26.0, -27.0]
            return []

        return scores

    failing = render_claims(evaluate_claims(lookup(-45.0), lambda part: None))
    assert f"  - reacher: {FAILS} (" in failing and "). Why: online, the EBM stays near" in failing
    holding = render_claims(evaluate_claims(lookup(-5.0), lambda part: None))
    assert f"  - reacher: {HOLDS} (" in holding and "Why:" not in holding  # a verdict is never written down
    particle = evaluate_claims(lookup(-45.0), lambda part: None)[0].comparisons[0]
    assert particle.label == "particle" and particle.why is None


def test_the_model_quality_table_shows_the_probe_of_the_runs_that_recorded_it(tmp_path):
    from eval.paper.results_doc import quality_table

    part = parts_of(tmp_path, "table1")["table1/maze/pretrained"]
    assert quality_table([collect_cell(cell(part, "ebm"))]) is None  # nothing run yet
    for job, auroc in zip(cell(part, "ebm").jobs, (0.8, 0.9, 1.0)):
        fake_run(job, -70.0)
        metrics = json.loads((job.run_dir / "metrics.json").read_text())
        metrics["model_quality"] = {"feasibility_auroc": auroc, "next_state_rank": 0.5, "next_state_mean_rank": 0.25}
        (job.run_dir / "metrics.json").write_text(json.dumps(metrics))
    table = quality_table([collect_cell(cell(part, "ebm")), collect_cell(cell(part, "action-ff"))])
    assert table is not None and len(table.splitlines()) == 3  # header, rule, the EBM's row only
    row = table.splitlines()[-1]
    assert "| 3 | 0.900 ± 0.082 | - | 0.500 ± 0.000 | 0.250 ± 0.000 |" in row  # no uniform AUROC recorded: "-"
