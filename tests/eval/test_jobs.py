"""run_job end to end with the random agent on the particle env, and its failure path."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest
import yaml

from eval.jobs import Job, JobResult, env_short_name
from eval.registry import AGENTS, AgentSpec, register_agent
from eval.run import run_job

pytest.importorskip("envs.particle")
pytest.importorskip("baselines.random_agent")


def _job(tmp_path, **overrides) -> Job:
    settings = {
        "env_id": "ebm/Particle-v0",
        "agent": "random",
        "seed": 3,
        "timesteps": 200,
        "eval_freq": 100,
        "eval_episodes": 2,
        "env_kwargs": {"start": (0.0, 0.0)},
        "device": "cpu",
        "out_dir": str(tmp_path),
    }
    settings.update(overrides)
    return Job(**settings)


def test_run_job_writes_the_run_folder(tmp_path, capsys):
    job = _job(tmp_path)
    result = run_job(job)
    assert result.ok, result.error
    assert pickle.loads(pickle.dumps(result)) == result
    run_dir = tmp_path / "particle" / "random" / "seed_3"
    assert result.run_dir == run_dir
    assert {p.name for p in run_dir.iterdir()} >= {"config.yaml", "evaluations.npz", "metrics.json", "model.zip"}

    config = yaml.safe_load((run_dir / "config.yaml").read_text())
    assert config["env_id"] == "ebm/Particle-v0" and config["timesteps"] == 200
    assert config["env_kwargs"] == {"start": [0.0, 0.0]}
    assert "stable-baselines3" in config["versions"]

    with np.load(run_dir / "evaluations.npz") as data:
        np.testing.assert_array_equal(data["timesteps"], [100, 200])
        assert data["results"].shape == (2, 2) and data["ep_lengths"].shape == (2, 2)
        last_evaluation = data["results"][-1]

    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["timesteps"] == 200 and metrics["budget_respected"]
    # The callback's evaluation at the final step is the final evaluation.
    np.testing.assert_allclose(metrics["episode_scores"], last_evaluation)
    assert metrics["score_mean"] == pytest.approx(np.mean(last_evaluation))
    assert metrics["score_std"] == pytest.approx(np.std(last_evaluation))
    assert metrics["success_rate"] == 0.0  # random actions do not stop within 0.01 of the goal
    assert result.timesteps == 200 and result.score_mean == pytest.approx(metrics["score_mean"])
    assert metrics["model_quality"] is None  # no energy to probe

    events = list((tmp_path / "tb" / "particle").glob("random_s3_1/events.out.tfevents.*"))
    assert len(events) == 1 and events[0].stat().st_size > 0

    # Without a progress bar, each learning-curve evaluation prints one line naming the run, with its score.
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith(str(run_dir))]
    assert [line.split(": ")[1].split(",")[0] for line in lines] == ["100/200 transitions", "200/200 transitions"]
    assert f"evaluation {np.mean(last_evaluation):.2f} ± {np.std(last_evaluation):.2f}, success 0.00" in lines[-1]
    assert "about 0 min left" in lines[-1]


def test_final_evaluation_is_appended_when_the_last_callback_one_was_earlier(tmp_path):
    result = run_job(_job(tmp_path, timesteps=150, eval_freq=100))
    assert result.ok, result.error
    with np.load(result.run_dir / "evaluations.npz") as data:
        np.testing.assert_array_equal(data["timesteps"], [100, 150])
        np.testing.assert_allclose(data["results"][-1], result.episode_scores)


def _broken_factory(**_kwargs):
    raise RuntimeError("this agent cannot be built")


@pytest.fixture
def broken_agent():
    register_agent("broken", AgentSpec(_broken_factory, "Broken"))
    yield "broken"
    del AGENTS["broken"]


def test_a_failing_run_returns_a_failed_result(tmp_path, broken_agent):
    result = run_job(_job(tmp_path, agent=broken_agent))
    assert isinstance(result, JobResult) and result.status == "failed" and not result.ok
    assert "this agent cannot be built" in (result.error or "")
    assert "this agent cannot be built" in (result.run_dir / "error.txt").read_text()
    assert (result.run_dir / "config.yaml").exists()


def test_unknown_agent_is_a_failed_result_naming_the_choices(tmp_path):
    result = run_job(_job(tmp_path, agent="nope"))
    assert result.status == "failed"
    assert "unknown agent 'nope'; choose one of:" in (result.error or "")


def test_register_agent_checks_its_input():
    with pytest.raises(ValueError, match="already registered"):
        register_agent("ppo", AGENTS["ppo"])
    with pytest.raises(TypeError, match="AgentSpec"):
        register_agent("other", object())  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("env_id", "short"),
    [("ebm/Particle-v0", "particle"), ("ebm/SawyerReach-v0", "sawyer"), ("Pendulum-v1", "Pendulum-v1"), ("a/B-v0", "a_B-v0")],
)
def test_env_short_name(env_id, short):
    assert env_short_name(env_id) == short


def test_a_run_folder_held_by_a_live_process_is_left_alone_and_a_stale_lock_taken_over(tmp_path):
    import json as json_module
    import os
    import socket

    from eval.run import RUN_LOCK

    job = _job(tmp_path)
    job.run_dir.mkdir(parents=True)
    (job.run_dir / "metrics.json").write_text("{}")  # the other process's files must survive
    lock = job.run_dir / RUN_LOCK
    lock.write_text(json_module.dumps({"host": socket.gethostname(), "pid": os.getppid()}))  # alive: our parent
    result = run_job(job)
    assert result.status == "failed" and "two processes must not share a run folder" in result.error
    assert (job.run_dir / "metrics.json").read_text() == "{}" and lock.exists()
    lock.write_text(json_module.dumps({"host": socket.gethostname(), "pid": 2**22 + 12345}))  # no such process
    assert run_job(job).ok
    assert not lock.exists()  # released when the run ends


def test_an_untrained_job_evaluates_the_agent_as_built(tmp_path):
    """mode="untrained": no transition is learned from; the score is that of a fresh agent of the same seed."""
    import gymnasium as gym
    import torch

    from ebm_agent import EBMPlannerAgent

    tiny = {"planner_config": {"num_samples": 8, "iterations": 2}}
    job = _job(tmp_path, agent="ebm", mode="untrained", timesteps=0, eval_freq=1, hyperparams=tiny)
    result = run_job(job)
    assert result.ok, result.error
    assert result.timesteps == 0 and len(result.episode_scores) == 2
    metrics = json.loads((job.run_dir / "metrics.json").read_text())
    assert metrics["mode"] == "untrained" and metrics["budget_respected"] and metrics["pretraining"] is None
    # The energy's model-quality probe is recorded (the particle labels moves past its border infeasible).
    quality = metrics["model_quality"]
    assert set(quality) == {"next_state_rank", "next_state_mean_rank", "feasibility_auroc", "feasibility_auroc_uniform"}
    assert all(0.0 <= value <= 1.0 for value in quality.values())
    saved = EBMPlannerAgent.load(job.run_dir / "model.zip", device="cpu")
    fresh = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Particle-v0"), seed=job.seed, device="cpu", **tiny)
    for name, tensor in fresh.policy.state_dict().items():
        assert torch.equal(saved.policy.state_dict()[name], tensor), name
    with pytest.raises(ValueError, match="timesteps must be 0"):
        _job(tmp_path, agent="ebm", mode="untrained", timesteps=10)


def test_a_maze_run_records_the_wall_auroc_of_its_energy(tmp_path):
    """On the maze the env labels moves into walls, so the record also holds the feasibility AUROCs."""
    tiny = {"planner_config": {"num_samples": 8, "iterations": 2}}
    settings = {"env_id": "ebm/Maze-v0", "env_kwargs": {"max_episode_steps": 5}, "eval_episodes": 1}
    job = _job(tmp_path, agent="ebm", mode="untrained", timesteps=0, eval_freq=1, hyperparams=tiny, **settings)
    result = run_job(job)
    assert result.ok, result.error
    quality = json.loads((job.run_dir / "metrics.json").read_text())["model_quality"]
    assert set(quality) == {"next_state_rank", "next_state_mean_rank", "feasibility_auroc", "feasibility_auroc_uniform"}
    assert quality["feasibility_auroc"] == quality["feasibility_auroc_uniform"]  # no buffer yet: both uniform
    assert 0.0 < quality["feasibility_auroc"] < 1.0
