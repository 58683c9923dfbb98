"""Deterministic episodes that are bound to repeat run once and stand for all of them, with the same numbers."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.logger import configure

import envs  # noqa: F401
from ebm_agent import EBMPlannerAgent
from eval import evaluation
from eval.evaluation import RepeatAwareEvalCallback, draws_no_randomness, evaluate_episodes, repeats_exactly
from eval.jobs import Job
from eval.run import run_job

TINY = {"planner_config": {"num_samples": 8, "iterations": 2}, "horizon": 5}
FIXED = {"start": (0.0, 0.0), "goal": (0.5, 0.5), "max_episode_steps": 12}


def _agent() -> EBMPlannerAgent:
    return EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Particle-v0"), seed=0, device="cpu", **TINY)


class CountingAgent:
    """Counts the episodes ``predict`` is asked to start."""

    def __init__(self, agent: EBMPlannerAgent) -> None:
        self.agent, self.starts = agent, 0

    def __getattr__(self, name: str):
        return getattr(self.agent, name)

    def predict(self, observation, state=None, episode_start=None, deterministic=False):
        self.starts += int(np.sum(episode_start)) if episode_start is not None else 0
        return self.agent.predict(observation, state, episode_start, deterministic)


def test_which_envs_draw_no_randomness():
    assert draws_no_randomness(gym.make("ebm/Maze-v0"))  # its fixed start and goal
    assert draws_no_randomness(gym.make("ebm/Particle-v0", start=(0.0, 0.0), goal=(0.5, 0.5)))
    assert not draws_no_randomness(gym.make("ebm/Particle-v0"))  # random starts
    assert not draws_no_randomness(gym.make("ebm/Reacher-v0"))  # Reacher-v4's reset noise


def test_one_episode_stands_for_identical_ones_with_the_same_numbers(monkeypatch):
    env = make_vec_env("ebm/Particle-v0", n_envs=1, seed=7, env_kwargs=FIXED)
    counted = CountingAgent(_agent())
    once = evaluate_episodes(counted, env, 4)
    assert counted.starts == 1 and once.evaluated == 1
    monkeypatch.setattr(evaluation, "repeats_exactly", lambda model, eval_env: False)  # every episode, as before
    counted.starts = 0
    every = evaluate_episodes(counted, make_vec_env("ebm/Particle-v0", n_envs=1, seed=7, env_kwargs=FIXED), 4)
    assert counted.starts == 4 and every.evaluated is None
    assert (once.scores, once.lengths, once.successes) == (every.scores, every.lengths, every.successes)
    assert once.score_mean == every.score_mean and once.score_std == every.score_std == 0.0


def test_random_starts_or_a_subgoal_graph_run_every_episode():
    agent = _agent()
    assert not repeats_exactly(agent, make_vec_env("ebm/Particle-v0", n_envs=1, seed=0))
    assert repeats_exactly(agent, make_vec_env("ebm/Particle-v0", n_envs=1, seed=0, env_kwargs=FIXED))
    agent.subgoals = object()  # a graph keeps stall bookkeeping from one episode to the next
    assert not agent.deterministic_episodes_repeat
    assert not repeats_exactly(agent, make_vec_env("ebm/Particle-v0", n_envs=1, seed=0, env_kwargs=FIXED))


def test_the_learning_curve_lists_the_one_episode_for_all(tmp_path):
    agent = _agent()
    agent.set_logger(configure(str(tmp_path), []))  # what learn sets up
    counted = CountingAgent(agent)
    callback = RepeatAwareEvalCallback(
        make_vec_env("ebm/Particle-v0", n_envs=1, seed=7, env_kwargs=FIXED),
        n_eval_episodes=3,
        eval_freq=1,
        log_path=str(tmp_path),
        verbose=0,
        warn=False,
    )
    callback.init_callback(agent)
    callback.model = counted  # the evaluation calls predict on the callback's model
    assert callback.on_step() and callback.on_step()  # two evaluations: a curve of two rows
    assert callback.repeats and counted.starts == 2
    with np.load(tmp_path / "evaluations.npz") as data:
        assert data["results"].shape == (2, 3) and len(set(data["results"][0])) == 1
        assert data["ep_lengths"].shape == (2, 3) and data["successes"].shape == (2, 3)


def test_a_run_records_how_many_episodes_it_evaluated(tmp_path):
    job = Job(
        "ebm/Particle-v0",
        "ebm",
        0,
        timesteps=0,
        mode="untrained",
        eval_episodes=3,
        eval_freq=1,
        out_dir=str(tmp_path),
        hyperparams=TINY,
        env_kwargs=FIXED,
    )
    result = run_job(job)
    assert result.ok, result.error
    metrics = json.loads((job.run_dir / "metrics.json").read_text())
    assert metrics["evaluated_episodes"] == 1 and len(metrics["episode_scores"]) == 3
    assert len(set(metrics["episode_scores"])) == 1


@pytest.mark.parametrize("agent", ["random"])
def test_agents_that_do_not_declare_it_run_every_episode(agent):
    from eval.registry import get_agent

    model = get_agent(agent).factory(
        env_id="ebm/Particle-v0",
        env_kwargs=dict(FIXED),
        seed=0,
        tensorboard_log=None,
        device="cpu",
        hyperparams={},
        verbose=0,
    )
    assert not repeats_exactly(model, make_vec_env("ebm/Particle-v0", n_envs=1, seed=0, env_kwargs=FIXED))


def test_an_online_run_with_several_evaluations_lists_each_for_all_its_episodes(tmp_path):
    job = Job(
        "ebm/Particle-v0",
        "ebm",
        0,
        timesteps=40,
        eval_freq=20,
        eval_episodes=3,
        out_dir=str(tmp_path),
        hyperparams=TINY,
        eval_env_kwargs=FIXED,
    )
    result = run_job(job)
    assert result.ok, result.error
    with np.load(job.run_dir / "evaluations.npz") as data:
        assert data["timesteps"].tolist() == [20, 40] and data["results"].shape == (2, 3)
    assert json.loads((job.run_dir / "metrics.json").read_text())["evaluated_episodes"] == 1
