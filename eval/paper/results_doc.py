"""``docs/results.md`` from a results folder: every experiment's numbers beside the paper's, or "not run yet".

    python -m eval.paper.results_doc -f runs/results              # docs/results.md
    ebm-eval --report-only -f runs/results                  # the same

The document is built from the registry (``eval.paper.experiments``) and the run folders only: a cell's number is
read from the ``metrics.json`` of runs whose fingerprint matches the cell's configuration (seeds found on disk
beyond the default ones are included), a figure from its ``figure.json``. A part without runs says "not run
yet" with the command that runs it; nothing is ever filled in. Per table: mean ± std over seeds of the per-seed
mean scores (10 deterministic episodes each at the paper's scale), the IQM with its 95% stratified-bootstrap
interval from 3 seeds on (``eval.stats``), the paper's number, the anchors of the evaluation env
(``eval.anchors``), and per part the command that produced it, the machine, the date and the wall time. Claims
are judged from the numbers (``eval.paper.claims``), and the cells whose interval excludes the paper's number are listed with
the reason we know (``eval.paper.differences``). Figures are copied to ``<docs>/figures/`` and linked.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import shlex
import shutil
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ebm_agent.checkpoint_files import atomic_path
from eval import stats
from eval.anchors import EnvAnchors, compute_anchors
from eval.jobs import Job, to_plain
from eval.locks import file_lock
from eval.paper.claims import evaluate_claims, render_claims
from eval.paper.differences import find_differences, render_differences
from eval.paper.estimates import format_duration
from eval.paper.experiments import EXPERIMENTS, make_context
from eval.paper.figures.common import figure_complete, figure_seeds_kept, figure_state
from eval.paper.parts import SCALES, Cell, Part
from eval.paper.records import default_docs, default_records, restore_records
from eval.plots import load_curve, plot_curves
from eval.provenance import (
    describe_machine,
    is_current_run,
    job_fingerprint,
    read_metrics,
    read_provenance,
    read_sessions,
)
from eval.report import anchors_table, markdown_table
from eval.run import evaluation_env_kwargs


@dataclass
class CellResult:
    """The finished runs of one cell.

    :param cell: the cell.
    :param runs: (job, metrics) of each finished run, by seed.
    """

    cell: Cell
    runs: list[tuple[Job, dict[str, Any]]] = field(default_factory=list)
    retired: int = 0
    """Seeds with a finished run of the same configuration made with other library defaults (to be run again)."""

    @property
    def scores(self) -> np.ndarray:
        """[seeds] the per-seed mean score of the cell's evaluation."""
        return np.array([score_of(metrics, self.cell.evaluation) for _, metrics in self.runs], dtype=np.float64)

    @property
    def missing_seeds(self) -> list[int]:
        """The cell's seeds without a finished run."""
        done = {job.seed for job, _ in self.runs}
        return [job.seed for job in self.cell.jobs if job.seed not in done]


def score_of(metrics: dict[str, Any], evaluation: str | None) -> float:
    """A run's mean score: its final evaluation's, or an extra evaluation's.

    :param metrics: the run's ``metrics.json``.
    :param evaluation: the extra evaluation's name, or None.
    :return: the mean over episodes.
    """
    if evaluation is None:
        return float(metrics["score_mean"])
    return float(metrics["extra_evaluations"][evaluation]["score_mean"])


def collect_cell(cell: Cell) -> CellResult:
    """Read a cell's finished runs: its seeds, and any other seed found in its folder with the same configuration.

    :param cell: the cell.
    :return: its finished runs, by seed.
    """
    jobs = {job.seed: job for job in cell.jobs}
    template = cell.jobs[0]
    folder = template.run_dir.parent
    if folder.is_dir():
        for seed_dir in folder.glob("seed_*"):
            suffix = seed_dir.name.removeprefix("seed_")
            if suffix.isdigit() and int(suffix) not in jobs:
                jobs[int(suffix)] = replace(template, seed=int(suffix))
    result = CellResult(cell)
    for seed in sorted(jobs):
        job = jobs[seed]
        metrics = read_metrics(job.run_dir)
        if metrics is None or not is_current_run(job, metrics):
            if metrics is not None and metrics.get("fingerprint") == job_fingerprint(job):
                result.retired += 1  # the same job under earlier defaults
            continue
        if not (job.run_dir / "evaluations.npz").exists():
            continue
        if cell.evaluation is not None and cell.evaluation not in (metrics.get("extra_evaluations") or {}):
            continue
        result.runs.append((job, metrics))
    return result


QUALITY_COLUMNS = {
    "feasibility_auroc": "wall AUROC near the visited states",
    "feasibility_auroc_uniform": "wall AUROC, uniform states",
    "next_state_rank": "next-state top-1 of 65",
    "next_state_mean_rank": "next-state mean rank (0 best, 0.5 chance)",
}
"""The model-quality keys a finished EBM run records (``eval.run.model_quality_of``), and their column titles."""


def quality_table(results: Sequence[CellResult]) -> str | None:
    """The model-quality probe of the cells whose runs recorded it: mean ± std over seeds of each measure.

    :param results: the cells' results.
    :return: the markdown table, or None when no run recorded the probe.
    """
    rows = []
    for result in results:
        if result.cell.evaluation is not None:
            continue  # an extra evaluation of another cell's runs: their probe is that cell's row
        records = [m["model_quality"] for _, m in result.runs if m.get("model_quality")]
        if records:
            cells = []
            for key in QUALITY_COLUMNS:
                values = np.array([r[key] for r in records if r.get(key) is not None], dtype=np.float64)
                cells.append(f"{stats.mean(values):.3f} ± {stats.std(values):.3f}" if len(values) else "-")
            rows.append([result.cell.setting, result.cell.env, result.cell.label, str(len(records)), *cells])
    header = ["setting", "env", "agent", "seeds", *QUALITY_COLUMNS.values()]
    return markdown_table(header, rows) if rows else None


def _pm(values: np.ndarray) -> str:
    return f"{stats.mean(values):.2f} ± {stats.std(values):.2f}"


def _iqm(values: np.ndarray) -> str:
    if len(values) < stats.MIN_SEEDS_FOR_CI:
        return "-"
    low, high = stats.bootstrap_ci(values, stats.iqm)
    return f"{stats.iqm(values):.2f} [{low:.2f}, {high:.2f}]"


def _paper(cell: Cell) -> str:
    text = "-" if cell.paper is None else f"{cell.paper:g}"
    return f"{text} ({cell.paper_note})" if cell.paper_note else text


def cells_table(results: Sequence[CellResult]) -> str:
    """The markdown table of a part's (or an experiment's) cells.

    :param results: the cells' results.
    :return: one row per cell: ours, seeds, IQM [95% CI], success, paper.
    """
    rows = []
    for result in results:
        cell, scores = result.cell, result.scores
        ours = _pm(scores) if len(scores) else "not run yet"
        if not len(scores) and result.retired:
            ours = f"rerun pending ({result.retired} run(s) made with earlier library defaults)"
        seeds = f"{len(scores)}/{len(cell.jobs)}" if len(scores) < len(cell.jobs) else str(len(scores))
        # The success of the evaluation that stands for the cell: the run's own, or an extra evaluation's.
        evaluations = [
            m if cell.evaluation is None else (m.get("extra_evaluations") or {}).get(cell.evaluation) or {}
            for _, m in result.runs
        ]
        successes = [float(e["success_rate"]) for e in evaluations if e.get("success_rate") is not None]
        success = f"{np.mean(successes):.2f}" if successes else "-"
        rows.append([cell.setting, cell.env, cell.label, ours, seeds, _iqm(scores), success, _paper(cell)])
    header = ["setting", "env", "agent", "ours: mean ± std over seeds", "seeds", "IQM [95% CI]", "success", "paper"]
    return markdown_table(header, rows)


@dataclass
class PartStatus:
    """How far a part got, and where its numbers came from.

    :param done: finished runs (or 1 for a finished figure).
    :param total: runs it needs (or 1 for a figure).
    :param commands: the commands that produced its runs.
    :param machines: the machines they ran on.
    :param finished: dates its runs finished.
    :param wall_time_s: summed wall time of its runs (or the figure's, with its seeds from earlier processes).
    :param untimed_seeds: a figure's seeds finished by earlier processes that recorded no time (not in the sum).
    """

    done: int = 0
    total: int = 0
    commands: list[str] = field(default_factory=list)
    machines: list[str] = field(default_factory=list)
    finished: list[str] = field(default_factory=list)
    wall_time_s: float = 0.0
    untimed_seeds: int = 0


def part_status(part: Part, results: Sequence[CellResult]) -> PartStatus:
    """The status of a table part from its cells' runs, or of a figure part from its folder.

    :param part: the part.
    :param results: its cells' results (ignored for a figure part).
    :return: the status.
    """
    status = PartStatus()
    if part.figure is not None:
        record = read_provenance(part.figure_dir) or {}
        status.total, status.done = 1, int(figure_complete(part))
        if status.done:
            status.commands = [str(record.get("command", "unknown"))]
            status.machines = [describe_machine(record.get("machine"))]
            status.finished = [str(record.get("date", ""))]
            status.wall_time_s = float(record.get("wall_time_s", 0.0))
            status.untimed_seeds = int(record.get("earlier_seeds_untimed", 0))
        return status
    runs: dict[Path, tuple[Job, dict[str, Any]]] = {}
    for result in results:
        runs.update((job.run_dir, (job, metrics)) for job, metrics in result.runs)
    status.total, status.done = len(part.jobs), sum(1 for job in part.jobs if job.run_dir in runs)
    for job, metrics in runs.values():
        record = read_provenance(job.run_dir) or {}
        status.commands.append(str(record.get("command", "unknown")))
        status.machines.append(describe_machine(metrics.get("machine")))
        status.finished.append(str(metrics.get("finished_at", "")))
        status.wall_time_s += float(metrics.get("wall_time_s", 0.0))
    return status


def parts_table(parts: Sequence[Part], statuses: Sequence[PartStatus]) -> str:
    """Per part: status, command(s), machine(s), finish dates, wall time.

    :param parts: the parts.
    :param statuses: their statuses.
    :return: a markdown table.
    """
    rows: list[list[str]] = []
    for part, status in zip(parts, statuses):
        if status.done == 0:
            rows.append([part.name, "not run yet", f"`{part.command()}`", "", "", ""])
            continue
        state = "complete" if status.done == status.total else f"partial ({status.done}/{status.total}); to finish:"
        commands = sorted(set(status.commands)) if status.done == status.total else [part.command()]
        dates = sorted(d[:10] for d in status.finished if d)
        when = (dates[0] if dates[0] == dates[-1] else f"{dates[0]} to {dates[-1]}") if dates else "-"
        untimed = f" + {status.untimed_seeds} earlier seed(s), time not recorded" if status.untimed_seeds else ""
        machines = "<br>".join(sorted(set(status.machines)))
        wall = f"{format_duration(status.wall_time_s)}{untimed}"
        rows.append([part.name, state, "<br>".join(f"`{c}`" for c in commands), machines, when, wall])
    header = ["part", "status", "command", "machine", "finished", "wall time (sum of its runs)"]
    return markdown_table(header, rows)


def _anchor_key(job: Job, evaluation: dict[str, Any]) -> str:
    return json.dumps(to_plain({"env_id": job.env_id, "kwargs": evaluation}), sort_keys=True)


def anchors_rows(results: Sequence[CellResult], out_dir: Path) -> list[tuple[str, EnvAnchors | None]]:
    """Anchors of the evaluation envs of cells that have runs (cached in ``<out>/anchors_cache.json``).

    :param results: cells.
    :param out_dir: the results folder.
    :return: (label, anchors or None when they could not be computed), one per evaluation configuration.
    """
    cache_path = out_dir / "anchors_cache.json"
    try:
        cache = json.loads(cache_path.read_text())
    except (OSError, ValueError):
        cache = {}
    rows, seen = [], set()
    for result in results:
        if not result.runs:
            continue
        job = result.cell.jobs[0]
        kwargs = evaluation_env_kwargs(job)
        if result.cell.evaluation is not None:
            kwargs = {**kwargs, **job.extra_evaluations.get(result.cell.evaluation, {})}
        key = _anchor_key(job, kwargs)
        if key in seen:
            continue
        seen.add(key)
        if key not in cache:
            try:
                cache[key] = asdict(compute_anchors(job.env_id, kwargs))
            except Exception as error:  # context only: a failure must not cost the document
                print(f"results_doc: no anchors for {job.env_id} {kwargs}: {error}", file=sys.stderr)
                cache[key] = None
        shown = {k: v for k, v in kwargs.items() if k != "max_episode_steps"}
        label = result.cell.env + (f" ({', '.join(f'{k}={v}' for k, v in shown.items())})" if shown else "")
        rows.append((label, None if cache[key] is None else EnvAnchors(**cache[key])))
    with atomic_path(cache_path) as temporary:
        temporary.write_text(json.dumps(cache, indent=2))
    return rows


def _anchors_md(rows: Sequence[tuple[str, EnvAnchors | None]]) -> str:
    return anchors_table(dict(rows), first="evaluation env")


def learning_curves(part: Part, results: Sequence[CellResult], figures_dir: Path) -> Path | None:
    """Learning curves of a part's online cells (mean over seeds, min-max band) as a PNG, if any has two points.

    :param part: the part.
    :param results: its cells' results.
    :param figures_dir: where the PNG goes.
    :return: the PNG, or None.
    """

    curves: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    for result in results:
        if result.cell.evaluation is not None:
            continue
        for job, _ in result.runs:
            if job.mode != "online":
                continue
            curve = load_curve(job.run_dir / "evaluations.npz")
            if len(curve[0]) >= 2:
                curves.setdefault(f"{result.cell.label} ({result.cell.setting})", []).append(curve)
    if not curves:
        return None
    figures_dir.mkdir(parents=True, exist_ok=True)
    path = figures_dir / f"{_safe(part.name)}_learning_curves.png"
    return plot_curves(curves, path, f"{part.name}: score vs transitions")


def _safe(name: str) -> str:
    return name.replace("/", "_").replace("+", "_")


def figure_section(part: Part, figures_dir: Path, docs_dir: Path) -> list[str]:
    """A figure part's numbers and images (PNGs copied into ``figures_dir``), or "not run yet".

    :param part: a figure part.
    :param figures_dir: where PNGs are copied.
    :param docs_dir: the document's folder (links are relative to it).
    :return: markdown lines.
    """

    lines = []
    if part.paper:
        lines += ["Paper: " + ", ".join(f"{label} {value:g}" for label, value in part.paper.items()) + ".", ""]
    state = figure_state(part)
    kept = figure_seeds_kept(part) if state != "complete" else []
    progress = (
        f" Seeds already made under today's defaults and kept for it: {', '.join(map(str, kept))} "
        f"(of {', '.join(map(str, part.seeds))})."
        if kept
        else ""
    )
    if state == "retired":
        return [*lines, f"Rerun pending (the figure was made with earlier library defaults): `{part.command()}`.{progress}"]
    if state != "complete":
        return [*lines, f"Not run yet: `{part.command()}`.{progress}"]
    figure = json.loads((part.figure_dir / "figure.json").read_text())
    if figure.get("table_md"):
        lines += [str(figure["table_md"]).strip(), ""]
    else:
        lines += [f"- {key}: {_short(value)}" for key, value in (figure.get("metrics") or {}).items()] + [""]
    for png in figure.get("pngs") or []:
        source = _resolve_png(Path(png), part.figure_dir)
        if source is None:
            lines.append(f"(missing image {png})")
            continue
        figures_dir.mkdir(parents=True, exist_ok=True)
        target = figures_dir / f"{_safe(part.name)}_{source.name}"
        shutil.copyfile(source, target)
        lines.append(f"![{part.figure}: {source.stem}]({target.relative_to(docs_dir).as_posix()})")
    return lines


def _resolve_png(path: Path, folder: Path) -> Path | None:
    for candidate in (path, folder / path, folder / path.name):
        if candidate.is_file():
            return candidate
    return None


def _short(value: Any) -> str:
    array = np.asarray(value, dtype=object)
    if array.ndim == 0:
        return f"{value:.4g}" if isinstance(value, float) else str(value)
    try:
        numbers = np.asarray(value, dtype=np.float64)
        return f"mean {numbers.mean():.4g} over {numbers.size} values"
    except (TypeError, ValueError):
        return json.dumps(to_plain(value))[:200]


def render_results(
    out_dir: Path,
    docs_path: Path,
    scale: str = "paper",
    seeds: Sequence[int] | None = None,
    records: str | None = None,
) -> str:
    """The whole results document.

    :param out_dir: the results folder.
    :param docs_path: the document's path (figures go to ``<its folder>/figures/``).
    :param scale: the scale whose runs are reported.
    :param seeds: the default seeds expected per cell (None: the scale's); other finished seeds are included too.
    :param records: the records folder the results folder was restored from (named in the header), or None.
    :return: markdown.
    """
    context = make_context(scale, str(out_dir), seeds)
    docs_dir = docs_path.parent
    figures_dir = docs_dir / "figures"
    regenerate = ["ebm-eval", "--report-only", "-f", str(out_dir)]
    regenerate += ["--scale", scale] if scale != "paper" else []
    regenerate += ["--seeds", *map(str, seeds)] if seeds else []
    kept = (
        f" The small files of every finished run and figure are kept in `{records}/` (committed) and restored from "
        "there before each run or report, so numbers from earlier machines are reported with their own provenance."
        if records
        else ""
    )
    sections, by_key, figure_metrics, judged = [], {}, {}, []
    retired_by_key: dict[tuple[str, str, str], int] = {}
    for experiment in EXPERIMENTS.values():
        parts = experiment.build(context)
        section = [f"## {experiment.title}", "", f"{experiment.description} ({experiment.source}.)", ""]
        all_results, statuses, per_part = [], [], []
        for part in parts:
            results = [collect_cell(cell) for cell in part.cells]
            for result in results:
                by_key[(part.name, result.cell.agent, result.cell.setting)] = result.scores
                retired_by_key[(part.name, result.cell.agent, result.cell.setting)] = result.retired
                judged.append((part.name, result.cell, result.scores))
            all_results += results
            per_part.append(results)
            statuses.append(part_status(part, results))
            if part.figure is not None:
                section += [f"### {part.name}", "", *figure_section(part, figures_dir, docs_dir), ""]
                if statuses[-1].done:
                    figure_metrics[part.name] = json.loads((part.figure_dir / "figure.json").read_text()).get("metrics")
        if all_results:
            section += [cells_table(all_results), ""]
            quality = quality_table(all_results)
            if quality is not None:
                section += [
                    "The learned energy, probed at the end of each run (`ebm_agent.probe.model_quality`):",
                    "",
                    quality,
                    "",
                ]
            anchors = anchors_rows(all_results, out_dir)
            if anchors:
                section += ["Anchors of the evaluation envs:", "", _anchors_md(anchors), ""]
            for part, results in zip(parts, per_part):
                curve = learning_curves(part, results, figures_dir)
                if curve is not None:
                    section += [f"![{part.name} learning curves]({curve.relative_to(docs_dir).as_posix()})", ""]
        section += ["Parts:", "", parts_table(parts, statuses), ""]
        sections += section
    claims = evaluate_claims(lambda key: list(by_key.get(key, [])), figure_metrics.get, lambda key: retired_by_key.get(key, 0))
    header = [
        "# Reproduction results",
        "",
        f"Generated by `{shlex.join(regenerate)}` on {time.strftime('%Y-%m-%d %H:%M %Z')} from the run folders under "
        f"`{out_dir}/` (scale `{scale}`). Every number is read from a finished run of the configuration its row "
        "names; a part that has not run says so, with the command that runs it. `make results` runs everything "
        f"(`ebm-eval --experiment all -f runs/results`) and regenerates this file.{kept}",
        "",
        "Score: the undiscounted sum of the env's per-step rewards over one deterministic evaluation episode (the "
        f"paper's metric), {SCALES[scale].eval_episodes} evaluation episode(s) per run; ± is the population std over "
        "seeds of the per-seed mean scores; IQM [95% CI] (stratified bootstrap over seeds) from "
        f"{stats.MIN_SEEDS_FOR_CI} seeds on. "
        "The paper reports single numbers without seeds or spread.",
        "",
        "## Claims (judged from the numbers below)",
        "",
        render_claims(claims),
        "",
        *render_differences(find_differences(judged)),
    ]
    return "\n".join(header + sections + _sessions_md(out_dir)).rstrip() + "\n"


def _sessions_md(out_dir: Path) -> list[str]:
    sessions = read_sessions(out_dir)
    if not sessions:
        return []
    lines = [
        "## Sessions",
        "",
        "| started | command | machine | wall time | ran | skipped | failed | stopped |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for record in sessions:
        counts = " | ".join(str(len(record.get(key, []))) for key in ("ran", "skipped", "failed", "stopped"))
        lines.append(
            f"| {str(record.get('started', ''))[:16]} | `{record.get('command', '')}` | "
            f"{describe_machine(record.get('machine'))} | {format_duration(float(record.get('wall_time_s', 0.0)))} | "
            f"{counts} |"
        )
    return [*lines, ""]


def write_results(
    out_dir: Path,
    docs_path: Path,
    scale: str = "paper",
    seeds: Sequence[int] | None = None,
    records: str | None = None,
) -> Path:
    """Write the results document.

    :param out_dir: the results folder.
    :param docs_path: the document (its folder gets ``figures/``).
    :param scale: the scale whose runs are reported.
    :param seeds: the default seeds of each cell.
    :param records: the records folder the results folder was restored from, or None.
    :return: ``docs_path``.
    """
    docs_path = Path(docs_path)
    docs_path.parent.mkdir(parents=True, exist_ok=True)
    text = render_results(Path(out_dir), docs_path, scale, seeds, records)
    with atomic_path(docs_path) as temporary:  # a reader never sees half a document
        temporary.write_text(text)
    return docs_path


def report_lock(docs_path: Path) -> contextlib.AbstractContextManager[None]:
    """The lock that the processes writing one results document take in turn (``.<name>.lock`` beside it).

    Held while a writer gathers every finished run (its own and those that other processes recorded) and writes the
    document, so that two ``ebm-eval`` processes ending at once write, one after the other, a complete document.

    :param docs_path: the document.
    :return: a context manager holding the lock.
    """
    docs_path = Path(docs_path)
    return file_lock(docs_path.with_name(f".{docs_path.name}.lock"))


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m eval.paper.results_doc``: regenerate the results document.

    :param argv: the arguments.
    :return: 0.
    """
    parser = argparse.ArgumentParser(
        prog="python -m eval.paper.results_doc",
        description="Regenerate the results document (docs/results.md) from a results folder; nothing is trained.",
    )
    parser.add_argument("-f", "--out", default="runs/results", help="the results folder (default: runs/results)")
    parser.add_argument("--scale", default="paper", choices=list(SCALES), help="the scale reported (default: paper)")
    parser.add_argument("--seeds", nargs="+", type=int, help="default seeds of each cell (default: the scale's)")
    parser.add_argument(
        "--docs", help="the document (default: docs/results.md at the paper's scale from runs/results, else <out>/results.md)"
    )
    parser.add_argument(
        "--records",
        help="restore finished runs from this records folder first (default: docs/records for docs/results.md made "
        "from runs/results; 'none': off)",
    )
    args = parser.parse_args(argv)
    docs = default_docs(args.docs, args.scale, args.out)
    records = default_records(args.records, docs, args.out)
    with report_lock(Path(docs)):
        if records:
            print(restore_records(Path(records), Path(args.out)).describe("restored", Path(records), Path(args.out)))
        path = write_results(Path(args.out), Path(docs), args.scale, args.seeds, records)
    print(f"Results document: {path}")
    return 0


__all__ = [
    "CellResult",
    "PartStatus",
    "cells_table",
    "collect_cell",
    "figure_section",
    "learning_curves",
    "main",
    "part_status",
    "parts_table",
    "render_results",
    "report_lock",
    "score_of",
    "write_results",
]


if __name__ == "__main__":
    sys.exit(main())
