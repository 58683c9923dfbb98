"""One training run of the comparison (env, agent, seed, budget) as a picklable job, and what it produced.

``eval.run.run_job`` is a pure function of its ``Job``: it is what a process-pool worker (``LocalExecutor``) or a
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
- ``model.zip``: the trained model; ``error.txt`` instead when the job failed;
- ``vecnormalize.pkl``: for a model trained on normalised observations (a baseline entry's ``normalize``), the
  statistics it acts on.

TensorBoard events go to ``<out>[/<variant>]/tb/<env_short>/<agent>_s<seed>_1/`` so that ``tensorboard --logdir
<out>`` shows every agent and seed of an env side by side.
"""

from __future__ import annotations

import json
import platform
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any

from ebm_agent.presets import PRESETS
from envs import ENV_IDS, THIRD_PARTY_ENV_IDS

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

GRAPH_TRANSITIONS = "graph_transitions.npz"
"""The real transitions an agent with graph subgoals built its final graph from, kept beside its model."""

VEC_NORMALIZE = "vecnormalize.pkl"
"""The observation statistics of a model trained on a ``VecNormalize`` env (an entry's ``normalize``), beside its
model: ``VecNormalize.load(path, venv)`` gives the env it acts on."""

RUN_OUTPUTS = ("metrics.json", "evaluations.npz", "model.zip", GRAPH_TRANSITIONS, VEC_NORMALIZE, "error.txt")
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
    for short, registered in (*ENV_IDS.items(), *THIRD_PARTY_ENV_IDS.items()):
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
    versions = {"python": platform.python_version()}
    for package in ("ebm-agent", "torch", "numpy", "gymnasium", "stable-baselines3", "mujoco"):
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            versions[package] = "not installed"
    return versions


Runner = Callable[[Job], JobResult]
"""What an executor calls on each job (``eval.run.run_job``, or a stand-in in tests)."""


__all__ = [
    "DATASETS",
    "EVAL_SEED_OFFSET",
    "GRAPH_TRANSITIONS",
    "MODES",
    "RESUME_FOLDER",
    "RUN_OUTPUTS",
    "STATE_FILE",
    "Job",
    "JobResult",
    "Runner",
    "env_short_name",
    "library_versions",
    "to_plain",
]
