"""ebm-eval: flags, presets, errors (exit 2) and a whole sweep on a tiny budget."""

from __future__ import annotations

import contextlib
import csv
import io
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from eval.cli import main, resolve_settings
from eval.flags import build_parser, parse_value
from eval.presets import available_presets, load_preset

REPO = Path(__file__).resolve().parents[2]


def settings_of(*argv: str) -> dict:
    return resolve_settings(build_parser().parse_args(list(argv)))


def test_help_exits_0_and_explains_each_flag(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--help"])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    for flag in (
        "--env",
        "--baseline",
        "--timesteps",
        "--seeds",
        "--eval-episodes",
        "--eval-freq",
        "--out",
        "--device",
        "--config",
        "--jobs",
        "--env-kwargs",
        "--hyperparams",
        "--executor",
        "--no-progress",
        "--verbose",
    ):
        assert flag in text
    assert "particle, maze, reacher, sawyer" in text


def test_defaults_of_ebm_eval_baseline_ppo():
    settings = settings_of("--baseline", "ppo")
    assert settings["agents"] == ["ebm", "ppo"]
    assert settings["env_ids"] == ["ebm/Particle-v0"]
    assert settings["timesteps"] == 2000 and settings["eval_freq"] == 400
    assert settings["seeds"] == [0] and settings["eval_episodes"] == 10 and settings["jobs"] == 1
    assert settings["out"].startswith("runs/ebm-eval-")


def test_baselines_repeat_and_ebm_is_always_first():
    assert settings_of("--baseline", "ppo", "--baseline", "random")["agents"] == ["ebm", "ppo", "random"]
    assert settings_of("--baseline", "ppo", "action-ff")["agents"] == ["ebm", "ppo", "action-ff"]
    assert settings_of("--agents", "random", "ppo")["agents"] == ["random", "ppo"]


def test_env_names_and_key_value_flags():
    settings = settings_of(
        "--env", "maze", "Pendulum-v1", "--env", "envs:ebm/Reacher-v0",
        "--env-kwargs", "start=[0, 0]", "goal=[0.5,0.5]",
        "--hyperparams", "horizon=20", "ppo:learning_rate=1e-3", "ppo:n_steps=64",
    )  # fmt: skip
    assert settings["env_ids"] == ["ebm/Maze-v0", "Pendulum-v1", "ebm/Reacher-v0"]
    assert settings["env_kwargs"] == {"start": [0, 0], "goal": [0.5, 0.5]}
    assert settings["hyperparams"] == {"ebm": {"horizon": 20}, "ppo": {"learning_rate": 1e-3, "n_steps": 64}}
    assert settings["eval_env_kwargs"] == {"start": [0, 0], "goal": [0.5, 0.5]}  # defaults to the training kwargs
    settings = settings_of("--env-kwargs", "goal=[0.5,0.5]", "--eval-env-kwargs", "start=[0,0]")
    assert settings["env_kwargs"] == {"goal": [0.5, 0.5]}
    assert settings["eval_env_kwargs"] == {"goal": [0.5, 0.5], "start": [0, 0]}


@pytest.mark.parametrize(
    ("text", "value"),
    [("1e-3", 1e-3), ("64", 64), ("[0, 0.5]", [0, 0.5]), ("true", True), ("variable", "variable"), ("null", None)],
)
def test_parse_value(text, value):
    assert parse_value(text) == value
    assert type(parse_value(text)) is type(value)


def test_preset_merges_under_explicit_flags(tmp_path):
    settings = settings_of("--config", "smoke")
    assert settings["agents"] == ["random"] and settings["timesteps"] == 200 and settings["eval_freq"] == 100
    settings = settings_of("--config", "smoke", "--timesteps", "300", "--baseline", "ppo")
    assert settings["timesteps"] == 300 and settings["agents"] == ["ebm", "ppo"]
    preset = tmp_path / "mine.yaml"
    preset.write_text("env: maze\nbaseline: [random]\nseeds: [1, 2]\nhyperparams:\n  ebm: {horizon: 10, width: 64}\n")
    settings = settings_of("--config", str(preset), "--hyperparams", "horizon=30")
    assert settings["env_ids"] == ["ebm/Maze-v0"] and settings["agents"] == ["ebm", "random"]
    assert settings["seeds"] == [1, 2]
    assert settings["hyperparams"] == {"ebm": {"horizon": 30, "width": 64}}
    assert settings["eval_freq"] == 400  # default timesteps 2000 // 5


def test_every_bundled_preset_is_valid():
    names = available_presets()
    assert {"smoke", "particle_online"} <= set(names)
    for name in names:
        settings = settings_of("--config", name)
        assert settings["agents"] and settings["env_ids"], name
    assert load_preset(str(REPO / "eval" / "presets" / "smoke.yaml"))["timesteps"] == 200


@pytest.mark.parametrize("name", ["maze_demo", "maze_follow"])
def test_the_maze_presets_build_their_agents(name):
    from eval.registry import get_agent

    preset = load_preset(name)
    for agent, hyperparams in preset["hyperparams"].items():
        model = get_agent(agent).factory("ebm/Maze-v0", {}, 0, None, "cpu", dict(hyperparams), 0)
        graph = model.subgoal_graph.kwargs()
        assert {key: graph[key] for key in hyperparams["subgoal_graph"]} == hyperparams["subgoal_graph"], agent
        assert model.explore.every == hyperparams["explore"]["every"], agent


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--env", "nowhere"], "unknown env 'nowhere': use a short name (particle, maze, reacher, sawyer, pointmaze, fetch-"),
        (["--timesteps", "0"], "must be a positive integer"),
        (["--timesteps", "-5"], "must be a positive integer"),
        (["--timesteps", "many"], "expected a positive integer"),
        (["--eval-episodes", "0"], "must be a positive integer"),
        (["--jobs", "0"], "must be a positive integer"),
        (["--threads", "0"], "--threads: must be a positive integer"),
        (["--executor", "ray", "--threads", "1"], "--threads applies to the local executor"),
        (["--seeds", "-1"], "seeds are non-negative integers"),
        (["--baseline", "dqn"], "invalid choice: 'dqn'"),
        (["--config", "nope"], "unknown preset 'nope'"),
        (["--env-kwargs", "start"], "expected key=value"),
        (["--hyperparams", "sac:lr=1"], "unknown agent 'sac'"),
        (["--executor", "dask"], "unknown executor 'dask'"),
        (["--bogus-flag"], "unrecognized arguments"),
    ],
)
def test_bad_flags_exit_2_with_a_message(argv, message, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    error = capsys.readouterr().err
    assert message in error
    assert error.startswith("usage: ebm-eval")


def test_bad_preset_content_exits_2(tmp_path, capsys):
    preset = tmp_path / "bad.yaml"
    preset.write_text("timesteps: 100\nlearning_rate: 0.1\n")
    with pytest.raises(SystemExit) as exit_info:
        main(["--config", str(preset)])
    assert exit_info.value.code == 2
    assert "unknown keys ['learning_rate']" in capsys.readouterr().err
    preset.write_text("hyperparams: {horizon: 20}\n")
    with pytest.raises(SystemExit):
        main(["--config", str(preset)])
    assert "preset hyperparams must map agent names" in capsys.readouterr().err
    preset.write_text("timesteps: -3\n")
    with pytest.raises(SystemExit):
        main(["--config", str(preset)])
    assert "timesteps must be a positive integer" in capsys.readouterr().err


def test_unknown_preset_lists_the_bundled_ones(capsys):
    with pytest.raises(SystemExit):
        main(["--config", "nope"])
    assert "smoke" in capsys.readouterr().err


def test_console_process_exits_2_on_a_bad_flag():
    completed = subprocess.run(
        [sys.executable, "-m", "eval", "--timesteps", "0"], cwd=REPO, capture_output=True, text=True, timeout=120
    )
    assert completed.returncode == 2
    assert "--timesteps: must be a positive integer" in completed.stderr


# ---- a whole sweep on a tiny budget -------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    pytest.importorskip("envs.particle")
    pytest.importorskip("baselines.random_agent")
    pytest.importorskip("baselines.ppo")
    out = tmp_path_factory.mktemp("sweep")
    argv = ["--agents", "random", "ppo", "--timesteps", "200", "--eval-episodes", "2", "--eval-freq", "100",
            "--eval-env-kwargs", "start=[0,0]", "--out", str(out), "--no-progress", "--device", "cpu"]  # fmt: skip
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        code = main(argv)
    return code, out, stdout.getvalue()


def test_sweep_succeeds_and_prints_the_table(sweep):
    code, _out, stdout = sweep
    assert code == 0
    assert "| env | agent | seeds | score (over seeds)" in stdout
    assert "| particle | random | 1 |" in stdout and "| particle | ppo | 1 |" in stdout
    assert "200 / 200" in stdout


def test_sweep_csv_rows_and_exact_budgets(sweep):
    _code, out, _stdout = sweep
    with open(out / "results.csv", newline="") as file:
        rows = list(csv.DictReader(file))
    assert [(row["env"], row["agent"], row["seed"]) for row in rows] == [("particle", "random", "0"), ("particle", "ppo", "0")]
    for row in rows:
        assert row["status"] == "ok" and row["timesteps"] == "200"
        assert float(row["score_mean"]) < 0.0 and float(row["score_std"]) >= 0.0
        assert 0.0 <= float(row["success_rate"]) <= 1.0


def test_sweep_markdown_has_anchors_and_command(sweep):
    _code, out, _stdout = sweep
    text = (out / "results.md").read_text()
    assert "## Sanity anchors" in text and "-4.50" in text and "-100.00" in text
    assert "ebm-eval --agents random ppo --timesteps 200" in text
    assert (out / "config.yaml").exists() and (out / "anchors.json").exists()


@pytest.mark.parametrize("agent", ["random", "ppo"])
def test_sweep_run_folders_npz_and_tensorboard(sweep, agent):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    _code, out, _stdout = sweep
    run_dir = out / "particle" / agent / "seed_0"
    for name in ("config.yaml", "metrics.json", "model.zip"):
        assert (run_dir / name).is_file()
    config = yaml.safe_load((run_dir / "config.yaml").read_text())
    # The paper's particle evaluation (envs.PAPER_EVAL_KWARGS) under the --eval-env-kwargs flag.
    assert config["env_kwargs"] == {} and config["eval_env_kwargs"] == {"start": [0, 0], "goal": [0.5, 0.5]}
    with np.load(run_dir / "evaluations.npz") as data:
        assert {"timesteps", "results", "ep_lengths"} <= set(data.files)
        np.testing.assert_array_equal(data["timesteps"], [100, 200])
        assert data["results"].shape == (2, 2)
    (tb_run,) = (out / "tb" / "particle").glob(f"{agent}_s0_*")
    events = EventAccumulator(str(tb_run))
    events.Reload()
    assert {"eval/mean_reward", "final/score_mean"} <= set(events.Tags()["scalars"])
    assert [e.step for e in events.Scalars("eval/mean_reward")] == [100, 200]


def test_sweep_learning_curve_png(sweep):
    _code, out, _stdout = sweep
    data = (out / "learning_curves_particle.png").read_bytes()
    assert data.startswith(b"\x89PNG") and len(data) > 5000


def test_a_failed_run_gives_exit_1_and_keeps_the_others(tmp_path, capsys):
    pytest.importorskip("envs.particle")
    pytest.importorskip("baselines.random_agent")
    from eval.registry import AGENTS, AgentSpec, register_agent

    def broken(**_kwargs):
        raise RuntimeError("cannot build")

    register_agent("broken", AgentSpec(broken, "Broken"))
    try:
        code = main(["--agents", "random", "broken", "--timesteps", "100", "--eval-episodes", "1", "--out", str(tmp_path),
                     "--no-progress"])  # fmt: skip
    finally:
        del AGENTS["broken"]
    assert code == 1
    with open(tmp_path / "results.csv", newline="") as file:
        assert [row["status"] for row in csv.DictReader(file)] == ["ok", "failed"]
    assert "RuntimeError: cannot build" in (tmp_path / "results.md").read_text()
    assert "broken / seed 0: RuntimeError: cannot build" in capsys.readouterr().out
