"""Agent presets in the harness: the paper's rows keep their recorded runs, the fast preset gets rows of its own."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from ebm_agent import EBMPlannerAgent
from ebm_agent.config import OnlineConfig, make_config
from ebm_agent.presets import PAPER_EBM
from eval.cli import build_jobs, resolve_settings
from eval.digest import class_defaults
from eval.flags import build_parser
from eval.jobs import Job
from eval.paper.experiments import build_parts, make_context
from eval.paper.figures.common import figure_digest
from eval.pretraining import collector_settings
from eval.provenance import agent_defaults_digest, defaults_digest, job_fingerprint
from eval.run import agent_settings

RECORDS = Path(__file__).resolve().parents[2] / "docs" / "records"


def test_every_recorded_table_run_is_current_under_the_paper_preset(tmp_path: Path) -> None:
    """The records were made before presets existed, with what is now the paper preset: they must all stay current
    (same fingerprint, same defaults digest), while the same jobs under the fast preset would not be. The fast rows
    were recorded while the fast budgets were the library's defaults: they must be current under the fast preset."""
    parts = build_parts(["all"], make_context("paper", str(tmp_path)))
    jobs = {job.run_dir.relative_to(tmp_path): job for part in parts for cell in part.cells for job in cell.jobs}
    checked = 0
    for metrics_path in sorted(RECORDS.glob("**/seed_*/metrics.json")):
        relative = metrics_path.parent.relative_to(RECORDS)
        if relative not in jobs:
            continue
        job, metrics = jobs[relative], json.loads(metrics_path.read_text())
        assert metrics["fingerprint"] == job_fingerprint(job), relative
        assert metrics["defaults_digest"] == defaults_digest(job), relative
        if job.agent in ("ebm", "action-ff"):
            # The fast preset's own rows (variant *_defaults) and the later cells that ask for it (preset: fast)
            # are current under the fast preset; every other row under the paper's. Under the other preset, none is.
            # The third-party rows (issue 46) are the library's defaults' (preset ""), as users get them.
            allowed = ("", "paper", "fast") if job.variant.startswith("third_party_") else ("paper", "fast")
            assert job.preset == "fast" if job.variant.endswith("_defaults") else job.preset in allowed, relative
            other = "paper" if job.preset == "fast" else "fast"
            assert defaults_digest(replace(job, preset=other)) != metrics["defaults_digest"], relative
        checked += 1
    assert checked >= 100  # Tables 1 and 2 and the ablations: 150 runs were recorded


def test_fast_rows_run_the_fast_preset_in_their_own_folders(tmp_path: Path) -> None:
    parts = {part.name: part for part in build_parts(["table1", "table2"], make_context("paper", str(tmp_path)))}
    for name in ("table1/particle/online", "table1/maze/online", "table1/reacher/online", "table2/sawyer/online_fixed"):
        paper, fresh = parts[name], parts[name + "_fast"]
        assert [cell.agent for cell in fresh.cells] == ["ebm", "action-ff"]
        for old, new in zip(paper.cells, fresh.cells, strict=True):
            assert {job.preset for job in old.jobs} == {"paper"} and {job.preset for job in new.jobs} == {"fast"}
            assert {job.run_dir for job in old.jobs}.isdisjoint(job.run_dir for job in new.jobs)
            assert [job.timesteps for job in old.jobs] == [job.timesteps for job in new.jobs] == [50_000] * 3
    variable = parts["table2/sawyer/online_variable_fast"].cells[0].jobs[0]
    assert variable.env_kwargs == {"goal": "variable"} and variable.variant == "online_variable_goal_defaults"


def test_the_preset_reaches_the_agent_the_collector_and_the_digest() -> None:
    job = Job("ebm/Particle-v0", "ebm", 0, 100, 50, 1, hyperparams={"planner_config": {"num_samples": 8}}, preset="paper")
    settings = agent_settings(job)
    assert settings["planner_config"] == {**PAPER_EBM["planner_config"], "num_samples": 8}
    assert agent_settings(replace(job, preset="")) == {"planner_config": {"num_samples": 8}}
    assert agent_settings(replace(job, preset="fast"))["planner_config"]["warm_iterations"] == 3
    assert agent_settings(replace(job, agent="ppo", hyperparams={})) == {}  # PPO has no preset
    directed = replace(job, mode="pretrained", dataset="directed", dataset_kwargs={"horizon": 5})
    assert collector_settings(directed) == {**PAPER_EBM, "horizon": 5}
    assert job_fingerprint(job) == job_fingerprint(replace(job, preset="fast"))  # the digest tells them apart
    assert defaults_digest(job) != defaults_digest(replace(job, preset="fast"))
    # The defaults departed from the paper (evaluation goal weight 10); the paper preset keeps the recorded digest.
    assert defaults_digest(job) != defaults_digest(replace(job, preset=""))
    assert agent_defaults_digest("ebm", "ebm/Particle-v0", "paper") == "89db7682350f5b22"
    assert agent_defaults_digest("ebm", "ebm/Particle-v0", "fast") == "22984ac86eb5780c"
    assert agent_defaults_digest("ppo", "ebm/Particle-v0", "paper") == agent_defaults_digest("ppo", "ebm/Particle-v0")
    with pytest.raises(ValueError, match=r"Job\.preset"):
        replace(job, preset="faster")


def test_figures_are_digested_under_the_paper_preset() -> None:
    checked = 0
    for provenance in sorted(RECORDS.glob("figures/*/provenance.json")):
        recorded = json.loads(provenance.read_text()).get("defaults_digest")
        figure = provenance.parent.name
        if recorded is None or figure_digest(figure) is None:
            continue
        assert recorded == figure_digest(figure), figure
        checked += 1
    assert checked >= 1


def test_cli_preset_flag(tmp_path: Path) -> None:
    args = build_parser().parse_args(["--preset", "fast", "--timesteps", "100", "-f", str(tmp_path)])
    jobs = build_jobs(resolve_settings(args), progress=False)
    assert {job.preset for job in jobs} == {"fast"}
    plain = build_jobs(resolve_settings(build_parser().parse_args(["-f", str(tmp_path)])), progress=False)
    assert {job.preset for job in plain} == {""}


def test_no_loss_comparison_reads_the_reference_interval() -> None:
    from eval.paper.claims import CLAIMS, FAILS, HOLDS, MISSING, compare_no_loss

    paper = [-10.0, -10.5, -9.5]
    assert compare_no_loss("env", "new", [-10.2, -9.9, -10.1], "paper", paper).verdict == HOLDS
    above = compare_no_loss("env", "new", [-5.0], "paper", paper)
    assert above.verdict == HOLDS and "above the interval" in above.evidence
    below = compare_no_loss("env", "new", [-12.0, -12.5, -11.8], "paper", paper)
    assert below.verdict == FAILS and "below" in below.evidence
    assert compare_no_loss("env", "new", [], "paper", paper).verdict == MISSING
    # Fewer than 3 reference seeds: the lowest reference seed is the bar.
    assert compare_no_loss("env", "new", [-10.4], "paper", [-10.5, -9.5]).verdict == HOLDS
    assert compare_no_loss("env", "new", [-10.6], "paper", [-10.5, -9.5]).verdict == FAILS
    claim = next(spec for spec in CLAIMS if spec.kind == "no_loss" and "fast preset" in spec.text)
    assert len(claim.comparisons) == 10  # 5 online settings x (EBM, Action FF)
    assert all(item.cells[0][0] == item.cells[1][0] + "_fast" for item in claim.comparisons)
    graph = next(spec for spec in CLAIMS if spec.kind == "no_loss" and "graph subgoals" in spec.text)
    assert [item.label for item in graph.comparisons] == ["particle", "reacher", "sawyer"]


def test_a_removed_setting_fails_naming_why_and_the_digest_still_counts_it() -> None:
    with pytest.raises(TypeError, match=r"online\.adaptive_iterations: the original's adaptive planning budget .* removed"):
        make_config(OnlineConfig, {"adaptive_iterations": False}, "online")
    online = class_defaults(EBMPlannerAgent)["online:OnlineConfig"]
    # the recorded runs were made with the rule off: their digest holds the removed fields at those values
    assert {k: online[k] for k in ("adaptive_iterations", "adapt_every", "max_iterations")} == {
        "adaptive_iterations": False,
        "adapt_every": 10,
        "max_iterations": 800,
    }
