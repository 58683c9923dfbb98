"""Running one job (``eval.jobs.Job``): train the agent for exactly its budget, evaluate it, write its run folder.

``run_job`` is a pure function of its ``Job``: it is what a process-pool worker (``LocalExecutor``) or a distributed
task (a Ray executor) runs; the run folder's files are listed in ``eval.jobs``. A run folder is held by one process
at a time (``RUN_LOCK``).
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import socket
import time
import traceback
from dataclasses import asdict
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.logger import TensorBoardOutputFormat, configure

import envs  # noqa: F401  registers the ebm/ ids in this (possibly fresh) process
from baselines.hyperparams import normalized_like
from ebm_agent.datasets import collect_random_transitions
from ebm_agent.presets import merge_settings, preset_settings
from ebm_agent.probe import model_quality
from eval.code_version import CodeChanged, check_code_unchanged, code_version
from eval.evaluation import (
    EpisodeScores,
    EvaluationLine,
    RepeatAwareEvalCallback,
    append_evaluation,
    evaluate_episodes,
    last_evaluation,
)
from eval.jobs import (
    EVAL_SEED_OFFSET,
    GRAPH_TRANSITIONS,
    RESUME_FOLDER,
    RUN_OUTPUTS,
    VEC_NORMALIZE,
    Job,
    JobResult,
    library_versions,
    to_plain,
)
from eval.pretraining import pretrain
from eval.provenance import defaults_digest, job_fingerprint, machine_info
from eval.registry import get_agent
from eval.resume import ResumeCheckpoint, RunState, discard_run_state, read_run_state, resumable, write_run_state
from eval.stop import RunStopped, raise_if_stopped, stop_at_next_step


def run_job(job: Job) -> JobResult:
    """Train one agent on one env for exactly its budget, evaluate it, and write its run folder.

    Never raises for a failure inside the run: the error comes back as a failed ``JobResult`` (and in
    ``error.txt``) so that a sweep keeps its other runs. A planning agent's online run (or directed collection)
    that receives SIGTERM or Ctrl-C during ``learn`` writes its checkpoint and comes back ``"stopped"``
    (``eval.stop``); the next ``run_job`` of the same job resumes it.

    :param job: the run.
    :return: the result.
    """

    start = time.perf_counter()
    run_dir = job.run_dir
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        holder = _take_run_lock(run_dir)
    except Exception:  # another live process owns the folder: leave its files alone
        return JobResult(job=job, status="failed", wall_time_s=0.0, error=traceback.format_exc())
    try:
        check_code_unchanged(f"run {run_dir} not started")
        for name in RUN_OUTPUTS:
            (run_dir / name).unlink(missing_ok=True)
        config = {
            **to_plain(asdict(job)),
            "fingerprint": job_fingerprint(job),
            "versions": library_versions(),
            "code": code_version(),
        }
        (run_dir / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
        return _train_and_evaluate(job, start)
    except RunStopped as stop:  # SIGTERM or Ctrl-C: its checkpoint is written, the next call resumes it
        return JobResult(job=job, status="stopped", wall_time_s=time.perf_counter() - start, error=str(stop))
    except CodeChanged as changed:  # a sweep runs one version of the code (eval.code_version)
        with contextlib.suppress(OSError):
            (run_dir / "error.txt").write_text(f"{changed}\n")
        return JobResult(job=job, status="failed", wall_time_s=time.perf_counter() - start, error=str(changed))
    except Exception:  # a failed run must not end the sweep
        error = traceback.format_exc()
        try:
            (run_dir / "error.txt").write_text(error)
        except OSError:
            pass
        return JobResult(job=job, status="failed", wall_time_s=time.perf_counter() - start, error=error)
    finally:
        holder.unlink(missing_ok=True)


RUN_LOCK = ".running"
"""A run folder's lock file while a process trains in it: ``{"host", "pid"}``."""


def _take_run_lock(run_dir: Path) -> Path:
    """Claim a run folder for this process, so that a second invocation of the same run cannot clobber it.

    A lock left by a process that no longer exists on this host (killed, crashed) is taken over.

    :param run_dir: the folder.
    :return: the lock file, to remove when the run ends.
    :raises RuntimeError: when a live process (or one on another host) holds the folder.
    """

    lock = run_dir / RUN_LOCK
    mine = {"host": socket.gethostname(), "pid": os.getpid()}
    for _ in range(2):
        try:
            with open(lock, "x") as handle:  # atomic: exactly one process creates it
                handle.write(json.dumps(mine))
            return lock
        except FileExistsError:
            if not run_in_progress(run_dir):
                lock.unlink(missing_ok=True)  # stale: its process is gone
                continue
            try:
                held = json.loads(lock.read_text())
            except (OSError, ValueError):
                held = {}
            raise RuntimeError(
                f"{run_dir} is being trained by process {held.get('pid')} on {held.get('host')}: two processes must not "
                f"share a run folder. Wait for it, or, if no such process runs any more, delete {lock}."
            ) from None
    raise RuntimeError(f"could not claim {run_dir} ({lock} keeps reappearing)")


def run_in_progress(run_dir: Path) -> bool:
    """Whether a live process (on this host, or any process on another host) holds the run folder's lock.

    :param run_dir: the folder.
    :return: True while someone trains in it; False with no lock or a stale one.
    """

    lock = Path(run_dir) / RUN_LOCK
    try:
        held = json.loads(lock.read_text())
    except FileNotFoundError:
        return False
    except (OSError, ValueError):
        return True  # being written: its holder has just claimed it
    if held.get("host") != socket.gethostname():
        return True
    return _alive(int(held.get("pid", -1)))


def _alive(pid: int) -> bool:

    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # it exists, owned by someone else
        return True
    return True


def agent_settings(job: Job) -> dict[str, Any]:
    """The agent's keyword arguments: the job's preset (``ebm_agent.presets``) with its ``hyperparams`` over it.

    :param job: the job.
    :return: a new dict.
    """

    class_name = get_agent(job.agent).class_name
    if not job.preset or class_name is None:
        return dict(job.hyperparams)
    return merge_settings(preset_settings(job.preset, class_name), job.hyperparams)


def _train_and_evaluate(job: Job, start: float) -> JobResult:

    spec = get_agent(job.agent)
    run_dir = job.run_dir
    model = spec.factory(
        env_id=job.env_id,
        env_kwargs=dict(job.env_kwargs),
        seed=job.seed,
        tensorboard_log=str(job.tensorboard_log),
        device=job.device,
        hyperparams=agent_settings(job),
        verbose=job.verbose,
    )
    eval_kwargs = evaluation_env_kwargs(job)
    eval_env = normalized_like(
        model, make_vec_env(job.env_id, n_envs=1, seed=job.seed + EVAL_SEED_OFFSET, env_kwargs=eval_kwargs)
    )
    resume = read_run_state(job) if resumable(model, job) else None
    if resume is not None:  # go on from the last checkpoint of a run cut short, with its envs as they were
        fresh_env = model.get_env()
        if fresh_env is not None:
            fresh_env.close()
        eval_env.close()
        agent_class: Any = type(model)  # resumable() checked that it has load_checkpoint (CheckpointMixin)
        model = agent_class.load_checkpoint(resume.agent_path, env=resume.train_env, device=job.device, force_reset=False)
        eval_env = resume.eval_env
    try:
        learn_start = time.perf_counter()
        pretraining: dict[str, Any] | None = None
        if job.mode == "pretrained":
            pretraining = pretrain(model, job)
            timesteps, reused = int(pretraining["dataset_size"]), None
        elif job.mode == "untrained":
            timesteps, reused = 0, None
        else:
            timesteps, reused = _learn_online(model, job, eval_env, spec.callbacks, resume)
        # Time of earlier processes: an online run's up to its checkpoint, a pretrained run's on the directed
        # collection it finished.
        earlier = resume.learn_time_s if resume is not None else 0.0
        if pretraining is not None:
            earlier += float(pretraining.get("collect_time_earlier_processes_s", 0.0))
        learn_time = time.perf_counter() - learn_start + earlier
        eval_start = time.perf_counter()
        episodes = reused or evaluate_episodes(model, eval_env, job.eval_episodes)
        eval_time = time.perf_counter() - eval_start
        append_evaluation(run_dir / "evaluations.npz", timesteps, episodes)
        _log_final_scalars(model, job, timesteps, episodes.score_mean, episodes.success_rate)
        extra = {name: evaluate_with(model, job, changes) for name, changes in job.extra_evaluations.items()}
        model.save(run_dir / "model.zip")
        normalizer = model.get_vec_normalize_env()
        if normalizer is not None:  # the observation statistics the model acts on (SB3's own pickle)
            normalizer.save(str(run_dir / VEC_NORMALIZE))
        save_graph_transitions(model, run_dir / GRAPH_TRANSITIONS)
        quality = model_quality_of(model, job)
        wall_time = time.perf_counter() - start + earlier
        metrics = {
            "env_id": job.env_id,
            "agent": job.agent,
            "seed": job.seed,
            "mode": job.mode,
            "budget": job.timesteps,
            "timesteps": timesteps,
            "budget_respected": timesteps == job.timesteps,
            "n_envs": int(model.n_envs),
            "score_mean": episodes.score_mean,
            "score_std": episodes.score_std,
            "episode_scores": episodes.scores,
            "episode_lengths": episodes.lengths,
            "success_rate": episodes.success_rate,
            "episode_successes": episodes.successes,
            "evaluated_episodes": episodes.evaluated or len(episodes.scores),
            "final_evaluation": "EvalCallback at the final step" if reused else "evaluate_policy after learning",
            "eval_env_kwargs": to_plain(eval_kwargs),
            "extra_evaluations": extra,
            "model_quality": quality,
            "pretraining": pretraining,
            "wall_time_s": wall_time,
            "learn_time_s": learn_time,
            "eval_time_s": eval_time,
            "resumed_at": [*resume.resumed_at, resume.num_timesteps] if resume is not None else [],
            "finished_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "machine": machine_info(model.device),
            "fingerprint": job_fingerprint(job),
            "defaults_digest": defaults_digest(job),
            "versions": library_versions(),
            "code": code_version(),
        }
        # Modules imported while it ran (an env's at gym.make, a worker's) must have been the sweep's version.
        check_code_unchanged(f"run {run_dir} not recorded (its checkpoint is kept)")
        (run_dir / "metrics.json").write_text(json.dumps(to_plain(metrics), indent=2))
        discard_run_state(job)  # finished: the checkpoint is no longer needed
        return JobResult(
            job=job,
            status="ok",
            timesteps=timesteps,
            score_mean=episodes.score_mean,
            score_std=episodes.score_std,
            episode_scores=tuple(episodes.scores),
            episode_lengths=tuple(episodes.lengths),
            success_rate=episodes.success_rate,
            wall_time_s=wall_time,
        )
    finally:
        eval_env.close()
        if getattr(model, "_logger", None) is not None:
            model.logger.close()  # releases the event file: a sweep runs many jobs in one process
        training_env = model.get_env()
        if training_env is not None:
            training_env.close()


def save_graph_transitions(model: Any, path: Path) -> bool:
    """Keep the replay buffer of an online agent with graph subgoals (``subgoal_graph``), which the model file leaves
    out, so that its final graph can be rebuilt and a failed evaluation looked into::

        data = np.load(path); agent.build_subgoals(data["states"], data["next_states"])

    Written atomically (a temporary file, then renamed).

    :param model: the trained agent.
    :param path: the ``.npz`` file to write.
    :return: whether a file was written (not for agents without ``subgoal_graph`` or with an empty buffer).
    """
    buffer = getattr(model, "pos_buffer", None)
    if getattr(model, "subgoal_graph", None) is None or buffer is None or len(buffer) == 0:
        return False
    real = buffer.contents()
    partial = path.with_name(path.name + ".partial")
    with open(partial, "wb") as file:
        np.savez_compressed(file, states=real.states, next_states=real.next_states, actions=real.actions)
    os.replace(partial, path)
    return True


PROBE_MOVES = 2000
"""(state, move) samples of each feasibility AUROC a finished run records (``ebm_agent.probe``)."""

PROBE_TRANSITIONS = 1000
"""Held-out random transitions of the next-state rank a finished run records."""


def model_quality_of(model: Any, job: Job) -> dict[str, float] | None:
    """The model-quality probe of a trained agent with an energy (``ebm_agent.probe.model_quality``), for its record.

    Measured on the training env's task (its ``env_kwargs``: e.g. the random-start maze a pretrained model learned),
    on held-out random transitions and moves seeded ``job.seed + EVAL_SEED_OFFSET``, after the model is saved: the run's
    scores do not depend on it.

    :param model: the trained agent.
    :param job: its job.
    :return: the probe's values by key, or None for an agent without an ``energy_model`` (PPO, Action FF).
    """
    if not callable(getattr(model, "energy_model", None)):
        return None
    seed = job.seed + EVAL_SEED_OFFSET
    env = gym.make(job.env_id, **job.env_kwargs)
    try:
        held_out = collect_random_transitions(env, PROBE_TRANSITIONS, seed=seed)
        quality, _, _ = model_quality(model, env, held_out, PROBE_MOVES, seed=seed)
    finally:
        env.close()
    return quality


def evaluation_env_kwargs(job: Job) -> dict[str, Any]:
    """Keyword arguments of the job's evaluation env: ``eval_env_kwargs``, or the training env's when None.

    :param job: the job.
    :return: a fresh dict.
    """
    return dict(job.env_kwargs if job.eval_env_kwargs is None else job.eval_env_kwargs)


def _learn_online(
    model: Any, job: Job, eval_env: Any, callbacks: Any, resume: RunState | None = None
) -> tuple[int, EpisodeScores | None]:
    """``learn`` for exactly the budget with ``EvalCallback`` writing the learning curve (and, for the planning
    agents, a checkpoint after each evaluation: ``eval.resume``).

    :param resume: the checkpoint the run goes on from (None: a fresh run).
    :return: the transitions consumed and the callback's final-step evaluation when it can stand as the final one.
    """

    after_eval: list[BaseCallback] = []
    if not job.progress_bar:  # one line per evaluation says that a long run is alive and how far it is
        after_eval.append(EvaluationLine(str(job.run_dir), job.timesteps))
    # EvalCallback counts callback calls, i.e. vectorised steps: n_envs transitions each.
    eval_callback = RepeatAwareEvalCallback(
        eval_env,
        n_eval_episodes=job.eval_episodes,
        eval_freq=max(job.eval_freq // model.n_envs, 1),
        log_path=str(job.run_dir),
        deterministic=True,
        verbose=0,
        warn=False,
        callback_after_eval=CallbackList(after_eval) if after_eval else None,
    )
    if resume is not None:
        resume.refill(eval_callback)
        # A resumed run's calls count from its checkpoint (taken at an evaluation, or wherever a stop was asked
        # for), so that the later evaluations fall where an uninterrupted run's would.
        eval_callback.n_calls = resume.num_timesteps // model.n_envs
    extra = callbacks(job.timesteps) if callbacks is not None else []
    learn = functools.partial(
        model.learn,
        total_timesteps=job.timesteps - (resume.num_timesteps if resume is not None else 0),
        tb_log_name=job.tb_log_name,
        reset_num_timesteps=resume is None,
        progress_bar=job.progress_bar,
    )
    if not resumable(model, job):  # PPO's minutes-long runs: no checkpoints, signals keep their usual effect
        learn(callback=CallbackList([*extra, eval_callback]))
    else:
        before, resumed_at = (resume.learn_time_s, [*resume.resumed_at, resume.num_timesteps]) if resume else (0.0, [])

        def write(elapsed_s: float) -> None:
            write_run_state(job, model, eval_callback, before + elapsed_s, resumed_at)

        with stop_at_next_step() as flag:
            checkpoint = ResumeCheckpoint(write, job.timesteps, after=eval_callback, flag=flag)
            learn(callback=CallbackList([*extra, eval_callback, checkpoint]))
        raise_if_stopped(flag, int(model.num_timesteps), job.timesteps, f"run {job.run_dir}", job.run_dir / RESUME_FOLDER)
    timesteps = int(model.num_timesteps)
    # An evaluation EvalCallback just ran at the final step is the final evaluation (same call, same env):
    # reuse it rather than pay for the episodes twice, which for a planner costs as much as learning.
    return timesteps, last_evaluation(eval_callback, timesteps, job.eval_episodes)


def evaluate_with(model: Any, job: Job, changes: dict[str, Any]) -> dict[str, Any]:
    """Evaluate the trained model on the job's evaluation env with ``changes`` to its kwargs (same seed, the job's
    ``eval_episodes``): an extra evaluation (``{}``: the main one again, as ``eval.reevaluate`` does).

    :return: the env kwargs used and the scores, as in ``metrics.json``.
    """

    kwargs = {**evaluation_env_kwargs(job), **changes}
    env = normalized_like(model, make_vec_env(job.env_id, n_envs=1, seed=job.seed + EVAL_SEED_OFFSET, env_kwargs=kwargs))
    try:
        episodes = evaluate_episodes(model, env, job.eval_episodes)
    finally:
        env.close()
    return {
        "env_kwargs": to_plain(kwargs),
        "score_mean": episodes.score_mean,
        "score_std": episodes.score_std,
        "episode_scores": episodes.scores,
        "episode_lengths": episodes.lengths,
        "success_rate": episodes.success_rate,
    }


def _log_final_scalars(model: Any, job: Job, timesteps: int, score_mean: float, success_rate: float | None) -> None:
    """Write the final evaluation to TensorBoard, into the model's own run folder when it has one.

    An agent that ignored ``tensorboard_log`` gets a folder of its own, so that every run shows up.
    """

    logger = model.logger if getattr(model, "_logger", None) is not None else None
    owns_logger = logger is None or not any(isinstance(f, TensorBoardOutputFormat) for f in logger.output_formats)
    if owns_logger:
        logger = configure(str(job.tensorboard_log / f"{job.tb_log_name}_1"), ["tensorboard"])
    assert logger is not None
    logger.record("final/score_mean", score_mean)
    if success_rate is not None:
        logger.record("final/success_rate", success_rate)
    logger.dump(timesteps)
    if owns_logger:
        logger.close()


__all__ = [
    "PROBE_MOVES",
    "PROBE_TRANSITIONS",
    "RUN_LOCK",
    "agent_settings",
    "evaluate_with",
    "evaluation_env_kwargs",
    "model_quality_of",
    "run_in_progress",
    "run_job",
    "save_graph_transitions",
]
