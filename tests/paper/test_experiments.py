"""The experiment registry, pretrained jobs, resumable parts and `ebm-eval --experiment` (smoke budgets only)."""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from eval.cli import main
from eval.digest import class_defaults, env_inverse_dynamics_defaults, neutral_settings
from eval.jobs import Job, JobResult
from eval.paper.experiments import EXPERIMENTS, build_parts, make_context, select_parts
from eval.paper.figures.common import figure_complete
from eval.paper.parts import SCALES, Part, make_cell
from eval.paper.runner import run_parts, unique_jobs
from eval.pretraining import dataset_path, repeat_transitions
from eval.provenance import completed_result, defaults_digest, job_fingerprint, read_provenance, read_sessions
from eval.registry import AGENTS
from eval.run import run_job

pytest.importorskip("envs.particle")

RUN_FILES = {"config.yaml", "evaluations.npz", "metrics.json", "model.zip"}


def paper_parts(tmp_path: Path, names=("all",)) -> list[Part]:
    return build_parts(list(names), make_context("paper", str(tmp_path)))


def test_every_experiment_builds_with_the_paper_budgets(tmp_path):
    parts = paper_parts(tmp_path)
    assert {part.experiment for part in parts} == set(EXPERIMENTS)
    for job in unique_jobs(parts):  # also: no run folder gets two configurations
        assert job.eval_episodes == 10 and job.seed in (0, 1, 2, 3, 4)
        if job.mode == "pretrained":
            assert job.timesteps == 100_000
        elif job.mode == "untrained":
            assert job.timesteps == 0 and job.agent == "ebm"
        elif job.variant.startswith("third_party_"):  # issue 46's budgets: 5,000 and 10,000 on FetchReach
            assert job.timesteps == {"5k": 5_000, "10k": 10_000, "50k": 50_000}[job.variant.split("_")[2]]
        elif job.agent != "ppo":
            assert job.timesteps == 50_000
    for part in parts:
        assert part.seeds == ((0, 1, 2, 3) if part.figure == "sawyer_exploration" else (0, 1, 2))
        for cell in part.cells:  # the follow rows of beyond_maze name 5 seeds of their own
            key = cell.key or ""
            five = key.startswith(("explore_follow", "explore_real_follow")) and not key.endswith("_untrained")
            assert len(cell.jobs) == (5 if five else 3)


def test_paper_numbers_sit_beside_the_cells(tmp_path):
    cells = {(p.name, c.agent, c.setting): c for p in paper_parts(tmp_path) for c in p.cells}
    assert len(cells) == sum(len(p.cells) for p in paper_parts(tmp_path))  # the keys the claims use are unique
    assert cells[("table1/particle/pretrained", "ebm", "pretrained")].paper == -5.14
    assert cells[("table1/maze/online", "action-ff", "online")].paper == -949.99
    assert cells[("table1/reacher/online", "ebm", "online")].paper == -29.87
    assert (
        cells[("table2/sawyer/pretrained_directed_sequential", "action-ff", "pretrained directed + sequential")].paper
        == -12838
    )
    assert cells[("table2/sawyer/online_variable", "ebm", "online variable")].paper == -3907
    assert cells[("sawyer_ppo/1x", "ppo", "PPO 1x")].paper == -9300
    assert cells[("inverse_dynamics/sawyer", "ebm", "ground truth")].paper == -3782
    assert cells[("inverse_dynamics/sawyer", "ebm", "RLS")].paper == -4694
    assert cells[("fixed_on_variable/sawyer", "ebm", "trained fixed, evaluated variable")].paper == -4547
    from eval.paper.claims import CLAIMS, cell_keys

    for claim in CLAIMS:  # every claim names cells that exist
        for comparison in claim.comparisons:
            assert all(cell in cells for cell in comparison.cells)
    ids = {c.id: (p.name, c.agent, c.setting) for p in paper_parts(tmp_path) for c in p.cells}
    assert ids == cell_keys()  # a cell's id in paper.yaml is the one its Cell carries
    obstacle = next(p for p in paper_parts(tmp_path, ["obstacle"]))
    assert obstacle.paper == {"EBM": -61.94, "Action FF": -81.24}


def test_cells_configure_their_runs(tmp_path):
    parts = {p.name: p for p in paper_parts(tmp_path)}
    particle = parts["table1/particle/online"].cells[0].jobs[0]
    assert particle.eval_env_kwargs == {"start": (0.0, 0.0), "goal": (0.5, 0.5)} and particle.env_kwargs == {}
    assert [c.jobs[0].timesteps for p in ("1x", "5x", "10x") for c in parts[f"sawyer_ppo/{p}"].cells] == [
        50_000,
        250_000,
        500_000,
    ]
    datasets = [c.jobs[0].dataset for c in parts["table2/sawyer/pretrained_directed_sequential"].cells]
    assert datasets == ["directed+sequential"] * 2
    variable = parts["table2/sawyer/online_variable"].cells[0].jobs[0]
    assert variable.env_kwargs == {"goal": "variable"} == variable.eval_env_kwargs
    cells = parts["inverse_dynamics/particle"].cells
    kinds = [c.jobs[0].hyperparams.get("inverse_dynamics") for c in cells]
    assert kinds == [None, "mlp", "rls", "mlp", "mlp", "mlp"]
    assert [c.jobs[0].mode for c in cells] == ["online", "online", "online", "untrained", "online", "untrained"]  # + controls
    # The fixed-on-variable evaluation reads the very runs of Table 2's online fixed-goal cells.
    fixed = parts["table2/sawyer/online_fixed"].cells
    on_variable = parts["fixed_on_variable/sawyer"].cells
    assert [c.jobs for c in on_variable] == [c.jobs for c in fixed]
    assert all(c.evaluation == "variable_goal" for c in on_variable)
    assert fixed[0].jobs[0].extra_evaluations == {"variable_goal": {"goal": "variable"}}
    # The untrained controls: the EBM of the same env configuration, budget 0, no paper number.
    for name, online, untrained in (
        ("table1/reacher/untrained", parts["table1/reacher/online"], parts["table1/reacher/untrained"]),
        ("table2/sawyer/untrained_fixed", parts["table2/sawyer/online_fixed"], parts["table2/sawyer/untrained_fixed"]),
        (
            "table2/sawyer/untrained_variable",
            parts["table2/sawyer/online_variable"],
            parts["table2/sawyer/untrained_variable"],
        ),
    ):
        (cell,) = untrained.cells
        trained = next(c for c in online.cells if c.agent == "ebm").jobs[0]
        job = cell.jobs[0]
        assert (cell.agent, cell.paper, job.mode, job.timesteps) == ("ebm", None, "untrained", 0), name
        assert cell.setting == ("untrained" if name.startswith("table1") else name.split("/")[-1].replace("_", " "))
        assert (job.env_kwargs, job.eval_env_kwargs, job.hyperparams) == (
            trained.env_kwargs,
            trained.eval_env_kwargs,
            trained.hyperparams,
        ), name
        assert job.run_dir != trained.run_dir


def test_part_globs_and_unknown_names(tmp_path):
    parts = paper_parts(tmp_path)
    assert [p.name for p in select_parts(parts, ["table1/particle/*"])] == [
        "table1/particle/pretrained",
        "table1/particle/online",
        "table1/particle/online_fast",
        "table1/particle/untrained",
    ]
    sawyer = {p.name for p in select_parts(parts, ["*/sawyer*"])}
    assert "table2/sawyer/online_fixed" in sawyer and "sawyer_exploration/sawyer" in sawyer
    assert "table1/maze/online" not in sawyer
    assert len(select_parts(parts, None)) == len(parts)
    with pytest.raises(ValueError, match="matches no part"):
        select_parts(parts, ["table9/*"])
    with pytest.raises(ValueError, match="unknown experiment"):
        build_parts(["table9"], make_context("paper", str(tmp_path)))
    with pytest.raises(ValueError, match="unknown scale"):
        make_context("huge", str(tmp_path))


def test_smoke_runs_live_apart_from_paper_runs(tmp_path):
    smoke = build_parts(["table1"], make_context("smoke", str(tmp_path)))
    paper = paper_parts(tmp_path, ["table1"])
    assert all(job.run_dir.relative_to(tmp_path).parts[0] == "smoke" for p in smoke for job in p.jobs)
    assert not {j.run_dir for p in smoke for j in p.jobs} & {j.run_dir for p in paper for j in p.jobs}
    assert SCALES["smoke"].online < 100 and smoke[0].command().endswith("--scale smoke")


def test_a_cell_can_name_its_own_seeds_per_scale(tmp_path):
    """The follow rows of beyond_maze run 5 seeds at the paper's scale, the scale's seeds elsewhere; --seeds wins."""
    paper = select_parts(paper_parts(tmp_path, ["beyond_maze"]), ["beyond_maze/online"])[0]
    seeds = {cell.key: [job.seed for job in cell.jobs] for cell in paper.cells}
    assert seeds["explore_follow"] == seeds["explore_real_follow_pair3"] == [0, 1, 2, 3, 4]
    assert seeds["explore_anneal"] == [0, 1, 2]
    assert paper.seeds == (0, 1, 2) and "--seeds" not in paper.command()
    smoke = select_parts(build_parts(["beyond_maze"], make_context("smoke", str(tmp_path))), ["beyond_maze/online"])[0]
    assert {len(cell.jobs) for cell in smoke.cells} == {1}
    chosen = select_parts(build_parts(["beyond_maze"], make_context("paper", str(tmp_path), [3])), ["beyond_maze/online"])
    assert {job.seed for job in chosen[0].jobs} == {3}


@pytest.mark.parametrize(
    ("seeds", "message"),
    [
        ({"papr": [0, 1]}, "unknown scales \\['papr'\\]"),
        ({"paper": []}, "non-empty list of seeds"),
        ({"paper": [0, 0]}, "distinct non-negative integers"),
        ({"paper": [-1]}, "distinct non-negative integers"),
        ({"paper": 5}, "non-empty list of seeds"),
    ],
)
def test_bad_cell_seeds_name_the_cell(tmp_path, seeds, message):
    context = make_context("paper", str(tmp_path))
    with pytest.raises(ValueError, match=message):
        make_cell(context, "a row", "particle", "ebm", "v", seeds=seeds, part="p/q")


# ------------------------------------------------------------------------------------------------ pretrained jobs
def _smoke_job(tmp_path: Path, **overrides) -> Job:
    part = next(p for p in build_parts(["table1"], make_context("smoke", str(tmp_path))) if p.name.endswith("particle/online"))
    return replace(part.cells[0].jobs[0], **overrides)


def test_a_pretrained_job_writes_the_same_files_as_an_online_one(tmp_path):
    online = run_job(_smoke_job(tmp_path))
    pretrained_job = _smoke_job(tmp_path, mode="pretrained", variant="smoke/pretrained_random")
    pretrained_job = replace(pretrained_job, offline_kwargs={"epochs": 1, "batch_size": 16})
    pretrained = run_job(pretrained_job)
    assert online.ok and pretrained.ok, (online.error, pretrained.error)
    assert {p.name for p in pretrained.run_dir.iterdir()} >= RUN_FILES
    assert {p.name for p in online.run_dir.iterdir()} >= RUN_FILES
    metrics = json.loads((pretrained.run_dir / "metrics.json").read_text())
    assert metrics["mode"] == "pretrained" and metrics["timesteps"] == pretrained_job.timesteps == 40
    assert metrics["pretraining"]["dataset_size"] == 40 and metrics["pretraining"]["gradient_steps"] == 3
    assert metrics["fingerprint"] == job_fingerprint(pretrained_job)
    assert metrics["defaults_digest"] == defaults_digest(pretrained_job) is not None
    with np.load(pretrained.run_dir / "evaluations.npz") as data:
        np.testing.assert_array_equal(data["timesteps"], [40])
        np.testing.assert_allclose(data["results"][-1], pretrained.episode_scores)
    assert dataset_path(pretrained_job).exists()  # cached for the Action FF job of the same seed
    assert completed_result(pretrained_job) == pretrained


def test_a_directed_dataset_and_an_extra_evaluation(tmp_path):
    job = _smoke_job(
        tmp_path,
        agent="action-ff",
        mode="pretrained",
        dataset="directed+sequential",
        offline_kwargs={"epochs": 1, "batch_size": 16, "repeat": 3},
        dataset_kwargs={"planner_config": {"iterations": 2, "num_samples": 8}},
        extra_evaluations={"far_goal": {"goal": [-0.5, -0.5]}},
        variant="smoke/pretrained_directed_sequential",
    )
    result = run_job(job)
    assert result.ok, result.error
    metrics = json.loads((job.run_dir / "metrics.json").read_text())
    assert metrics["pretraining"]["repeat"] == 3 and metrics["pretraining"]["sequential"]
    assert metrics["pretraining"]["gradient_steps"] == 8  # ceil(40 * 3 / 16)
    assert metrics["pretraining"]["dataset_info"]["policy"] == "directed"
    extra = metrics["extra_evaluations"]["far_goal"]
    assert extra["env_kwargs"]["goal"] == [-0.5, -0.5] and len(extra["episode_scores"]) == job.eval_episodes


def test_ppo_cannot_be_pretrained(tmp_path):
    result = run_job(_smoke_job(tmp_path, agent="ppo", mode="pretrained", hyperparams={}))
    assert not result.ok and "cannot be pretrained" in (result.error or "")


def test_repeat_transitions_keeps_copies_adjacent(tmp_path):
    from ebm_agent.datasets import TransitionDataset

    data = TransitionDataset(np.arange(6.0).reshape(3, 2), np.ones((3, 2)), np.zeros((3, 1)), np.arange(3))
    repeated = repeat_transitions(data, 2)
    np.testing.assert_array_equal(repeated.states[:, 0], [0, 0, 2, 2, 4, 4])
    with pytest.raises(ValueError, match=r"Job\.mode"):
        _smoke_job(tmp_path, mode="offline")


# ---------------------------------------------------------------------------------------------------------- resume
class FakeExecutor:
    """Writes a finished-looking run folder for each job instead of training, and counts the jobs."""

    def __init__(self) -> None:
        self.ran: list[Job] = []

    def map(self, jobs, progress=True):
        results = []
        for job in jobs:
            self.ran.append(job)
            job.run_dir.mkdir(parents=True, exist_ok=True)
            np.savez(job.run_dir / "evaluations.npz", timesteps=[job.timesteps], results=[[-1.0]], ep_lengths=[[5]])
            metrics = {
                "timesteps": job.timesteps,
                "score_mean": -1.0,
                "score_std": 0.0,
                "episode_scores": [-1.0],
                "episode_lengths": [5],
                "fingerprint": job_fingerprint(job),
            }
            (job.run_dir / "metrics.json").write_text(json.dumps(metrics))
            results.append(JobResult(job=job, status="ok", timesteps=job.timesteps, score_mean=-1.0))
        return results


def test_resume_skips_complete_jobs_and_reruns_incomplete_ones(tmp_path):
    parts = select_parts(
        build_parts(["table1"], make_context("smoke", str(tmp_path))), ["table1/particle/pretrained", "table1/particle/online"]
    )
    executor, messages = FakeExecutor(), []
    first = run_parts(parts, executor, "ebm-eval first", progress=False, log=messages.append)
    assert first.ok and len(executor.ran) == 4 and not first.skipped
    assert read_provenance(executor.ran[0].run_dir)["command"] == "ebm-eval first"

    executor.ran.clear()
    (parts[1].jobs[0].run_dir / "metrics.json").unlink()  # interrupted run
    stale = parts[1].jobs[1]
    (stale.run_dir / "metrics.json").write_text(
        json.dumps({**json.loads((parts[0].jobs[0].run_dir / "metrics.json").read_text())})
    )
    second = run_parts(parts, executor, "ebm-eval second", progress=False, log=messages.append)
    assert [job.run_dir for job in executor.ran] == [parts[1].jobs[0].run_dir, stale.run_dir]
    assert len(second.skipped) == 2
    assert sum("complete (same configuration" in m for m in messages) == 2
    assert any("moved" in m and "another configuration" in m for m in messages)
    assert list(stale.run_dir.parent.glob("seed_0.replaced-*"))  # the other configuration's run is kept
    sessions = read_sessions(tmp_path)
    assert [s["command"] for s in sessions] == ["ebm-eval first", "ebm-eval second"]
    assert len(sessions[1]["skipped"]) == 2 and len(sessions[1]["ran"]) == 2


class KilledExecutor(FakeExecutor):
    """Finishes the first job, then dies like an invocation killed mid-sweep."""

    def map(self, jobs, progress=True):
        super().map(jobs[:1], progress)
        raise KeyboardInterrupt


def test_a_run_of_a_killed_invocation_still_names_its_command(tmp_path):
    parts = select_parts(build_parts(["table1"], make_context("smoke", str(tmp_path))), ["table1/particle/online"])
    executor = KilledExecutor()
    with pytest.raises(KeyboardInterrupt):
        run_parts(parts, executor, "ebm-eval killed", progress=False, log=lambda _m: None)
    record = read_provenance(executor.ran[0].run_dir)
    assert record["command"] == "ebm-eval killed" and record["status"] == "started"
    assert completed_result(executor.ran[0]) is not None  # finished, so a rerun skips it and the doc cites its command


def test_a_figure_part_runs_once_through_eval_figures(tmp_path, monkeypatch):
    calls = []

    def fake_figure(out_dir, *, seeds, scale):
        calls.append((Path(out_dir), tuple(seeds), scale))
        (Path(out_dir) / "plan.png").write_bytes(b"\x89PNG fake")
        payload = {"name": "plan_diversity", "pngs": ["plan.png"], "metrics": {"spread": 0.5}, "table_md": None}
        (Path(out_dir) / "figure.json").write_text(json.dumps({**payload, "command": "x"}))

    monkeypatch.setattr("eval.paper.runner.figure_function", lambda name: fake_figure)
    parts = build_parts(["plan_diversity"], make_context("smoke", str(tmp_path)))
    summary = run_parts(parts, FakeExecutor(), "ebm-eval fig", progress=False, log=lambda _m: None)
    assert summary.figures_ran == ["plan_diversity/particle"] and figure_complete(parts[0])
    assert calls == [(parts[0].figure_dir, (0,), "smoke")]
    again = run_parts(parts, FakeExecutor(), "ebm-eval fig", progress=False, log=lambda _m: None)
    assert again.figures_skipped == ["plan_diversity/particle"] and len(calls) == 1


def test_a_figure_runs_at_the_local_executors_threads(tmp_path, monkeypatch):
    # Figures train in the ebm-eval process: --threads must reach them, not only the runs of jobs=1.
    import torch

    from eval.executors import LocalExecutor

    seen = []

    def fake_figure(out_dir, *, seeds, scale):
        seen.append(torch.get_num_threads())
        (Path(out_dir) / "figure.json").write_text(json.dumps({"name": "plan_diversity", "pngs": [], "command": "x"}))

    monkeypatch.setattr("eval.paper.runner.figure_function", lambda name: fake_figure)
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        parts = build_parts(["plan_diversity"], make_context("smoke", str(tmp_path)))
        run_parts(parts, LocalExecutor(jobs=1, threads_per_job=1), "ebm-eval fig", progress=False, log=lambda _m: None)
    finally:
        torch.set_num_threads(before)
    assert seen == [1]


class StoppedExecutor(FakeExecutor):
    """Every run comes back stopped, as after SIGTERM (``eval.stop``)."""

    def map(self, jobs, progress=True):
        self.ran.extend(jobs)
        return [JobResult(job=job, status="stopped", error="run x stopped by SIGTERM at 7/10 transitions") for job in jobs]


def test_a_stopped_run_is_recorded_stopped_and_no_figure_starts(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr("eval.paper.runner.figure_function", lambda name: calls.append)
    context = make_context("smoke", str(tmp_path))
    parts = [
        *select_parts(build_parts(["table1"], context), ["table1/particle/online"]),
        *build_parts(["plan_diversity"], context),
    ]
    messages: list[str] = []
    summary = run_parts(parts, StoppedExecutor(), "ebm-eval stopped", progress=False, log=messages.append)
    assert not summary.ok and calls == [] and not summary.figures_ran
    assert read_provenance(parts[0].jobs[0].run_dir)["status"] == "stopped"
    assert any(m.startswith("stopped ") and "SIGTERM at 7/10" in m for m in messages)
    assert any("figures of this command not started" in m for m in messages)
    session = read_sessions(tmp_path)[-1]
    assert session["stopped"] == [str(job.run_dir) for job in parts[0].jobs] and session["failed"] == []


def test_a_failing_figure_is_reported_not_raised(tmp_path, monkeypatch):
    def broken(out_dir, *, seeds, scale):
        raise RuntimeError("no figure today")

    monkeypatch.setattr("eval.paper.runner.figure_function", lambda name: broken)
    parts = build_parts(["energy_maps"], make_context("smoke", str(tmp_path)))
    summary = run_parts(parts, FakeExecutor(), "ebm-eval fig", progress=False, log=lambda _m: None)
    assert not summary.ok and "no figure today" in summary.figures_failed["energy_maps/particle_maze"]


# ------------------------------------------------------------------------------------------------------------- CLI
@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--experiment", "table9"], "unknown experiment(s) 'table9'; choose from: table1, table2"),
        (["--experiment", "table1", "--part", "nothing/*"], "--part 'nothing/*' matches no part"),
        (["--experiment", "table1", "--timesteps", "10"], "--timesteps: not with --experiment"),
        (["--experiment", "table1", "--scale", "huge"], "unknown scale 'huge'"),
        (["--experiment", "list", "table1"], "--experiment list prints the experiments; give it alone"),
        (["--part", "table1/*"], "--part: only with --experiment"),
        (["--experiment", "plan_diversity", "--agents", "ebm"], "the selected parts have no run of these agents"),
    ],
)
def test_bad_experiment_flags_exit_2_with_a_clear_message(argv, message, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err


def test_experiment_list_prints_parts_and_cost(capsys):
    assert main(["--experiment", "list"]) == 0
    text = capsys.readouterr().out
    for name in ("table1/particle/pretrained", "table2/sawyer/pretrained_directed_sequential", "sawyer_ppo/10x"):
        assert name in text
    assert "~" in text and "CPU time" in text


def test_experiment_agents_runs_only_those_agents_cells(tmp_path, capsys):
    argv = ["--experiment", "table1", "--part", "table1/particle/online", "--scale", "smoke", "-f", str(tmp_path)]
    assert main([*argv, "--agents", "action-ff", "--no-progress"]) == 0
    assert "1 run(s) to do, 0 already complete" in capsys.readouterr().err
    assert {p.parent.parent.name for p in tmp_path.glob("smoke/online/particle/*/seed_*/metrics.json")} == {"action-ff"}
    assert main([*argv, "--no-progress"]) == 0  # the whole part: the Action FF run is done, the EBM's is not
    assert "1 run(s) to do, 1 already complete" in capsys.readouterr().err


def test_experiment_cli_runs_a_smoke_part_then_skips_it(tmp_path, capsys):
    argv = ["--experiment", "table1", "--part", "table1/particle/online", "--scale", "smoke", "-f", str(tmp_path)]
    assert main([*argv, "--no-progress"]) == 0
    assert "0 already complete" in capsys.readouterr().err
    doc = (tmp_path / "results.md").read_text()
    assert "| online | particle | EBM |" in doc and "not run yet" in doc
    assert main([*argv, "--no-progress"]) == 0
    assert "2 already complete" in capsys.readouterr().err


@dataclass
class _ToyConfig:
    width: int = 128


class _ToyAgent:
    def __init__(
        self,
        policy: str,
        env: object,
        config: _ToyConfig | dict | None = None,
        rate: float = 1e-3,
        seed: int | None = None,
        verbose: int = 0,
    ) -> None:
        pass


def test_class_defaults_hold_the_config_fields_and_not_what_does_not_measure():
    defaults = class_defaults(_ToyAgent)
    assert defaults == {"config": None, "config:_ToyConfig": {"width": 128}, "rate": 1e-3}
    ebm = class_defaults(__import__("ebm_agent.agent", fromlist=["EBMPlannerAgent"]).EBMPlannerAgent)
    assert ebm["energy:EnergyConfig"]["hidden_dim"] == 128 and ebm["planner_config:MPPIConfig"]["iterations"] == 80
    assert "seed" not in ebm and "device" not in ebm


@dataclass
class _ToyConfigLater:
    width: int = 128
    damping: float = 0.0  # added later; 0.0 keeps the old behaviour


@dataclass
class _ToyConfigChanged:
    width: int = 128
    damping: float = 0.5  # its default changed: now it matters


class _ToyAgentLater(_ToyAgent):
    def __init__(
        self,
        policy: str,
        env: object,
        config: _ToyConfigLater | dict | None = None,
        rate: float = 1e-3,
        clip: float | None = None,
        seed: int | None = None,
        verbose: int = 0,
    ) -> None:
        pass


class _ToyAgentChanged(_ToyAgent):
    def __init__(
        self,
        policy: str,
        env: object,
        config: _ToyConfigChanged | dict | None = None,
        rate: float = 1e-3,
        clip: float | None = 2.0,
        seed: int | None = None,
        verbose: int = 0,
    ) -> None:
        pass


_TOY_RULES = {
    "config_fields": {"_ToyConfigLater": {"damping": 0.0}, "_ToyConfigChanged": {"damping": 0.0}},
    "arguments": {"_ToyAgentLater": {"clip": None}, "_ToyAgentChanged": {"clip": None}},
}


def test_fields_added_at_their_neutral_value_leave_the_defaults_digest_alone():
    before = class_defaults(_ToyAgent, neutral=_TOY_RULES)
    later = class_defaults(_ToyAgentLater, neutral=_TOY_RULES)
    renamed = {key.replace("_ToyConfigLater", "_ToyConfig"): value for key, value in later.items()}
    assert renamed == before  # a new field and a new argument at their neutral values retire nothing
    changed = class_defaults(_ToyAgentChanged, neutral=_TOY_RULES)
    assert changed["config:_ToyConfigChanged"] == {"width": 128, "damping": 0.5} and changed["clip"] == 2.0
    unruled = class_defaults(_ToyAgentLater, neutral={})  # without the rules, the new settings enter the digest
    assert unruled["clip"] is None and unruled["config:_ToyConfigLater"]["damping"] == 0.0


def test_the_library_planners_new_fields_and_the_horizon_keep_the_recorded_digest():
    """The rules file lists the planner fields added after the records, and the horizon that became None."""
    from baselines.action_ff import ActionFFAgent
    from ebm_agent.agent import EBMPlannerAgent

    rules = neutral_settings()
    assert rules["config_fields"]["MPPIConfig"]["warm_iterations"] is None
    for agent_class in (EBMPlannerAgent, ActionFFAgent):
        settings = class_defaults(agent_class)
        assert settings["horizon"] == 10  # the default None stands for the planner's 10, as recorded
        config = next(value for key, value in settings.items() if key.startswith("planner_config:"))
        assert "warm_iterations" not in config and config["horizon"] == 10
        assert class_defaults(agent_class, {"horizon": 20})["horizon"] == 20


def test_env_inverse_dynamics_defaults_retire_only_the_runs_that_use_them():
    """SawyerReach's finger weight changes only its inverse dynamics: the EBM's digest there sees it, no other."""
    from eval.provenance import agent_defaults_digest

    sawyer = {"inverse_finger_weight": 100.0, "inverse_rescue_ceiling": 0.1}
    assert env_inverse_dynamics_defaults("ebm/SawyerReach-v0") == sawyer
    assert env_inverse_dynamics_defaults("ebm/Particle-v0") == {}
    assert env_inverse_dynamics_defaults("no/SuchEnv-v0") == {}
    ebm = AGENTS["ebm"].defaults
    assert ebm is not None
    assert ebm("ebm/SawyerReach-v0")["env:inverse_dynamics"] == sawyer
    assert "env:inverse_dynamics" not in ebm("ebm/Particle-v0")  # other envs keep their digests
    assert agent_defaults_digest("ebm", "ebm/SawyerReach-v0") != agent_defaults_digest("ebm", "ebm/Particle-v0")
    assert agent_defaults_digest("action-ff", "ebm/SawyerReach-v0") == agent_defaults_digest("action-ff", "ebm/Particle-v0")


def test_runs_made_with_other_library_defaults_are_retired(tmp_path, monkeypatch):
    """A changed default of the EBM changes its digest: its runs made before are rerun, the others stay."""
    import eval.provenance as provenance

    context = make_context("smoke", str(tmp_path), [0, 1])
    parts = select_parts(build_parts(["table1"], context), ["table1/particle/online"])
    executor, messages = FakeExecutor(), []
    run_parts(parts, executor, "ebm-eval first", progress=False, log=messages.append)
    jobs = parts[0].jobs
    assert len(jobs) == 4
    for job in jobs:  # the digest as run_job records it
        metrics = json.loads((job.run_dir / "metrics.json").read_text())
        (job.run_dir / "metrics.json").write_text(json.dumps({**metrics, "defaults_digest": defaults_digest(job)}))
    legacy = next(job for job in jobs if job.agent == "ebm")  # finished before digests were recorded
    metrics = json.loads((legacy.run_dir / "metrics.json").read_text())
    (legacy.run_dir / "metrics.json").write_text(json.dumps({**metrics, "defaults_digest": None}))
    assert all(completed_result(job) is not None for job in jobs)

    original = AGENTS["ebm"].defaults
    changed = replace(AGENTS["ebm"], defaults=lambda env_id, preset="": {**original(env_id, preset), "horizon": 20})
    monkeypatch.setitem(AGENTS, "ebm", changed)
    provenance._defaults_digest.cache_clear()
    try:
        stale = [job for job in jobs if completed_result(job) is None]
        executor.ran.clear()
        run_parts(parts, executor, "ebm-eval second", progress=False, log=messages.append)
    finally:
        provenance._defaults_digest.cache_clear()
    assert stale == [job for job in jobs if job.agent == "ebm" and job != legacy]
    assert executor.ran == stale
    assert any("other library defaults" in message for message in messages), messages


def test_an_unfinished_figure_of_the_same_seeds_is_resumed_and_one_of_other_seeds_moved_aside(tmp_path, monkeypatch):
    seen = []

    def figure_that_dies(out_dir, *, seeds, scale):
        seen.append(sorted(p.name for p in Path(out_dir).iterdir()))
        (Path(out_dir) / "seeds").mkdir(exist_ok=True)
        (Path(out_dir) / "seeds" / "plan_diversity_seed0.json").write_text("{}")
        raise KeyboardInterrupt

    monkeypatch.setattr("eval.paper.runner.figure_function", lambda name: figure_that_dies)
    parts = build_parts(["plan_diversity"], make_context("smoke", str(tmp_path)))
    for _ in range(2):
        with pytest.raises(KeyboardInterrupt):
            run_parts(parts, FakeExecutor(), "ebm-eval fig", progress=False, log=lambda _m: None)
    assert seen == [["figure_started.json"], ["figure_started.json", "seeds"]]  # the second run found the first's seeds
    other = [replace(parts[0], seeds=(5,))]
    with pytest.raises(KeyboardInterrupt):
        run_parts(other, FakeExecutor(), "ebm-eval fig", progress=False, log=lambda _m: None)
    assert seen[-1] == ["figure_started.json"]  # other seeds: a fresh folder, the old one moved aside
    folder = parts[0].figure_dir
    assert (folder.with_name(f"{folder.name}.replaced-old") / "seeds" / "plan_diversity_seed0.json").exists()


def test_a_resumed_figure_counts_the_time_of_the_seeds_earlier_processes_finished(tmp_path, monkeypatch):
    from eval.paper.figures.common import figure_digest
    from eval.paper.results_doc import part_status, parts_table

    digest = figure_digest("plan_diversity")

    def figure_that_dies(out_dir, *, seeds, scale):
        (Path(out_dir) / "seeds").mkdir(exist_ok=True)
        seed0 = {"seed": 0, "wall_time_s": 600.0, "defaults_digest": digest}
        (Path(out_dir) / "seeds" / "plan_diversity_seed0.json").write_text(json.dumps(seed0))
        seed1 = {"seed": 1, "defaults_digest": digest}  # from before times were kept
        (Path(out_dir) / "seeds" / "plan_diversity_seed1.json").write_text(json.dumps(seed1))
        seed2 = {"seed": 2, "wall_time_s": 900.0, "defaults_digest": "0000000000000000"}  # computed again, not counted
        (Path(out_dir) / "seeds" / "plan_diversity_seed2.json").write_text(json.dumps(seed2))
        raise KeyboardInterrupt

    def figure_that_finishes(out_dir, *, seeds, scale):
        (Path(out_dir) / "figure.json").write_text("{}")

    parts = build_parts(["plan_diversity"], make_context("smoke", str(tmp_path)))
    monkeypatch.setattr("eval.paper.runner.figure_function", lambda name: figure_that_dies)
    with pytest.raises(KeyboardInterrupt):
        run_parts(parts, FakeExecutor(), "ebm-eval fig", progress=False, log=lambda _m: None)
    monkeypatch.setattr("eval.paper.runner.figure_function", lambda name: figure_that_finishes)
    run_parts(parts, FakeExecutor(), "ebm-eval fig", progress=False, log=lambda _m: None)
    record = read_provenance(parts[0].figure_dir)
    assert record["earlier_seeds"] == 2 and record["earlier_seeds_untimed"] == 1
    assert 600.0 <= record["wall_time_s"] < 660.0
    table = parts_table(parts, [part_status(parts[0], [])])
    assert "10 min + 1 earlier seed(s), time not recorded |" in table


def test_read_json_dict_reads_an_object_and_gives_none_for_anything_else(tmp_path):
    from eval.provenance import read_json_dict

    (tmp_path / "ok.json").write_text('{"a": 1}')
    (tmp_path / "torn.json").write_text('{"a": ')
    (tmp_path / "list.json").write_text("[1, 2]")
    assert read_json_dict(tmp_path / "ok.json") == {"a": 1}
    assert [read_json_dict(tmp_path / name) for name in ("torn.json", "list.json", "missing.json")] == [None] * 3


def _finished_figure(folder: Path, provenance: dict[str, Any], seed_digests: dict[int, str | None]) -> None:
    """A figure folder as a finished figure leaves it: figure.json, provenance.json and kept seeds."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "figure.json").write_text(json.dumps({"name": "obstacle_generalisation", "metrics": {"old": True}}))
    (folder / "provenance.json").write_text(json.dumps({"command": "ebm-eval old", **provenance}))
    for seed, digest in seed_digests.items():
        record = {"seed": seed, "result": {}, "wall_time_s": 60.0, **({"defaults_digest": digest} if digest else {})}
        (folder / "seeds").mkdir(exist_ok=True)
        (folder / "seeds" / f"obstacle_generalisation_seed{seed}.json").write_text(json.dumps(record))


def test_a_figure_made_under_earlier_defaults_is_retired_and_made_again(tmp_path, monkeypatch):
    from eval.paper.figures.common import figure_digest, figure_state

    (part,) = build_parts(["obstacle"], make_context("smoke", str(tmp_path)))
    current, folder = figure_digest("obstacle_generalisation"), part.figure_dir
    assert current is not None
    scale = {"scale": "smoke", "seeds": list(part.seeds)}
    _finished_figure(folder, {**scale, "defaults_digest": current}, {})
    assert figure_state(part) == "complete"
    _finished_figure(folder, {**scale, "defaults_digest": "0000000000000000"}, {})
    assert figure_state(part) == "retired" and not figure_complete(part)
    # A figure finished before figures recorded their digest: its kept seeds tell, else it is taken as it is.
    (folder / "provenance.json").write_text(json.dumps({"command": "ebm-eval old", **scale}))
    assert figure_state(part) == "complete"
    _finished_figure(folder, scale, {0: current})
    assert figure_state(part) == "complete"
    _finished_figure(folder, scale, {0: "0000000000000000"})
    assert figure_state(part) == "retired"
    (folder / "figure_started.json").write_text(json.dumps({"part": part.name, **scale}))

    def stopped_after_its_seeds(out_dir, *, seeds, scale):
        # The rerun replaces the seeds with current ones, then stops before writing its figure.json.
        for seed in seeds:
            record = {"seed": seed, "result": {}, "defaults_digest": current, "wall_time_s": 1.0}
            (Path(out_dir) / "seeds" / f"obstacle_generalisation_seed{seed}.json").write_text(json.dumps(record))
        raise RuntimeError("killed")

    monkeypatch.setattr("eval.paper.runner.figure_function", lambda name: stopped_after_its_seeds)
    messages: list[str] = []
    summary = run_parts([part], FakeExecutor(), "ebm-eval fig", progress=False, log=messages.append)
    assert any("made under earlier library defaults: making it again" in m for m in messages)
    assert any("0 finished seed(s) kept" in m for m in messages)  # the stale seed is not reused
    assert summary.figures_failed and figure_state(part) == "retired"  # the old figure.json does not pass for new

    def finishes(out_dir, *, seeds, scale):
        (Path(out_dir) / "figure.json").write_text(json.dumps({"name": "obstacle_generalisation", "metrics": {}}))

    monkeypatch.setattr("eval.paper.runner.figure_function", lambda name: finishes)
    summary = run_parts([part], FakeExecutor(), "ebm-eval fig", progress=False, log=lambda _m: None)
    assert summary.figures_ran == [part.name] and figure_state(part) == "complete"
    assert read_provenance(folder)["defaults_digest"] == current


def test_the_seeds_of_a_retired_figure_being_made_again_survive_in_the_records(tmp_path, monkeypatch):
    from eval.paper.figures.common import _current_seed_files, figure_digest, figure_state
    from eval.paper.records import restore_records, save_records

    out, records, fresh = tmp_path / "out", tmp_path / "records", tmp_path / "fresh"
    (part,) = build_parts(["obstacle"], make_context("smoke", str(out)))
    current, scale = figure_digest("obstacle_generalisation"), {"scale": "smoke", "seeds": list(part.seeds)}
    _finished_figure(part.figure_dir, scale, {0: "0000000000000000"})  # an old figure, its digest in its seeds
    (part.figure_dir / "figure_started.json").write_text(json.dumps({"part": part.name, **scale}))

    def stopped_after_its_seed(out_dir, *, seeds, scale):
        record = {"seed": 0, "result": {}, "defaults_digest": current, "wall_time_s": 1.0}
        (Path(out_dir) / "seeds" / "obstacle_generalisation_seed0.json").write_text(json.dumps(record))
        raise RuntimeError("the session ended")

    monkeypatch.setattr("eval.paper.runner.figure_function", lambda name: stopped_after_its_seed)
    run_parts([part], FakeExecutor(), "ebm-eval fig", progress=False, log=lambda _m: None)
    save_records(out, records)
    restore_records(records, fresh)  # the next session's checkout
    (moved,) = build_parts(["obstacle"], make_context("smoke", str(fresh)))
    assert figure_state(moved) == "retired"  # the old figure.json still does not pass for a current one
    kept = _current_seed_files(moved.figure_dir, "obstacle_generalisation")
    assert [path.name for path in kept] == ["obstacle_generalisation_seed0.json"]  # resumed, not trained again
