"""What the paper's experiments cost: rough CPU-time estimates before they run, measured wall times after.

``ebm-eval --experiment list`` prints both; the estimates only order and size the work, the measured times (from
the runs' ``metrics.json`` and the figures' ``provenance.json``, in the results folder or the records) are what a
plan should trust.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym

from eval.jobs import Job
from eval.paper.figures.common import figure_digest, recorded_figure_digests
from eval.paper.parts import Part
from eval.pretraining import dataset_path
from eval.provenance import is_current_run, job_fingerprint

SECONDS_PER_STEP = {"particle": 0.02, "maze": 0.02, "reacher": 0.037, "sawyer": 0.053}
"""Rough CPU seconds per env step of a planning agent (EBM, Action FF), learning or acting, in one of two processes
on 2 cores (``--jobs 2``): the Table 1 online runs in docs/records took 0.015-0.027 s per transition on the particle,
0.013-0.030 on the maze, about 0.037 on Reacher (2026-11-22 and 2026-12-01). The Sawyer's is from its online
fixed-goal EBM (seed 0, 2026-12-02, two or three processes on 2 cores): 3,778 s for 50,000 learning steps and 60,000
evaluation steps, i.e. 50,000 p + 60,000 p / ``ACTING_SHARE``; it was 0.135 before the Sawyer's inverse dynamics got
its rescue ceiling (docs/mujoco_envs.md). ``ebm-eval --experiment list`` prints measured times beside the
estimates once runs exist."""

ACTING_SHARE = 3.0
"""A planning agent's evaluation step costs about a third of a learning step (no energy training, warm-started
plans): the maze online runs, whose 60,000 evaluation steps would otherwise double their estimate, took 11-25 min."""

STEP_SECONDS_BY_AGENT: dict[tuple[str, str], tuple[float, float]] = {("sawyer", "action-ff"): (0.008, 0.014)}
"""(learning, acting) CPU seconds per step where an agent's cost differs from the env's planning cost. The Action FF
plans torques and needs no inverse dynamics, which is most of the EBM's Sawyer step: its pretrained evaluations took
135-142 s per 10,000 steps (0.014 a step) and its online fixed-goal run (seed 0, 2026-12-02, two processes on 2
cores) 18.4 min to its last curve evaluation, of which about 700 s were the 50,000 evaluation steps."""

COLLECT_SHARE = 2.0
"""A directed collection's step costs about this many learning steps of the env (``SECONDS_PER_STEP``): the Sawyer's
100,000 directed transitions of seed 0 took 10,715 s of one core (0.107 s a step, 2026-12-03, AMD host, beside other
processes, resumed three times), twice the online run's 0.053. The collecting EBM's replay grows to 100,000
transitions, twice the online run's, and it never pauses for the cheaper evaluation steps."""

PPO_SECONDS_PER_STEP = 0.001
"""Rough CPU seconds per PPO transition (docs/benchmarks.md: about 2,000 transitions/s on the particle)."""

SECONDS_PER_OFFLINE_UPDATE = {"ebm": 0.02, "action-ff": 0.003}
"""Rough CPU seconds per ``learn_offline`` minibatch of 256."""

FIGURE_SECONDS_PER_SEED = {
    "obstacle_generalisation": 5400.0,
    "plan_diversity": 400.0,
    "reacher_directions": 600.0,
    "maze_exploration": 950.0,
    "sawyer_exploration": 4700.0,
    "energy_maps": 1000.0,
}
"""Rough CPU seconds of a figure per seed at the paper's scale (the figure trains its own agents). plan_diversity,
reacher_directions, maze_exploration and energy_maps from their recorded wall times (2026-12-01 and 2026-12-02; the
energy maps: 48 min for 3 seeds, each an online EBM on the particle and a goal-free one on the maze);
sawyer_exploration from its seed 0 (2026-12-03: 4,668 s with one torch thread beside another process; the earlier
guess from ``SECONDS_PER_STEP`` was 3,000 s); obstacle_generalisation, an EBM and an Action FF online for 50,000
particle transitions each with evaluations in and out of the box, from its seeds 0 and 2 under today's defaults
(2026-12-04: 89.6 and 91 min, one torch thread beside another process on the Intel host; the guesses before them,
900 s and then 2,700 s from the Table 1 particle runs, were 6x and 2x low)."""


def _episode_length(job: Job) -> int:

    steps = job.env_kwargs.get("max_episode_steps")
    if steps is None:
        spec = gym.spec(job.env_id)
        steps = spec.max_episode_steps if spec is not None else 1000
    return int(steps or 1000)


def estimate_job_seconds(job: Job) -> float:
    """A rough CPU-seconds estimate of one job's own work: learning and evaluations.

    A directed dataset that the job learns from is not included: the EBM and Action FF of a seed, and the directed
    and directed + sequential parts, share one collection per seed (``estimate_collection_seconds``), which
    ``estimate_jobs_seconds`` counts once.

    :param job: the job.
    :return: seconds.
    """
    per_step = PPO_SECONDS_PER_STEP if job.agent == "ppo" else SECONDS_PER_STEP.get(job.env_short, 0.01)
    act = 0.0001 if job.agent == "ppo" else per_step / ACTING_SHARE
    per_step, act = STEP_SECONDS_BY_AGENT.get((job.env_short, job.agent), (per_step, act))
    episode = _episode_length(job)
    extra = 1 + len(job.extra_evaluations)
    if job.mode == "untrained":  # an untrained planner's plans rarely hold: it plans about every step, as in learning
        return extra * job.eval_episodes * episode * per_step
    if job.mode == "online":
        evaluations = max(job.timesteps // max(job.eval_freq, 1), 1)
        return job.timesteps * per_step + (evaluations + extra - 1) * job.eval_episodes * episode * act
    sequential = job.dataset == "directed+sequential"
    epochs = job.offline_kwargs.get("epochs", 1 if sequential else 10)
    repeat = job.offline_kwargs.get("repeat", 100) if sequential else 1
    batch = job.offline_kwargs.get("batch_size", 256)
    updates = epochs * math.ceil(job.timesteps * repeat / batch)
    return updates * SECONDS_PER_OFFLINE_UPDATE.get(job.agent, 0.01) + extra * job.eval_episodes * episode * act


def estimate_collection_seconds(job: Job) -> float:
    """A rough CPU-seconds estimate of the directed collection that a pretrained job learns from (0 for none).

    :param job: the job.
    :return: seconds of the whole collection (``job.timesteps`` directed steps, ``COLLECT_SHARE``).
    """
    if job.mode != "pretrained" or job.dataset == "random":
        return 0.0
    return job.timesteps * SECONDS_PER_STEP.get(job.env_short, 0.01) * COLLECT_SHARE


def estimate_jobs_seconds(jobs: Iterable[Job]) -> float:
    """A rough CPU-seconds estimate of several jobs, with each directed collection they share counted once.

    :param jobs: the jobs (a run listed twice is counted twice: deduplicate by ``run_dir`` first).
    :return: seconds.
    """

    total = 0.0
    collections: dict[Path, float] = {}  # one per env, size, seed and collector: its cache file
    for job in jobs:
        total += estimate_job_seconds(job)
        collect = estimate_collection_seconds(job)
        if collect:
            collections[dataset_path(job)] = collect
    return total + sum(collections.values())


def estimate_part_seconds(part: Part) -> float:
    """A rough CPU-seconds estimate of a part (one process; ``--jobs N`` divides the wall time).

    A part is charged every directed collection it needs, though another part may already have made it (the
    directed and directed + sequential parts of Table 2 share theirs); ``estimate_jobs_seconds`` counts them once
    over several parts.

    :param part: the part.
    :return: seconds.
    """
    if part.figure is not None:
        factor = 1.0 if part.scale == "paper" else 0.01
        return FIGURE_SECONDS_PER_SEED.get(part.figure, 600.0) * len(part.seeds) * factor
    return estimate_jobs_seconds(part.jobs)


def format_duration(seconds: float) -> str:
    """``45 s``, ``12 min``, ``3.4 h``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


@dataclass(frozen=True)
class MeasuredCost:
    """The wall time that a part's finished runs (or its figure) took, summed over runs.

    :param seconds: summed wall time of the finished runs (for a figure: of the command that made it).
    :param finished: runs (or figures) found finished.
    :param total: runs (or figures) of the part.
    :param unit: what was counted, ``runs`` or ``figure``.
    :param retired: of the finished ones, those made under earlier library defaults (``eval.provenance.is_current_run``,
        ``eval.paper.runner.figure_state``): their time is measured, but ``ebm-eval --experiment`` makes them
        again.
    """

    seconds: float
    finished: int
    total: int
    unit: str = "runs"
    retired: int = 0

    def describe(self) -> str:
        """``measured 1.3 h (6/6 runs)``, ``measured 1.6 h (2/6 runs, 1 under earlier defaults: to rerun)``; the
        time of one process, so ``--jobs 2`` halves the wall time of runs."""
        text = f"measured {format_duration(self.seconds)} ({self.finished}/{self.total} {self.unit}"
        if self.retired:
            text += f", {self.retired} under earlier defaults: to rerun"
        return text + ")"


def measured_part_cost(part: Part, folders: Sequence[Path | str]) -> MeasuredCost | None:
    """The measured cost of a part, read from the first of ``folders`` that holds each finished run or figure.

    Each folder mirrors the layout of ``part.out_dir`` (a results folder, or records saved from one).

    :param part: the part.
    :param folders: results or records folders, searched in order.
    :return: the measured cost, or None when nothing of the part has finished.
    """

    out_dir = Path(part.out_dir)
    if part.figure is not None:
        relative = part.figure_dir.relative_to(out_dir)
        found = _first_number((Path(folder) / relative / "provenance.json" for folder in folders), "wall_time_s")
        if found is None:
            return None
        seconds, record, path = found
        current = figure_digest(str(part.figure))
        old = current is not None and any(d != current for d in recorded_figure_digests(path.parent, record))
        return MeasuredCost(seconds, 1, 1, "figure", int(old))
    jobs = part.jobs
    total, finished, retired = 0.0, 0, 0
    for job in jobs:
        relative = job.run_dir.relative_to(out_dir)
        found = _first_number((Path(folder) / relative / "metrics.json" for folder in folders), "wall_time_s")
        if found is not None:
            seconds, metrics, _path = found
            total += seconds
            finished += 1
            # the same job (fingerprint) made under other defaults, as eval.paper.results_doc counts a rerun pending
            retired += int(metrics.get("fingerprint") == job_fingerprint(job) and not is_current_run(job, metrics))
    return MeasuredCost(total, finished, len(jobs), retired=retired) if finished else None


def _first_number(paths: Iterable[Path], key: str) -> tuple[float, dict[str, Any], Path] | None:
    """The first file of ``paths`` that holds a finite number under ``key``: (the number, the file's JSON, its path)."""
    for path in paths:
        try:
            record = json.loads(path.read_text())
            value = record.get(key)
        except (OSError, ValueError, AttributeError):
            continue
        if isinstance(value, int | float) and math.isfinite(value):
            return float(value), record, path
    return None


__all__ = [
    "ACTING_SHARE",
    "COLLECT_SHARE",
    "FIGURE_SECONDS_PER_SEED",
    "PPO_SECONDS_PER_STEP",
    "SECONDS_PER_OFFLINE_UPDATE",
    "SECONDS_PER_STEP",
    "MeasuredCost",
    "estimate_collection_seconds",
    "estimate_job_seconds",
    "estimate_jobs_seconds",
    "estimate_part_seconds",
    "format_duration",
    "measured_part_cost",
]
