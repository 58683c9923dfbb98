"""The harness on gymnasium-robotics envs it did not write, unmodified: names, the protocol's env kwargs, the success
key of the maze envs, and whole runs of the baselines with normalised observations."""

from __future__ import annotations

import contextlib
import csv
import io
import json

import pytest

from eval.cli import build_jobs, main, resolve_settings
from eval.evaluation import episode_success
from eval.flags import build_parser
from eval.jobs import VEC_NORMALIZE, env_short_name


def settings_of(*argv: str) -> dict:
    return resolve_settings(build_parser().parse_args(list(argv)))


def test_short_names_resolve_to_the_registered_ids_and_back() -> None:
    settings = settings_of("--env", "fetch-reach", "pointmaze", "FetchPush-v4")
    assert settings["env_ids"] == ["FetchReach-v4", "PointMaze_UMaze-v3", "FetchPush-v4"]
    assert [env_short_name(env_id) for env_id in settings["env_ids"]] == ["fetch-reach", "pointmaze", "fetch-push"]


def test_pointmaze_episodes_end_at_the_goal_in_training_and_evaluation_unless_the_user_says_otherwise() -> None:
    jobs = build_jobs(settings_of("--env", "pointmaze", "fetch-reach", "--agents", "random"), progress=False)
    maze, fetch = jobs
    assert maze.env_kwargs == {"continuing_task": False} and maze.eval_env_kwargs == {"continuing_task": False}
    assert fetch.env_kwargs == {} and fetch.eval_env_kwargs == {}  # the protocol names only what it changes
    (mine,) = build_jobs(
        settings_of("--env", "pointmaze", "--agents", "random", "--env-kwargs", "continuing_task=true"), progress=False
    )
    assert mine.env_kwargs == {"continuing_task": True} and mine.eval_env_kwargs == {"continuing_task": True}


def test_success_is_read_under_either_key_the_envs_use() -> None:
    assert episode_success({"is_success": 1.0}) == 1.0  # Fetch, the ebm/ envs
    assert episode_success({"success": True}) is True  # PointMaze, AntMaze
    assert episode_success({"is_success": 0.0, "success": True}) == 0.0  # the GoalEnv key first
    assert episode_success({}) is None


@pytest.fixture(scope="module")
def third_party_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("third_party")
    argv = ["--env", "fetch-reach", "pointmaze", "--agents", "sac-her", "--timesteps", "400", "--eval-episodes", "2",
            "--eval-freq", "200", "--hyperparams", "sac-her:learning_starts=300", "sac-her:buffer_size=2000",
            "sac-her:batch_size=32", "--out", str(out), "--no-progress", "--device", "cpu"]  # fmt: skip
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        code = main(argv)
    return code, out


def test_the_sweep_runs_both_envs_on_exact_budgets_with_success_rates(third_party_sweep) -> None:
    code, out = third_party_sweep
    assert code == 0
    with open(out / "results.csv", newline="") as file:
        rows = {row["env"]: row for row in csv.DictReader(file)}
    assert set(rows) == {"fetch-reach", "pointmaze"}
    for row in rows.values():
        assert row["status"] == "ok" and row["timesteps"] == "400"
        assert row["success_rate"] != ""  # PointMaze reports it as info["success"]
    metrics = json.loads((out / "pointmaze" / "sac-her" / "seed_0" / "metrics.json").read_text())
    assert len(metrics["episode_successes"]) == 2


def test_a_normalised_baseline_keeps_its_statistics_beside_its_model(third_party_sweep) -> None:
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    _code, out = third_party_sweep
    fetch = out / "fetch-reach" / "sac-her" / "seed_0"
    assert (fetch / VEC_NORMALIZE).is_file()  # FetchReach's entry normalises observations
    assert not (out / "pointmaze" / "sac-her" / "seed_0" / VEC_NORMALIZE).exists()  # the default entry does not
    statistics = VecNormalize.load(str(fetch / VEC_NORMALIZE), make_vec_env("FetchReach-v4", n_envs=1))
    assert statistics.obs_rms["observation"].count > 400  # the 400 training steps (and its prior count of 1e-4)
