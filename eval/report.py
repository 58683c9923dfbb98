"""The summary of a sweep: ``results.csv`` (one row per env, agent and seed) and ``results.md`` (per env x agent).

Aggregation per env x agent (see eval/stats.py for the conventions):

- score over seeds: mean +- population std of the per-seed mean scores;
- score over episodes: mean +- population std of every evaluation episode of every seed, pooled;
- IQM [95% CI]: interquartile mean of the per-seed scores with a stratified bootstrap interval, from 3 seeds on;
- success: mean of the per-seed success rates; steps: the transitions the runs really consumed / the budget.
"""

from __future__ import annotations

import csv
import shlex
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ebm_agent.checkpoint_files import atomic_path
from eval import stats
from eval.anchors import EnvAnchors
from eval.jobs import JobResult

CSV_COLUMNS = (
    "env",
    "agent",
    "seed",
    "timesteps",
    "budget",
    "score_mean",
    "score_std",
    "success_rate",
    "eval_episodes",
    "wall_time_s",
    "status",
    "error",
)
"""Columns of ``results.csv``, in order."""


@dataclass(frozen=True)
class AgentSummary:
    """One env x agent cell of the table.

    :param env: env short name.
    :param agent: agent name.
    :param seeds: seeds that finished.
    :param failed: seeds that failed.
    :param stopped: seeds that a signal stopped before they finished (``eval.stop``; their checkpoint resumes them).
    :param seed_mean: mean over seeds of the per-seed mean scores.
    :param seed_std: population std over seeds of the per-seed mean scores.
    :param episode_mean: mean over all evaluation episodes of all seeds.
    :param episode_std: population std over all those episodes.
    :param iqm: IQM of the per-seed scores (None below 3 seeds).
    :param iqm_ci: its 95% stratified bootstrap interval (None below 3 seeds).
    :param success_rate: mean of the per-seed success rates (None if the env reports none).
    :param steps_used: (min, max) transitions really consumed over seeds.
    :param budget: the budget each run had.
    """

    env: str
    agent: str
    seeds: tuple[int, ...]
    failed: tuple[int, ...]
    stopped: tuple[int, ...]
    seed_mean: float | None
    seed_std: float | None
    episode_mean: float | None
    episode_std: float | None
    iqm: float | None
    iqm_ci: tuple[float, float] | None
    success_rate: float | None
    steps_used: tuple[int, int] | None
    budget: int


def summarize(results: Sequence[JobResult], bootstrap_reps: int = 2000, seed: int = 0) -> list[AgentSummary]:
    """Aggregate results per env x agent, in the order they first appear.

    :param results: results of a sweep (failed ones are counted, not averaged).
    :param bootstrap_reps: resamples of the IQM interval.
    :param seed: seed of the bootstrap.
    :return: one summary per env x agent.
    """
    groups: dict[tuple[str, str], list[JobResult]] = {}
    for result in results:
        groups.setdefault((result.job.env_short, result.job.agent), []).append(result)
    summaries = []
    for (env, agent), group in groups.items():
        finished = [r for r in group if r.ok]
        per_seed = np.array([r.score_mean for r in finished])  # [seeds]
        episodes = np.array([score for r in finished for score in r.episode_scores], dtype=np.float64)  # [seeds x episodes]
        successes = [r.success_rate for r in finished if r.success_rate is not None]
        enough = len(finished) >= stats.MIN_SEEDS_FOR_CI
        summaries.append(
            AgentSummary(
                env=env,
                agent=agent,
                seeds=tuple(r.job.seed for r in finished),
                failed=tuple(r.job.seed for r in group if r.status not in ("ok", "stopped")),
                stopped=tuple(r.job.seed for r in group if r.status == "stopped"),
                seed_mean=stats.mean(per_seed) if finished else None,
                seed_std=stats.std(per_seed) if finished else None,
                episode_mean=stats.mean(episodes) if len(episodes) else None,
                episode_std=stats.std(episodes) if len(episodes) else None,
                iqm=stats.iqm(per_seed) if enough else None,
                iqm_ci=stats.bootstrap_ci(per_seed, stats.iqm, reps=bootstrap_reps, seed=seed) if enough else None,
                success_rate=float(np.mean(successes)) if successes else None,
                steps_used=(min(r.timesteps for r in finished), max(r.timesteps for r in finished)) if finished else None,
                budget=group[0].job.timesteps,
            )
        )
    return summaries


def write_csv(results: Sequence[JobResult], path: Path) -> Path:
    """Write one row per env, agent and seed.

    :param results: the sweep's results.
    :param path: the CSV file.
    :return: ``path``.
    """
    with open(path, "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=CSV_COLUMNS)
        writer.writeheader()
        for result in results:
            ok = result.ok
            writer.writerow(
                {
                    "env": result.job.env_short,
                    "agent": result.job.agent,
                    "seed": result.job.seed,
                    "timesteps": result.timesteps if ok else "",
                    "budget": result.job.timesteps,
                    "score_mean": f"{result.score_mean:.6g}" if ok else "",
                    "score_std": f"{result.score_std:.6g}" if ok else "",
                    "success_rate": "" if result.success_rate is None else f"{result.success_rate:.6g}",
                    "eval_episodes": len(result.episode_scores) if ok else result.job.eval_episodes,
                    "wall_time_s": f"{result.wall_time_s:.3f}",
                    "status": result.status,
                    "error": _last_line(result.error),
                }
            )
    return path


def _last_line(error: str | None) -> str:
    """The exception line of a traceback: the CSV keeps one line, error.txt keeps it all."""
    if not error:
        return ""
    lines = [line for line in error.strip().splitlines() if line.strip()]
    return lines[-1] if lines else ""


def _pm(mean: float | None, spread: float | None) -> str:
    return "-" if mean is None else f"{mean:.2f} ± {spread or 0.0:.2f}"


def _optional(value: float | None, fmt: str = ".2f") -> str:
    return "-" if value is None else format(value, fmt)


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[Any]], missing: str = "-") -> str:
    """A markdown table: the one writer of the harness's and the paper's tables.

    :param header: column titles.
    :param rows: the cells; a float gets 2 decimals, None becomes ``missing``, anything else its ``str``.
    :param missing: what stands for None.
    :return: the table, without a final newline.
    """

    def cell(value: Any) -> str:
        if value is None:
            return missing
        return f"{value:.2f}" if isinstance(value, float) else str(value)

    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(cell(value) for value in row) + " |" for row in rows]
    return "\n".join(lines)


def results_table(summaries: Sequence[AgentSummary]) -> str:
    """The comparison table in markdown.

    :param summaries: from ``summarize``.
    :return: a markdown table, one row per env x agent.
    """
    header = ["env", "agent", "seeds", "score (over seeds)", "score (over episodes)", "IQM [95% CI]", "success"]
    rows = []
    for s in summaries:
        unfinished = [f"{len(s.failed)} failed"] * bool(s.failed) + [f"{len(s.stopped)} stopped"] * bool(s.stopped)
        seeds = str(len(s.seeds)) + (f" ({', '.join(unfinished)})" if unfinished else "")
        iqm = "-" if s.iqm is None or s.iqm_ci is None else f"{s.iqm:.2f} [{s.iqm_ci[0]:.2f}, {s.iqm_ci[1]:.2f}]"
        if s.steps_used is None:
            steps = f"- / {s.budget}"
        elif s.steps_used[0] == s.steps_used[1]:
            steps = f"{s.steps_used[0]} / {s.budget}"
        else:
            steps = f"{s.steps_used[0]}-{s.steps_used[1]} / {s.budget}"
        seed_score, episode_score = _pm(s.seed_mean, s.seed_std), _pm(s.episode_mean, s.episode_std)
        rows.append([s.env, s.agent, seeds, seed_score, episode_score, iqm, _optional(s.success_rate), steps])
    return markdown_table([*header, "steps used / budget"], rows)


def anchors_table(anchors: dict[str, EnvAnchors | None], first: str = "env") -> str:
    """The sanity anchors in markdown.

    :param anchors: env label -> anchors (None where they could not be computed).
    :param first: the first column's title.
    :return: a markdown table, one row per env.
    """
    rows: list[list[Any]] = []
    for env, anchor in anchors.items():
        if anchor is None:
            rows.append([env, None, None, None])
            continue
        optimum = None if anchor.optimum is None else f"{anchor.optimum:.2f} ({anchor.optimum_source})"
        random = f"{anchor.random_mean:.2f} ± {anchor.random_std:.2f} ({anchor.random_episodes} episodes)"
        rows.append([env, optimum, random, f"{anchor.still_score:.2f}"])
    return markdown_table([first, "optimum", "random policy", "standing still"], rows)


def render_markdown(
    results: Sequence[JobResult],
    anchors: dict[str, EnvAnchors | None] | None = None,
    command: Sequence[str] | None = None,
    bootstrap_reps: int = 2000,
) -> str:
    """The whole ``results.md``: comparison table, anchors, failures, and the command that made it.

    :param results: the sweep's results.
    :param anchors: env short name -> anchors.
    :param command: the command line (argv, program name first).
    :param bootstrap_reps: resamples of the IQM interval.
    :return: markdown text.
    """
    parts = [
        "# ebm-eval results",
        "",
        "Score: undiscounted sum of per-step rewards of one deterministic evaluation episode (the paper's metric). "
        "± is the population std (ddof=0); IQM [95% CI] (stratified bootstrap over seeds) needs at least "
        f"{stats.MIN_SEEDS_FOR_CI} seeds.",
        "",
        results_table(summarize(results, bootstrap_reps=bootstrap_reps)),
    ]
    if anchors:
        parts += ["", "## Sanity anchors", "", anchors_table(anchors)]
    failed = [r for r in results if not r.ok]
    if failed:
        parts += ["", "## Unfinished runs (failed, or stopped by a signal: run the command again)", ""]
        parts += [
            f"- {r.job.env_short} / {r.job.agent} / seed {r.job.seed}: {'stopped: ' * (r.status == 'stopped')}"
            f"{_last_line(r.error)}"
            for r in failed
        ]
    if command:
        parts += ["", "## Command", "", "```", shlex.join(command), "```"]
    return "\n".join(parts) + "\n"


def write_markdown(
    results: Sequence[JobResult],
    path: Path,
    anchors: dict[str, EnvAnchors | None] | None = None,
    command: Sequence[str] | None = None,
) -> str:
    """Write ``results.md``.

    :param results: the sweep's results.
    :param path: the markdown file.
    :param anchors: env short name -> anchors.
    :param command: the command line.
    :return: the markdown text (to print).
    """
    text = render_markdown(results, anchors, command)
    with atomic_path(path) as temporary:  # a reader never sees half a table
        temporary.write_text(text)
    return text


__all__ = [
    "CSV_COLUMNS",
    "AgentSummary",
    "anchors_table",
    "markdown_table",
    "render_markdown",
    "results_table",
    "summarize",
    "write_csv",
    "write_markdown",
]
