"""The paper's experiments by name, each split into parts that run, resume and merge on their own.

    ebm-eval --experiment list                                  # experiments, parts and their estimated cost
    ebm-eval --experiment table1 -f runs/results                # Table 1, every part
    ebm-eval --experiment all --part 'table2/*' -f runs/results # only Table 2's parts
    ebm-eval --experiment all -f runs/results                   # everything, then docs/results.md

An :class:`Experiment` builds its :class:`Part` s for a :class:`Scale` (``paper``: the paper's budgets;
``smoke``: tiny ones for tests), as ``paper.yaml`` lists them. A part is either a list of :class:`Cell` s (one
number of a table each: the runs of one configuration over seeds, with the paper's number beside it) or one figure
of ``eval.paper.figures``. Every run
folder is named by its configuration (``<out>/<variant>/<env>/<agent>/seed_<k>``), so experiments that need the
same runs share them (Table 2's online fixed-goal runs are also the ground-truth row of the inverse-dynamics
ablation and the runs the fixed-goal-on-variable-goals evaluation reads).

Budgets (paper Sec. 4.1 and Table 2's caption): 50,000 transitions online, datasets of 100,000 transitions for
pretraining, 3 seeds, 10 deterministic evaluation episodes, the paper's evaluation configuration of each env
(``envs.PAPER_EVAL_KWARGS``). Agent settings per env come from the env's online preset
(``eval/presets/<env>_online.yaml``, key ``hyperparams``), so that ``--config particle_online`` and
``--experiment table1`` train the same agents.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Sequence
from fnmatch import fnmatchcase
from pathlib import Path
from typing import Any

from eval.jobs import RESUME_FOLDER, STATE_FILE, Job
from eval.paper.data import paper_data
from eval.paper.estimates import estimate_jobs_seconds, estimate_part_seconds, format_duration, measured_part_cost
from eval.paper.parts import SCALES, Cell, Context, Experiment, Part, figure_part, make_cell, table_part
from eval.pretraining import collection_checkpoint_dir
from eval.provenance import read_json_dict

CELL_FIELDS = frozenset(inspect.signature(make_cell).parameters) - {"context", "part"}
"""The fields a cell of ``paper.yaml`` may have (``eval.paper.parts.make_cell``'s arguments)."""


def _cell(context: Context, part: str, fields: dict[str, Any]) -> Cell:
    unknown = sorted(set(fields) - CELL_FIELDS)
    if unknown:
        raise ValueError(f"paper.yaml: a cell of {part} has unknown fields {unknown}; known: {sorted(CELL_FIELDS)}")
    return make_cell(context, **fields, part=part)


def _builder(parts: list[dict[str, Any]], experiment: str) -> Callable[[Context], list[Part]]:
    """``build(context) -> parts`` of one experiment's ``paper.yaml`` entry."""

    def build(context: Context) -> list[Part]:
        built = []
        for part in parts:
            if "figure" in part:
                built.append(figure_part(context, experiment, part["name"], part["figure"], part.get("paper")))
            else:
                cells = [_cell(context, part["name"], cell) for cell in part["cells"]]
                built.append(table_part(context, experiment, part["name"], cells))
        return built

    return build


EXPERIMENTS: dict[str, Experiment] = {
    entry["name"]: Experiment(
        entry["name"], entry["title"], entry["source"], entry["description"], _builder(entry["parts"], entry["name"])
    )
    for entry in paper_data()["experiments"]
}
"""Every experiment by name, in the order of the paper (``paper.yaml``, ``experiments``)."""


def build_parts(names: Sequence[str], context: Context) -> list[Part]:
    """The parts of the named experiments (``"all"`` for every one).

    :param names: experiment names.
    :param context: scale, folder, seeds, device.
    :return: the parts, experiment by experiment.
    :raises ValueError: for an unknown name.
    """
    selected = list(EXPERIMENTS) if "all" in names else list(dict.fromkeys(names))
    unknown = [name for name in selected if name not in EXPERIMENTS]
    if unknown:
        raise ValueError(f"unknown experiment(s) {unknown}; choose from: {', '.join(EXPERIMENTS)}, all (or list)")
    return [part for name in selected for part in EXPERIMENTS[name].build(context)]


def select_parts(parts: Sequence[Part], patterns: Sequence[str] | None) -> list[Part]:
    """The parts whose name matches any of the globs (all parts when there is none).

    :param parts: candidate parts.
    :param patterns: shell-style globs, e.g. ``table1/particle/*`` or ``*/sawyer*``.
    :return: the matching parts, in order.
    :raises ValueError: when a glob matches no part.
    """
    if not patterns:
        return list(parts)
    for pattern in patterns:
        if not any(fnmatchcase(part.name, pattern) for part in parts):
            names = ", ".join(part.name for part in parts)
            raise ValueError(f"--part {pattern!r} matches no part; the parts are: {names}")
    return [part for part in parts if any(fnmatchcase(part.name, pattern) for pattern in patterns)]


def make_context(scale: str, out_dir: str, seeds: Sequence[int] | None = None, device: str = "auto") -> Context:
    """A context for a scale by name.

    :param scale: ``paper`` or ``smoke``.
    :param out_dir: the results folder.
    :param seeds: training seeds (None: the scale's).
    :param device: torch device.
    :return: the context.
    :raises ValueError: for an unknown scale.
    """
    if scale not in SCALES:
        raise ValueError(f"unknown scale {scale!r}; choose one of: {', '.join(SCALES)}")
    return Context(SCALES[scale], str(out_dir), None if seeds is None else tuple(seeds), device)


def describe_experiments(context: Context, measured_from: Sequence[str | Path] = ()) -> str:
    """The text of ``ebm-eval --experiment list``: experiments, their parts, runs, estimated and measured cost.

    :param context: scale, folder, seeds.
    :param measured_from: results or records folders whose finished runs and figures give measured times.
    :return: the text.
    """
    lines = [
        f"Experiments at scale {context.scale.name!r} (CPU time of one process: a rough estimate, and the measured "
        "wall time of the finished runs, where there are any; --jobs N divides the wall time of runs):",
        "",
    ]
    unique_jobs: dict[Path, Job] = {}
    figures = 0.0
    for experiment in EXPERIMENTS.values():
        parts = experiment.build(context)
        runs = {job.run_dir: job for part in parts for job in part.jobs}
        cost = estimate_jobs_seconds(runs.values()) + sum(estimate_part_seconds(p) for p in parts if p.figure)
        for part in parts:
            unique_jobs.update((job.run_dir, job) for job in part.jobs)
            figures += estimate_part_seconds(part) if part.figure else 0.0
        lines.append(f"{experiment.name:<20} {experiment.title} ({experiment.source}) ~{format_duration(cost)}")
        for part in parts:
            what = f"figure {part.figure}" if part.figure else f"{len(part.jobs)} runs"
            seeds = " ".join(map(str, part.seeds))
            line = f"  {part.name:<46} {what:<32} seeds {seeds:<10} ~{format_duration(estimate_part_seconds(part)):<7}"
            measured = measured_part_cost(part, measured_from) if measured_from else None
            line = f"{line} {measured.describe()}" if measured else line.rstrip()
            lines.append(line + _in_progress(part))
    total = figures + estimate_jobs_seconds(unique_jobs.values())
    lines += [
        "",
        f"all: {len(unique_jobs)} runs and {sum(1 for _ in EXPERIMENTS)} experiments, ~{format_duration(total)} "
        "of CPU time (runs and directed collections shared by parts counted once)",
    ]
    return "\n".join(lines)


def _in_progress(part: Part) -> str:
    """``; resumes <run> at t/T, ...`` for the part's unfinished runs that kept a checkpoint (``eval.resume``) and
    the unfinished directed collections its pretrained runs wait for (``eval.pretraining``)."""

    found: list[str] = []
    collections: dict[Path, str] = {}  # the EBM and Action FF runs of a seed share one collection
    for job in part.jobs:
        state = read_json_dict(job.run_dir / RESUME_FOLDER / STATE_FILE)
        if state is not None and not (job.run_dir / "metrics.json").exists():
            found.append(f"{job.agent} seed {job.seed} at {state.get('num_timesteps')}/{job.timesteps}")
        if job.mode == "pretrained" and job.dataset != "random":
            folder = collection_checkpoint_dir(job)
            state = read_json_dict(folder / STATE_FILE)
            if state is not None:
                collections[folder] = (
                    f"the directed dataset of seed {job.seed} at {state.get('num_timesteps')}/{job.timesteps}"
                )
    found += collections.values()
    return f"; resumes {', '.join(found)}" if found else ""


__all__ = [
    "CELL_FIELDS",
    "EXPERIMENTS",
    "build_parts",
    "describe_experiments",
    "make_context",
    "select_parts",
]
