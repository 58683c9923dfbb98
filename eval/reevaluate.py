"""Evaluate a finished run again with its planning settings changed, without training it again.

A planner agent's ``predict`` reads settings that learning never touches (when to replan, where subgoals sit): a
change of one of them leaves the trained weights as they are. ``python -m eval.reevaluate RUN_DIR --set KEY=VALUE``
loads the run's ``model.zip``, rebuilds its subgoal graph from ``graph_transitions.npz`` (as ``learn`` does at its
end; a pretrained run's from its training dataset), applies the changes and runs the run's evaluation again (its
env, seed and episodes; ``--evaluation NAME``: one of its extra evaluations, e.g. a maze start/goal pair)::

    python -m eval.reevaluate runs/results/beyond_online_explore_unstick/maze/ebm/seed_0 \\
        --set online.arrival_threshold=0.025 subgoal_graph.lookahead=15

Only ``online.*`` (:class:`~ebm_agent.config.OnlineConfig`; of its fields only the evaluation ones,
``replan_threshold``, ``arrival_threshold`` and ``arrival_at``, change ``predict``) and ``subgoal_graph.*``
(:meth:`~ebm_agent.subgoals.GraphSubgoals.from_transitions`) can be set. It is a probe for choosing settings: a
setting worth keeping goes into the harness's hyperparameters and is measured by a run of its own, whose record
is what the docs cite. The recorded final evaluation of an online run is EvalCallback's at the last step, planned
with the graph of the last rebuild during ``learn``; this one plans with the graph of the whole replay buffer, as
``predict`` after ``learn`` does, so the unchanged settings can score a little differently.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import torch
import yaml
from stable_baselines3.common.env_util import make_vec_env

from baselines.action_ff import ActionFFAgent
from ebm_agent.agent import EBMPlannerAgent
from eval.jobs import GRAPH_TRANSITIONS, Job
from eval.pretraining import load_or_build_dataset, training_data
from eval.provenance import read_metrics
from eval.registry import get_agent
from eval.run import evaluate_with

__all__ = ["JOB_FIELDS", "PLANNERS", "SETTABLE", "apply_settings", "graph_transitions", "main", "parse_settings", "reevaluate"]

SETTABLE: tuple[str, ...] = ("online", "subgoal_graph")
"""The sections ``--set`` may change: the agent's OnlineConfig and its subgoal graph's keywords."""

JOB_FIELDS: tuple[str, ...] = tuple(field.name for field in dataclasses.fields(Job))
"""A run's ``config.yaml`` is its Job's fields plus its fingerprint and versions: these rebuild the Job."""

PLANNERS: dict[str, Any] = {cls.__name__: cls for cls in (EBMPlannerAgent, ActionFFAgent)}
"""The agent classes with planning settings, by the class name of their harness registration."""


def parse_settings(items: list[str]) -> dict[str, dict[str, Any]]:
    """``["online.arrival_threshold=0.025", ...]`` -> ``{"online": {"arrival_threshold": 0.025}}`` (values as YAML).

    :raises ValueError: for an item without ``SECTION.KEY=VALUE`` form or with a section outside :data:`SETTABLE`.
    """
    settings: dict[str, dict[str, Any]] = {}
    for item in items:
        name, sep, value = item.partition("=")
        section, dot, key = name.partition(".")
        if not sep or not dot or not key:
            raise ValueError(f"--set takes SECTION.KEY=VALUE (e.g. online.arrival_threshold=0.025), got {item!r}.")
        if section not in SETTABLE:
            raise ValueError(f"--set can change {', '.join(SETTABLE)} (evaluation-time settings), not {section!r}.")
        settings.setdefault(section, {})[key] = yaml.safe_load(value)
    return settings


def apply_settings(model: Any, settings: dict[str, dict[str, Any]]) -> None:
    """Change a loaded planner agent's evaluation-time settings (validated as at construction).

    :param model: a :class:`~ebm_agent.base.PlannerAgentBase`.
    :param settings: from :func:`parse_settings`.
    :raises ValueError: for an agent without these settings (PPO, SAC), or a subgoal graph setting on an agent
        without ``subgoal_graph``.
    :raises TypeError: for an unknown OnlineConfig or SubgoalGraphConfig field or a value of the wrong type.
    """
    if not hasattr(model, "online") or not hasattr(model, "subgoal_graph"):
        raise ValueError(f"{type(model).__name__} has no planning settings to change: only {', '.join(PLANNERS)}.")
    if "online" in settings:
        valid = {f.name for f in dataclasses.fields(model.online)}
        unknown = sorted(set(settings["online"]) - valid)
        if unknown:
            raise TypeError(f"online: unknown keys {unknown}; valid keys are {sorted(valid)}.")
        model.online = dataclasses.replace(model.online, **settings["online"])  # __post_init__ checks the values
    if "subgoal_graph" in settings:
        if model.subgoal_graph is None:
            raise ValueError("subgoal_graph settings need a run made with subgoal_graph (this one plans to the goal).")
        valid = {f.name for f in dataclasses.fields(model.subgoal_graph)}
        unknown = sorted(set(settings["subgoal_graph"]) - valid)
        if unknown:
            raise TypeError(f"subgoal_graph: unknown keys {unknown}; valid keys are {sorted(valid)}.")
        model.subgoal_graph = dataclasses.replace(model.subgoal_graph, **settings["subgoal_graph"])


def reevaluate(
    run_dir: Path, settings: dict[str, dict[str, Any]], evaluation: str | None = None, episodes: int | None = None
) -> dict[str, Any]:
    """Evaluate a finished run again with ``settings`` changed.

    :param run_dir: a run folder of the harness (``config.yaml``, ``model.zip``, ``metrics.json``).
    :param settings: from :func:`parse_settings` (``{}``: the run's own).
    :param evaluation: an extra evaluation's name (``config.yaml``'s ``extra_evaluations``), or None for the main one.
    :param episodes: deterministic episodes (default: the run's ``eval_episodes``).
    :return: the settings, the recorded score and the new scores (``score_mean``, ``success_rate``, per episode).
    :raises FileNotFoundError: for a folder without a finished run.
    :raises ValueError: for an unknown evaluation, or settings the agent does not have.
    """
    run_dir = Path(run_dir)
    metrics = read_metrics(run_dir)
    if metrics is None or not (run_dir / "config.yaml").is_file() or not (run_dir / "model.zip").is_file():
        raise FileNotFoundError(f"{run_dir} has no finished harness run (config.yaml, model.zip, metrics.json).")
    config = yaml.safe_load((run_dir / "config.yaml").read_text())
    job = Job(**{name: config[name] for name in JOB_FIELDS if name in config})
    if episodes is not None:
        job = dataclasses.replace(job, eval_episodes=int(episodes))
    recorded, changes = metrics["score_mean"], {}
    if evaluation is not None:
        if evaluation not in job.extra_evaluations:
            raise ValueError(f"{run_dir} has no evaluation {evaluation!r}; it has {sorted(job.extra_evaluations) or 'none'}.")
        recorded, changes = metrics["extra_evaluations"][evaluation]["score_mean"], job.extra_evaluations[evaluation]
    agent_class = PLANNERS.get(get_agent(job.agent).class_name or "")
    if agent_class is None:
        raise ValueError(f"{job.agent!r} has no planning settings to change: only {', '.join(PLANNERS)}.")
    # The model gets an env of its own: loading resets the env it is given, which would use up an evaluation env's
    # seeded first reset and evaluate other episodes than the run's.
    own_env = make_vec_env(job.env_id, n_envs=1, seed=job.seed, env_kwargs=dict(job.env_kwargs))
    try:
        model = agent_class.load(run_dir / "model.zip", env=own_env, device="cpu")
        apply_settings(model, settings)
        if model.subgoal_graph is not None:
            model.build_subgoals(*graph_transitions(run_dir, job))
        scores = evaluate_with(model, job, changes)
    finally:
        own_env.close()
    return {
        "run": str(run_dir),
        "evaluation": evaluation or "main",
        "settings": settings,
        "recorded_score_mean": recorded,
        **scores,
    }


def graph_transitions(run_dir: Path, job: Job) -> tuple[np.ndarray, np.ndarray]:
    """The real transitions a run's subgoal graph was built over: its ``graph_transitions.npz`` (an online run's replay
    buffer), or for a pretrained run its training dataset (the cached one, rebuilt the same way where missing).

    :param run_dir: the run folder.
    :param job: its job.
    :return: states [M, D] and next states [M, D].
    :raises FileNotFoundError: for an online run saved without ``graph_transitions.npz`` (finished before the
        harness kept it): evaluated without its graph, it would plan straight at the goal and say nothing of it.
    """
    path = run_dir / GRAPH_TRANSITIONS
    if path.is_file():
        with np.load(path) as data:
            return data["states"], data["next_states"]
    if job.mode == "pretrained":
        base, _ = load_or_build_dataset(job)
        data = training_data(base, job)
        return data.states, data.next_states
    raise FileNotFoundError(
        f"{run_dir} plans through a subgoal graph but has no {GRAPH_TRANSITIONS} (the replay buffer the graph was built "
        "over; runs finished before the harness kept it have none): run it again to re-evaluate it."
    )


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    """The command line: ``python -m eval.reevaluate RUN_DIR [RUN_DIR ...] [--set KEY=VALUE ...]``; prints a table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path, help="finished run folders (runs/results/<variant>/maze/ebm/seed_0)")
    parser.add_argument("--set", nargs="*", default=[], metavar="SECTION.KEY=VALUE", help="online.arrival_threshold=0.025")
    parser.add_argument("--evaluation", default=None, help="one of the run's extra evaluations (e.g. pair1)")
    parser.add_argument("--episodes", type=int, default=None, help="deterministic episodes (default: the run's)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (float results depend on it; default 1)")
    args = parser.parse_args(argv)
    settings = parse_settings(args.set)
    torch.set_num_threads(args.threads)
    results = [reevaluate(run, settings, args.evaluation, args.episodes) for run in args.runs]
    own = json.dumps(settings) if settings else "the runs' own"
    print(f"settings: {own}; evaluation: {args.evaluation or 'main'}")
    print("| run | recorded | re-evaluated | success | mean length |")
    print("|---|---|---|---|---|")
    for result in results:
        success = "-" if result["success_rate"] is None else f"{result['success_rate']:.2f}"
        print(
            f"| {result['run']} | {result['recorded_score_mean']:.2f} | {result['score_mean']:.2f} | {success} | "
            f"{np.mean(result['episode_lengths']):.1f} |"
        )
    if len(results) > 1:
        print(f"mean re-evaluated score: {np.mean([r['score_mean'] for r in results]):.2f} over {len(results)} runs")
    return results


if __name__ == "__main__":
    main()
