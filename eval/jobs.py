"""One training run of the comparison (env, agent, seed, budget) as a picklable job, and the function that runs it.

``run_job`` is a pure function of its ``Job``: it is what a process-pool worker (``LocalExecutor``) or a
distributed task (a Ray executor) runs, and its ``JobResult`` carries only plain Python values back.

A job learns either online (``mode="online"``: ``learn(total_timesteps)``, Algorithm 1 for the planners) or from
a fixed dataset (``mode="pretrained"``: the paper's pretrained rows, Tables 1-2; see ``eval.pretraining``), or not
at all (``mode="untrained"``, budget 0: the agent as built, the control that says what its planner and inverse
dynamics do before any learning), then is evaluated the same way, so all write the same files.

Run folder ``<out>[/<variant>]/<env_short>/<agent>/seed_<k>/``:

- ``config.yaml``: the job, its fingerprint and the library versions;
- ``evaluations.npz``: SB3's ``EvalCallback`` file (``timesteps``, ``results``, ``ep_lengths``[, ``successes``]),
  with the final evaluation appended when the callback's last one was earlier (a pretrained run has one row);
- ``metrics.json``: the final deterministic evaluation, any extra evaluations, the transitions really consumed,
  wall times, the machine and the job's fingerprint (``eval.provenance.completed_result`` reads it back, so that a
  finished job is skipped);
- ``model.zip``: the trained model; ``error.txt`` instead when the job failed.

TensorBoard events go to ``<out>[/<variant>]/tb/<env_short>/<agent>_s<seed>_1/`` so that ``tensorboard --logdir
<out>`` shows every agent and seed of an env side by side.
"""

from __future__ import annotations

import functools
import json
import platform
import time
import traceback
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

if TYPE_CHECKING:  # SB3 loads only inside a run
    from stable_baselines3.common.callbacks import BaseCallback

    from eval.evaluation import EpisodeScores
    from eval.resume import RunState

EVAL_SEED_OFFSET = 10_000
"""The evaluation env is seeded ``seed + EVAL_SEED_OFFSET`` so that it never replays the training env's episodes."""

MODES = ("online", "pretrained", "untrained")
"""How a job learns: online interaction (``learn``) or a fixed dataset (``learn_offline``)."""

DATASETS = ("random", "directed", "directed+sequential")
"""Datasets of pretrained jobs (paper Table 2); see ``eval.pretraining``."""

RESUME_FOLDER = "resume"
"""The run folder's subfolder holding the latest checkpoint of an unfinished online run (``eval.resume``)."""

STATE_FILE = "state.json"
"""The file in ``RESUME_FOLDER`` that names the checkpoint's two files; written last."""

RUN_OUTPUTS = ("metrics.json", "evaluations.npz", "model.zip", "error.txt")
"""Files a run writes; a rerun removes stale ones first (an old ``evaluations.npz`` would join the new curve)."""


@dataclass(frozen=True)
class Job:
    """Everything one training run needs; picklable.

    :param env_id: registered Gymnasium id (short names are resolved by the CLI).
    :param agent: a key of ``eval.registry.AGENTS``.
    :param seed: seed of the agent and of its training env.
    :param timesteps: budget: transitions the agent may learn from.
    :param eval_freq: evaluate every ``eval_freq`` transitions (converted to per-env calls for ``EvalCallback``).
    :param eval_episodes: deterministic episodes per evaluation.
    :param hyperparams: keyword arguments of the agent.
    :param env_kwargs: keyword arguments of ``gym.make`` for the training env.
    :param eval_env_kwargs: keyword arguments of the evaluation env (None: ``env_kwargs``), e.g. the paper's fixed
        evaluation start for an agent trained from random starts.
    :param device: torch device.
    :param out_dir: root folder of the sweep.
    :param verbose: SB3 verbosity of the agent.
    :param progress_bar: show SB3's progress bar during ``learn`` (for in-process runs).
    :param mode: ``"online"`` (learn from ``timesteps`` transitions of interaction) or ``"pretrained"`` (learn
        offline from a dataset of ``timesteps`` transitions, then evaluate; only agents with ``learn_offline``) or
        ``"untrained"`` (evaluate the agent as built; ``timesteps`` must be 0).
    :param dataset: pretrained only: ``"random"``, ``"directed"`` or ``"directed+sequential"`` (``eval.pretraining``).
    :param offline_kwargs: pretrained only: ``epochs``, ``batch_size`` of ``learn_offline`` and ``repeat`` (copies
        of each transition in the sequential dataset); unset keys take ``eval.pretraining``'s defaults.
    :param dataset_kwargs: pretrained, directed only: keyword arguments of the EBM agent that collects the dataset.
    :param extra_evaluations: name -> changes to the evaluation env's kwargs: the trained model is also evaluated
        on each such env (e.g. ``{"variable_goal": {"goal": "variable"}}`` for a fixed-goal model); the scores go to
        ``metrics.json`` under ``extra_evaluations``.
    :param variant: a label of the training configuration; it prefixes the run folder (``<out>/<variant>/...``) so
        that runs of several configurations of one env and agent live side by side.
    :param preset: the agent preset (``ebm_agent.presets``): ``""`` for the library's defaults, ``"paper"`` for the
        original code's settings; ``hyperparams`` are applied over it. Agents the preset does not name ignore it.
    """

    env_id: str
    agent: str
    seed: int
    timesteps: int
    eval_freq: int
    eval_episodes: int
    hyperparams: dict[str, Any] = field(default_factory=dict)
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    eval_env_kwargs: dict[str, Any] | None = None
    device: str = "auto"
    out_dir: str = "runs"
    verbose: int = 0
    progress_bar: bool = False
    mode: str = "online"
    dataset: str = "random"
    offline_kwargs: dict[str, Any] = field(default_factory=dict)
    dataset_kwargs: dict[str, Any] = field(default_factory=dict)
    extra_evaluations: dict[str, dict[str, Any]] = field(default_factory=dict)
    variant: str = ""
    preset: str = ""

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"Job.mode must be one of {MODES}, got {self.mode!r}")
        if self.mode == "untrained" and self.timesteps != 0:
            raise ValueError(f"Job.timesteps must be 0 for an untrained job (it learns nothing), got {self.timesteps}")
        if self.dataset not in DATASETS:
            raise ValueError(f"Job.dataset must be one of {DATASETS}, got {self.dataset!r}")
        from ebm_agent.presets import PRESETS

        if self.preset not in ("", *PRESETS):
            raise ValueError(
                f"Job.preset must be '' (the library's defaults) or one of {sorted(PRESETS)}, got {self.preset!r}"
            )
        if Path(self.variant).is_absolute() or ".." in Path(self.variant).parts:
            raise ValueError(f"Job.variant must be a relative folder name inside the output folder, got {self.variant!r}")

    @property
    def root(self) -> Path:
        """``<out>/<variant>``, or ``<out>`` without a variant."""
        return Path(self.out_dir) / self.variant if self.variant else Path(self.out_dir)

    @property
    def env_short(self) -> str:
        """The env's short name (``particle``) or its id made safe for a folder name."""
        return env_short_name(self.env_id)

    @property
    def run_dir(self) -> Path:
        """``<out>[/<variant>]/<env_short>/<agent>/seed_<k>``."""
        return self.root / self.env_short / self.agent / f"seed_{self.seed}"

    @property
    def tensorboard_log(self) -> Path:
        """``<out>[/<variant>]/tb/<env_short>``: one TensorBoard folder per env, one subfolder per agent and seed."""
        return self.root / "tb" / self.env_short

    @property
    def tb_log_name(self) -> str:
        """``<agent>_s<seed>``; SB3 appends ``_1`` to name the run folder."""
        return f"{self.agent}_s{self.seed}"


@dataclass(frozen=True)
class JobResult:
    """What a job produced; plain Python values only, so it pickles across processes.

    :param job: the job.
    :param status: "ok", "failed", or "stopped" (a signal stopped it after writing its checkpoint: run it again).
    :param timesteps: transitions the agent really consumed (``model.num_timesteps``).
    :param score_mean: mean final evaluation score.
    :param score_std: population std of the final evaluation scores over episodes.
    :param episode_scores: each final evaluation episode's score.
    :param episode_lengths: each final evaluation episode's length.
    :param success_rate: fraction of successful final evaluation episodes, None if the env does not say.
    :param wall_time_s: wall time of the whole job.
    :param error: the traceback when the job failed; for a stopped one, where it stopped and its checkpoint.
    """

    job: Job
    status: str
    timesteps: int = 0
    score_mean: float = float("nan")
    score_std: float = float("nan")
    episode_scores: tuple[float, ...] = ()
    episode_lengths: tuple[int, ...] = ()
    success_rate: float | None = None
    wall_time_s: float = 0.0
    error: str | None = None

    @property
    def ok(self) -> bool:
        """True when the job finished."""
        return self.status == "ok"

    @property
    def run_dir(self) -> Path:
        """The job's run folder."""
        return self.job.run_dir


def env_short_name(env_id: str) -> str:
    """The CLI short name of a registered id (``ebm/Particle-v0`` -> ``particle``), else a folder-safe id.

    :param env_id: Gymnasium id, optionally ``module:id``.
    :return: a name without path separators.
    """
    from envs import ENV_IDS

    for short, registered in ENV_IDS.items():
        if env_id in (registered, f"envs:{registered}"):
            return short
    return env_id.replace("/", "_").replace(":", "_")


def to_plain(value: Any) -> Any:
    """Turn tuples, numpy scalars and arrays into lists and Python numbers, so YAML and JSON accept them.

    :param value: a nested structure of dicts, sequences and scalars.
    :return: the same structure built from dict, list, str, int, float, bool and None only.
    """
    return json.loads(json.dumps(value, default=lambda obj: obj.tolist() if hasattr(obj, "tolist") else str(obj)))


def library_versions() -> dict[str, str]:
    """Versions that decide a run's numbers, for ``config.yaml`` and ``metrics.json``.

    :return: package name -> version.
    """
    from importlib import metadata

    versions = {"python": platform.python_version()}
    for package in ("ebm-agent", "torch", "numpy", "gymnasium", "stable-baselines3", "mujoco"):
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            versions[package] = "not installed"
    return versions


def run_job(job: Job) -> JobResult:
    """Train one agent on one env for exactly its budget, evaluate it, and write its run folder.

    Never raises for a failure inside the run: the error comes back as a failed ``JobResult`` (and in
    ``error.txt``) so that a sweep keeps its other runs. A planning agent's online run (or directed collection)
    that receives SIGTERM or Ctrl-C during ``learn`` writes its checkpoint and comes back ``"stopped"``
    (``eval.stop``); the next ``run_job`` of the same job resumes it.

    :param job: the run.
    :return: the result.
    """
    from eval.provenance import job_fingerprint
    from eval.stop import RunStopped

    start = time.perf_counter()
    run_dir = job.run_dir
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        holder = _take_run_lock(run_dir)
    except Exception:  # another live process owns the folder: leave its files alone
        return JobResult(job=job, status="failed", wall_time_s=0.0, error=traceback.format_exc())
    try:
        for name in RUN_OUTPUTS:
            (run_dir / name).unlink(missing_ok=True)
        config = {**to_plain(asdict(job)), "fingerprint": job_fingerprint(job), "versions": library_versions()}
        (run_dir / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
        return _train_and_evaluate(job, start)
    except RunStopped as stop:  # SIGTERM or Ctrl-C: its checkpoint is written, the next call resumes it
        return JobResult(job=job, status="stopped", wall_time_s=time.perf_counter() - start, error=str(stop))
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
    import os
    import socket

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
    import socket

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
    import os

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
    from ebm_agent.presets import merge_settings, preset_settings
    from eval.registry import get_agent

    class_name = get_agent(job.agent).class_name
    if not job.preset or class_name is None:
        return dict(job.hyperparams)
    return merge_settings(preset_settings(job.preset, class_name), job.hyperparams)


def _train_and_evaluate(job: Job, start: float) -> JobResult:
    from stable_baselines3.common.env_util import make_vec_env

    import envs  # noqa: F401  registers the ebm/ ids in this (possibly fresh) process
    from eval.evaluation import append_evaluation, evaluate_episodes
    from eval.provenance import defaults_digest, job_fingerprint, machine_info
    from eval.registry import get_agent
    from eval.resume import discard_run_state, read_run_state, resumable

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
    eval_env = make_vec_env(job.env_id, n_envs=1, seed=job.seed + EVAL_SEED_OFFSET, env_kwargs=eval_kwargs)
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
            from eval.pretraining import pretrain

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
        extra = {name: _extra_evaluation(model, job, changes) for name, changes in job.extra_evaluations.items()}
        model.save(run_dir / "model.zip")
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
            "final_evaluation": "EvalCallback at the final step" if reused else "evaluate_policy after learning",
            "eval_env_kwargs": to_plain(eval_kwargs),
            "extra_evaluations": extra,
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
        }
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
    from stable_baselines3.common.callbacks import CallbackList, EvalCallback

    from eval.evaluation import EvaluationLine, last_evaluation
    from eval.resume import RunCheckpoint, resumable
    from eval.stop import CheckpointOnStop, raise_if_stopped, stop_at_next_step

    after_eval: list[BaseCallback] = []
    if not job.progress_bar:  # one line per evaluation says that a long run is alive and how far it is
        after_eval.append(EvaluationLine(str(job.run_dir), job.timesteps))
    checkpoint: RunCheckpoint | None = None
    if resumable(model, job):
        checkpoint = RunCheckpoint(job, *((resume.learn_time_s, [*resume.resumed_at, resume.num_timesteps]) if resume else ()))
        after_eval.append(checkpoint)
    # EvalCallback counts callback calls, i.e. vectorised steps: n_envs transitions each.
    eval_callback = EvalCallback(
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
    if checkpoint is None:  # not resumable (PPO's minutes-long runs): signals keep their usual effect
        learn(callback=CallbackList([*extra, eval_callback]))
    else:
        run_checkpoint = checkpoint
        with stop_at_next_step() as flag:
            on_stop = CheckpointOnStop(flag, lambda: run_checkpoint.save(eval_callback), lambda: run_checkpoint.saved_at)
            learn(callback=CallbackList([*extra, eval_callback, on_stop]))
        raise_if_stopped(flag, int(model.num_timesteps), job.timesteps, f"run {job.run_dir}", job.run_dir / RESUME_FOLDER)
    timesteps = int(model.num_timesteps)
    # An evaluation EvalCallback just ran at the final step is the final evaluation (same call, same env):
    # reuse it rather than pay for the episodes twice, which for a planner costs as much as learning.
    return timesteps, last_evaluation(eval_callback, timesteps, job.eval_episodes)


def _extra_evaluation(model: Any, job: Job, changes: dict[str, Any]) -> dict[str, Any]:
    """Evaluate the trained model on the evaluation env with ``changes`` to its kwargs (same seed, same episodes).

    :return: the env kwargs used and the scores, as in ``metrics.json``.
    """
    from stable_baselines3.common.env_util import make_vec_env

    from eval.evaluation import evaluate_episodes

    kwargs = {**evaluation_env_kwargs(job), **changes}
    env = make_vec_env(job.env_id, n_envs=1, seed=job.seed + EVAL_SEED_OFFSET, env_kwargs=kwargs)
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
    from stable_baselines3.common.logger import TensorBoardOutputFormat, configure

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
    "DATASETS",
    "EVAL_SEED_OFFSET",
    "MODES",
    "Job",
    "JobResult",
    "env_short_name",
    "evaluation_env_kwargs",
    "library_versions",
    "run_job",
    "to_plain",
]
