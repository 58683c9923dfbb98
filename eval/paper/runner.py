"""Runs experiment parts into one results folder, resumably, so that parts run separately merge into one report.

- A job whose run folder already holds a finished run of the same configuration (``eval.provenance.
  completed_result``: its ``metrics.json`` carries the job's fingerprint) is skipped and says so; an interrupted
  or failed run is run again; a finished run of *another* configuration is moved aside to
  ``seed_<k>.replaced-<fingerprint>`` (never deleted) before the new one runs.
- Jobs of all selected parts run through one executor (``--jobs N`` processes, or Ray); runs shared by several
  parts (Table 2's online fixed-goal runs) run once.
- Figure parts call their ``eval.paper.figures`` function in this process (with the local executor's ``--threads``); a
  figure folder with a ``figure.json`` made at the same scale and seeds is complete. An unfinished figure of the same
  part, scale and seeds (its ``figure_started.json``) is resumed: the seeds it finished (``<folder>/seeds/``,
  ``eval.paper.figures.common.seed_result``) are kept, so a figure longer than one session finishes over several.
- Every run and figure folder gets a ``provenance.json`` (command, part, date), and ``<out>/sessions.jsonl`` one
  line per invocation (command, machine, start, wall time, what ran, was skipped or failed), which
  ``eval.paper.results_doc`` reports.
"""

from __future__ import annotations

import json
import shutil
import sys
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ebm_agent.checkpoint_files import atomic_path
from eval.code_version import code_version
from eval.executors import Executor
from eval.jobs import Job, JobResult
from eval.paper import figures
from eval.paper.experiments import build_parts, describe_experiments, make_context, select_parts
from eval.paper.figures.common import _current_seed_files, figure_digest, figure_state, recorded_figure_digests
from eval.paper.parts import Part
from eval.paper.records import FIGURE_STARTED, restore_records, save_records
from eval.paper.results_doc import report_lock, write_results
from eval.provenance import (
    append_session,
    completed_result,
    is_current_run,
    job_fingerprint,
    machine_info,
    now,
    read_json_dict,
    read_metrics,
    read_provenance,
    write_provenance,
)
from eval.stop import sweep_stop

Log = Callable[[str], None]


def _stderr(message: str) -> None:
    print(message, file=sys.stderr)


@dataclass
class RunSummary:
    """What one invocation did.

    :param ran: results of the jobs that ran.
    :param skipped: results read back from finished runs.
    :param figures_ran: figure parts that ran.
    :param figures_skipped: figure parts already complete.
    :param figures_failed: figure part -> the error's last line.
    """

    ran: list[JobResult] = field(default_factory=list)
    skipped: list[JobResult] = field(default_factory=list)
    figures_ran: list[str] = field(default_factory=list)
    figures_skipped: list[str] = field(default_factory=list)
    figures_failed: dict[str, str] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """True when nothing failed."""
        return all(result.ok for result in self.ran) and not self.figures_failed


def unique_jobs(parts: Sequence[Part]) -> list[Job]:
    """The jobs of the parts, each run folder once.

    :param parts: the parts.
    :return: the jobs in part order.
    :raises ValueError: when two parts give one run folder two configurations (a registry bug).
    """
    jobs: dict[Path, Job] = {}
    for part in parts:
        for job in part.jobs:
            known = jobs.setdefault(job.run_dir, job)
            if job_fingerprint(known) != job_fingerprint(job):
                raise ValueError(f"{job.run_dir} is given two configurations (part {part.name}); give one a variant")
    return list(jobs.values())


def plan_jobs(jobs: Sequence[Job], log: Log = _stderr) -> tuple[list[Job], list[JobResult]]:
    """Split jobs into those to run and those already finished; move finished runs of other configurations aside.

    :param jobs: the jobs.
    :param log: where the skip messages go.
    :return: (jobs to run, results of finished ones).
    """
    to_run, finished = [], []
    for job in jobs:
        result = completed_result(job)
        if result is not None:
            log(f"skip {job.run_dir}: complete (same configuration, score {result.score_mean:.2f})")
            finished.append(result)
            continue
        metrics = read_metrics(job.run_dir)
        if metrics is not None and not is_current_run(job, metrics):
            moved = _move_aside(job.run_dir, str(metrics.get("fingerprint")))
            log(
                f"moved {job.run_dir} aside to {moved.name}: it holds a finished run of another configuration or of "
                "other library defaults"
            )
        to_run.append(job)
    return to_run, finished


def _move_aside(folder: Path, tag: str) -> Path:
    target = folder.with_name(f"{folder.name}.replaced-{tag}")
    if target.exists():
        target = folder.with_name(f"{target.name}-{time.strftime('%Y%m%d%H%M%S')}")
    shutil.move(str(folder), str(target))
    return target


def run_parts(
    parts: Sequence[Part],
    executor: Executor,
    command: str,
    progress: bool = True,
    log: Log = _stderr,
) -> RunSummary:
    """Run the parts' missing jobs and figures, skipping finished ones, and record where everything came from.

    :param parts: the selected parts.
    :param executor: runs the jobs.
    :param command: the command line, recorded in each new run's ``provenance.json`` and in ``sessions.jsonl``.
    :param progress: show a progress bar over jobs.
    :param log: where progress messages go.
    :return: what ran, was skipped or failed.
    """
    if not parts:
        return RunSummary()
    out_dir = Path(parts[0].out_dir)
    started, start = now(), time.perf_counter()
    jobs = unique_jobs(parts)
    to_run, finished = plan_jobs(jobs, log)
    part_of = _parts_by_run(parts)
    if jobs:
        log(f"ebm-eval: {len(to_run)} run(s) to do, {len(finished)} already complete, in {out_dir}/")
    summary = RunSummary(skipped=finished)
    for job in to_run:
        # Recorded before the run, so that a run finished by an invocation that is later killed still names the
        # command that produced it; rewritten with the run's status below.
        write_provenance(job.run_dir, command, parts=part_of.get(job.run_dir, []), scale=parts[0].scale, status="started")
    with sweep_stop() as stop:  # a stop request during the runs also keeps the figures from starting
        summary.ran = executor.map(to_run, progress=progress) if to_run else []
    for result in summary.ran:
        write_provenance(
            result.run_dir, command, parts=part_of.get(result.run_dir, []), scale=parts[0].scale, status=result.status
        )
        if not result.ok:
            log(f"{result.status} {result.run_dir}: {(result.error or '').strip().splitlines()[-1:]}")
    if stop.requested or any(result.status == "stopped" for result in summary.ran):  # SIGTERM or Ctrl-C (eval.stop)
        log("ebm-eval: stopped by a signal, the figures of this command not started: run it again to resume")
    elif any(part.figure is not None for part in parts):
        # Figures train their agents in this process: with the local executor, at its threads per run (--threads),
        # not at torch's default of every core, which oversubscribes the cores that other processes share.
        limit = getattr(executor, "limit_this_process", None)
        if callable(limit):
            limit()
        for part in parts:
            if part.figure is not None:
                _run_figure(part, command, summary, log)
    append_session(
        out_dir,
        {
            "command": command,
            "started": started,
            "finished": now(),
            "wall_time_s": time.perf_counter() - start,
            "machine": machine_info(),
            "code": code_version(),
            "parts": [part.name for part in parts],
            "ran": [str(r.run_dir) for r in summary.ran if r.ok] + summary.figures_ran,
            "skipped": [str(r.run_dir) for r in summary.skipped] + summary.figures_skipped,
            "failed": [str(r.run_dir) for r in summary.ran if r.status not in ("ok", "stopped")]
            + sorted(summary.figures_failed),
            "stopped": [str(r.run_dir) for r in summary.ran if r.status == "stopped"],
        },
    )
    return summary


def _parts_by_run(parts: Sequence[Part]) -> dict[Path, list[str]]:
    names: dict[Path, list[str]] = {}
    for part in parts:
        for job in part.jobs:
            names.setdefault(job.run_dir, []).append(part.name)
    return names


def _run_figure(part: Part, command: str, summary: RunSummary, log: Log) -> None:

    folder = part.figure_dir
    state = figure_state(part)
    if state == "complete":
        log(f"skip {folder}: complete (figure {part.figure}, same scale and seeds)")
        summary.figures_skipped.append(part.name)
        return
    if state == "retired":
        log(f"figure {part.figure} in {folder}/ was made under earlier library defaults: making it again")
        _pin_recorded_digest(folder, str(part.figure))
    started = {"part": part.name, "scale": part.scale, "seeds": list(part.seeds)}
    earlier = EarlierSeeds()
    if read_json_dict(folder / FIGURE_STARTED) == started:
        kept = _current_seed_files(folder, str(part.figure))
        earlier = EarlierSeeds.of(kept)
        names = ", ".join(path.name for path in kept) or "none"
        log(f"resuming figure {part.figure} in {folder}/: {len(kept)} finished seed(s) kept ({names})")
    else:
        if folder.exists() and any(folder.iterdir()):
            moved = _move_aside(folder, "old")
            log(f"moved {folder} aside to {moved.name}: it holds another figure, or one of other seeds or scale")
        folder.mkdir(parents=True, exist_ok=True)
        with atomic_path(folder / FIGURE_STARTED) as temporary:
            temporary.write_text(json.dumps(started))
        log(f"figure {part.figure} (seeds {list(part.seeds)}, scale {part.scale}) into {folder}/")
    start = time.perf_counter()
    try:
        function = figure_function(str(part.figure))
        result = function(folder, seeds=part.seeds, scale=part.scale)
        if not (folder / "figure.json").exists() and hasattr(result, "save"):
            result.save(folder)
    except Exception:  # a failed figure must not cost the other parts
        error = traceback.format_exc()
        (folder / "error.txt").write_text(error)
        summary.figures_failed[part.name] = error.strip().splitlines()[-1]
        log(f"failed figure {part.figure}: {summary.figures_failed[part.name]}")
        return
    write_provenance(
        folder,
        command,
        part=part.name,
        scale=part.scale,
        seeds=list(part.seeds),
        defaults_digest=figure_digest(str(part.figure)),
        # A resumed figure's time includes the seeds finished by earlier processes, where they recorded theirs.
        wall_time_s=time.perf_counter() - start + earlier.wall_time_s,
        earlier_seeds=earlier.count,
        earlier_seeds_untimed=earlier.untimed,
        machine=machine_info(),
    )
    summary.figures_ran.append(part.name)


def _pin_recorded_digest(folder: Path, figure: str) -> None:
    """Write a retired figure's earlier digest into its ``provenance.json`` (older figures kept it only in their
    seeds): as the rerun replaces the seeds, the old ``figure.json`` must not pass for a current one before the new
    one is written."""

    record = read_provenance(folder) or {}
    if isinstance(record.get("defaults_digest"), str):
        return
    stale = sorted(recorded_figure_digests(folder, record) - {figure_digest(figure)})
    if stale:
        fields_ = {key: value for key, value in record.items() if key != "command"}
        write_provenance(folder, str(record.get("command", "unknown")), **{**fields_, "defaults_digest": stale[0]})


@dataclass
class EarlierSeeds:
    """The seeds of a resumed figure that earlier processes finished, and the time they recorded.

    :param count: how many.
    :param wall_time_s: the sum of their recorded times.
    :param untimed: how many were kept without a time (written before seeds recorded theirs).
    """

    count: int = 0
    wall_time_s: float = 0.0
    untimed: int = 0

    @classmethod
    def of(cls, paths: Sequence[Path]) -> EarlierSeeds:
        """Read the kept seed files.

        :param paths: the ``seeds/*.json`` files.
        :return: their count and time.
        """
        times = [(read_json_dict(path) or {}).get("wall_time_s") for path in paths]
        known = [float(value) for value in times if isinstance(value, int | float)]
        return cls(count=len(paths), wall_time_s=sum(known), untimed=len(times) - len(known))


def figure_function(name: str) -> Callable[..., Any]:
    """The ``eval.paper.figures`` function of a figure part.

    :param name: its name (a key of ``eval.paper.figures.FIGURES``).
    :return: ``function(out_dir, *, seeds, scale) -> FigureResult``.
    :raises ValueError: when the function is missing.
    """
    registry = getattr(figures, "FIGURES", {})
    function = registry.get(name) if isinstance(registry, dict) else None
    function = function or getattr(figures, name, None)
    if not callable(function):
        raise ValueError(f"eval.paper.figures has no figure {name!r}")
    return function  # type: ignore[no-any-return]


def selected_parts(settings: dict[str, Any]) -> list[Part]:
    """The parts ``ebm-eval --experiment`` selects (none for ``list`` and ``--report-only``).

    :param settings: from ``eval.cli.resolve_experiment_settings``.
    :return: the parts.
    :raises ValueError: for a ``--part`` glob that matches no part.
    """

    if settings["experiments"] == ["list"] or settings["report_only"]:
        return []
    context = make_context(settings["scale"], settings["out"], settings["seeds"], settings["device"])
    parts = select_parts(build_parts(settings["experiments"], context), settings["parts"])
    return only_agents(parts, settings.get("agents"))


def only_agents(parts: Sequence[Part], agents: Sequence[str] | None) -> list[Part]:
    """The parts' cells of these agents only (``--agents`` with ``--experiment``); figure parts are left out.

    This splits a part's runs between processes or machines, e.g. the EBM runs of a Table 2 column here and its
    Action FF runs elsewhere; each finished run is recorded and reported as usual.

    :param parts: the selected parts.
    :param agents: agent names, or None for all.
    :return: the parts that still hold a cell, with only those cells.
    :raises ValueError: when no selected part has a run of these agents.
    """
    if not agents:
        return list(parts)
    kept = [
        replace(part, cells=tuple(cell for cell in part.cells if cell.agent in agents))
        for part in parts
        if part.figure is None and any(cell.agent in agents for cell in part.cells)
    ]
    if not kept:
        raise ValueError(f"--agents {' '.join(agents)}: the selected parts have no run of these agents")
    return kept


def run_experiments(
    settings: dict[str, Any], parts: Sequence[Part], executor: Executor, command: str, progress: bool = True
) -> int:
    """``ebm-eval --experiment``: list the experiments, or run the parts, then write the results document.

    With ``settings["records"]`` (``docs/records`` for the published document) the recorded runs are restored into
    the results folder first (so they are skipped and reported) and every finished run is recorded after
    (``eval.paper.records``); the document then reports the protocol's seeds whatever ``--seeds`` ran (``--report-only
    --seeds`` still reports those seeds).

    :param settings: from ``eval.cli.resolve_experiment_settings``.
    :param parts: from ``selected_parts``.
    :param executor: runs the jobs.
    :param command: the command line, recorded with every new run.
    :param progress: show progress bars.
    :return: 0 when nothing failed, else 1.
    """

    if settings["experiments"] == ["list"]:
        context = make_context(settings["scale"], settings["out"], settings["seeds"])
        records = settings.get("records")
        print(describe_experiments(context, [settings["out"], *([records] if records else [])]))
        return 0
    out, records = Path(settings["out"]), settings.get("records")
    if records:
        _stderr(restore_records(Path(records), out).describe("restored", Path(records), out))
    summary = run_parts(parts, executor, command, progress=progress) if parts else RunSummary()
    # The published document (the one kept with records) reports the protocol's seeds: ``--seeds`` on a run only
    # splits the work, and must not turn the figures of other seed sets into "not run yet".
    seeds = None if (records and not settings["report_only"]) else settings["seeds"]
    # One writer at a time: each records its own runs, takes every run the others recorded, then writes the whole
    # document atomically, so that processes ending at once leave a complete one, whichever writes last.
    with report_lock(Path(settings["docs"])):
        if records:
            save_records(out, Path(records))
            restore_records(Path(records), out)
        path = write_results(out, Path(settings["docs"]), settings["scale"], seeds, records=records)
        if records:  # after the document, so that the anchors it computed are kept too
            _stderr(save_records(out, Path(records)).describe("recorded", out, Path(records)))
    print(f"Results document: {path} (from {settings['out']}/)")
    return 0 if summary.ok else 1


__all__ = [
    "RunSummary",
    "figure_function",
    "plan_jobs",
    "run_experiments",
    "run_parts",
    "selected_parts",
    "unique_jobs",
]
