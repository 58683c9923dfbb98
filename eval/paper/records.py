"""Records: the small files of finished runs and figures, kept in the repository so that results outlive a machine.

A results folder (``runs/results``) holds models, TensorBoard logs and datasets, and is not committed; its numbers
would be lost with the machine. ``save_records`` copies what the results document is built from into a records
folder (``docs/records`` for the published document) with the same layout:

- per finished run (``metrics.json`` and ``evaluations.npz`` present): ``metrics.json``, ``evaluations.npz``,
  ``provenance.json`` and ``config.yaml``;
- per finished figure (``figure.json`` present): its JSON, CSV, markdown and PNG files of at most 2 MB;
- per unfinished figure (``figure_started.json`` but no ``figure.json``): the seeds it finished (``seeds/*.json`` and
  the drawings kept with them, ``seeds/*.png``, at most 2 MB each), so that a figure longer than a session resumes on
  another machine;
- ``sessions.jsonl`` and ``anchors_cache.json``, merged with what the records already hold.

``restore_records`` copies them back into a results folder wherever it has no finished run or figure of its own,
so that ``ebm-eval --experiment`` skips what has been run before (the fingerprint in ``metrics.json`` decides, as
for any run) and the document reports every recorded number. Runs moved aside (``*.replaced-*``) and unfinished
runs are never recorded. Every file is written atomically.

    python -m eval.paper.records save -f runs/results             # after a run: into docs/records
    python -m eval.paper.records restore -f runs/results          # on a new machine: before a run or a report
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ebm_agent.checkpoint_files import atomic_path
from eval.provenance import SESSIONS_FILE, read_metrics
from eval.run import run_in_progress

FIGURE_STARTED = "figure_started.json"
"""Written into a figure's folder when it starts (``eval.paper.runner``): its part, scale and seeds."""

SEED_FOLDER = "seeds"
"""Sub-folder of a figure's folder holding its finished seeds (``eval.paper.figures.common.seed_result``)."""

RECORDS_DIR = "docs/records"
"""The records of the published document (``docs/results.md``)."""

PUBLISHED = ("docs/results.md", "runs/results")
"""The published document and the results folder it is made from: the pair that uses ``RECORDS_DIR`` by default."""

RUN_FILES = ("metrics.json", "evaluations.npz", "provenance.json", "config.yaml")
"""The files of a finished run that are recorded (no model, no TensorBoard log)."""

FIGURE_SUFFIXES = (".json", ".csv", ".md", ".png")
"""The files of a finished figure that are recorded."""

MAX_FIGURE_FILE_BYTES = 2 * 1024 * 1024
"""Larger figure files (raw arrays) are not recorded."""

ANCHORS_CACHE = "anchors_cache.json"
SKIPPED_DIRS = ("datasets", "tensorboard", "checkpoints")


@dataclass
class RecordsSummary:
    """What one ``save_records`` or ``restore_records`` copied.

    :param runs: run folders copied (relative to the results folder).
    :param figures: figure folders copied.
    :param kept: folders left alone because the destination holds a finished one of its own, or a run in progress
        (restore only).
    :param seeds: finished seeds of unfinished figures copied (``<figure folder>/seeds/<file>``).
    """

    runs: list[str] = field(default_factory=list)
    figures: list[str] = field(default_factory=list)
    kept: list[str] = field(default_factory=list)
    seeds: list[str] = field(default_factory=list)

    def describe(self, verb: str, source: Path, target: Path) -> str:
        """One line for the log.

        :param verb: "recorded" or "restored".
        :param source: where the files came from.
        :param target: where they went.
        :return: the line.
        """
        line = f"{verb} {len(self.runs)} run(s) and {len(self.figures)} figure(s) from {source}/ into {target}/"
        line += f", and {len(self.seeds)} finished seed(s) of unfinished figures" if self.seeds else ""
        return line + (f"; {len(self.kept)} kept as they were" if self.kept else "")


def _visible(relative: Path) -> bool:
    return not any(".replaced-" in part or part.startswith(".") or part in SKIPPED_DIRS for part in relative.parts)


def _is_finished(run_dir: Path) -> bool:
    return (run_dir / "evaluations.npz").exists() and read_metrics(run_dir) is not None


def finished_runs(folder: Path) -> Iterator[Path]:
    """The finished run folders under a results or records folder.

    :param folder: the folder.
    :return: each run folder, relative to ``folder``, in sorted order.
    """
    for metrics in sorted(Path(folder).rglob("metrics.json")):
        run_dir = metrics.parent
        relative = run_dir.relative_to(folder)
        if _visible(relative) and _is_finished(run_dir):
            yield relative


def finished_figures(folder: Path) -> Iterator[Path]:
    """The figure folders (with a ``figure.json``) under a results or records folder.

    :param folder: the folder.
    :return: each figure folder, relative to ``folder``, in sorted order.
    """
    for record in sorted(Path(folder).rglob("figure.json")):
        relative = record.parent.relative_to(folder)
        if _visible(relative):
            yield relative


def unfinished_figures(folder: Path) -> Iterator[Path]:
    """The figure folders that were started (``figure_started.json``) and not finished (no ``figure.json``).

    :param folder: a results or records folder.
    :return: each figure folder, relative to ``folder``, in sorted order.
    """
    for record in sorted(Path(folder).rglob(FIGURE_STARTED)):
        relative = record.parent.relative_to(folder)
        if _visible(relative) and not (record.parent / "figure.json").exists():
            yield relative


def _copy_partial_figure(source: Path, target: Path, overwrite: bool) -> list[str]:
    """Copy an unfinished figure's start record and finished seeds; with ``overwrite=False`` only missing seeds."""
    started = target / FIGURE_STARTED
    if started.exists() and started.read_text() != (source / FIGURE_STARTED).read_text():
        return []  # the destination started another figure (other seeds or scale) in that folder: leave it
    copied = []
    for path in sorted(p for p in (source / SEED_FOLDER).glob("*") if p.suffix in (".json", ".png")):
        destination = target / SEED_FOLDER / path.name
        if path.stat().st_size <= MAX_FIGURE_FILE_BYTES and (overwrite or not destination.exists()):
            _copy_atomic(path, destination)
            copied.append(f"{SEED_FOLDER}/{path.name}")
    if copied:  # a figure with no finished seed has nothing to resume
        _copy_atomic(source / FIGURE_STARTED, started)
    return copied


def _copy_atomic(source: Path, target: Path) -> None:
    with atomic_path(target) as temporary:
        shutil.copyfile(source, temporary)


def _write_atomic(target: Path, text: str) -> None:
    with atomic_path(target) as temporary:
        temporary.write_text(text)


def _figure_files(folder: Path) -> list[Path]:
    return sorted(
        path
        for path in folder.rglob("*")
        if path.is_file()
        and path.suffix in FIGURE_SUFFIXES
        and _visible(path.relative_to(folder))
        and path.stat().st_size <= MAX_FIGURE_FILE_BYTES
    )


def _copy_run(source: Path, target: Path) -> None:
    for name in RUN_FILES:
        if (source / name).exists():
            _copy_atomic(source / name, target / name)


def _copy_figure(source: Path, target: Path) -> None:
    for path in _figure_files(source):
        _copy_atomic(path, target / path.relative_to(source))


def _merge_sessions(source: Path, target: Path) -> None:
    """Append to ``target/sessions.jsonl`` the lines of ``source``'s that it lacks, in order of start."""
    texts = [(folder / SESSIONS_FILE).read_text() for folder in (target, source) if (folder / SESSIONS_FILE).exists()]
    lines = dict.fromkeys(line for text in texts for line in text.splitlines() if line.strip())  # ordered, unique
    if not lines:
        return

    def started(line: str) -> str:
        try:
            return str(json.loads(line).get("started", ""))
        except (ValueError, AttributeError):
            return ""

    _write_atomic(target / SESSIONS_FILE, "".join(line + "\n" for line in sorted(lines, key=started)))


def _merge_anchors(source: Path, target: Path) -> None:
    """Add to ``target``'s anchors cache the entries of ``source``'s that it lacks."""
    merged: dict[str, object] = {}
    for folder in (source, target):  # the target's entries win
        try:
            merged.update(json.loads((folder / ANCHORS_CACHE).read_text()))
        except (OSError, ValueError, TypeError):
            continue
    if merged:
        _write_atomic(target / ANCHORS_CACHE, json.dumps(merged, indent=2))


def default_docs(flag: str | None, scale: str, out: str | Path) -> str:
    """The results document a command writes: the flag's; else the published ``docs/results.md`` for the paper's
    scale reported from ``runs/results``; else ``<out>/results.md``, so that a scratch folder never overwrites the
    published document.

    :param flag: ``--docs`` as given, or None.
    :param scale: the scale reported.
    :param out: the results folder.
    :return: the document's path.
    """
    if flag:
        return flag
    if scale == "paper" and Path(out) == Path(PUBLISHED[1]):
        return PUBLISHED[0]
    return str(Path(out) / "results.md")


def default_records(flag: str | None, docs: str | Path | None, out: str | Path) -> str | None:
    """The records folder a command uses: the flag's (``"none"``: none); else ``RECORDS_DIR`` when it writes the
    published document from ``runs/results``; else none, so that a scratch folder's runs never enter the records.

    :param flag: ``--records`` as given, or None.
    :param docs: the document the command writes, or None.
    :param out: its results folder.
    :return: the records folder, or None.
    """
    if flag is not None:
        return None if flag.lower() == "none" else flag
    published = docs is not None and Path(docs) == Path(PUBLISHED[0]) and Path(out) == Path(PUBLISHED[1])
    return RECORDS_DIR if published else None


def save_records(out_dir: Path, records_dir: Path = Path(RECORDS_DIR)) -> RecordsSummary:
    """Copy the finished runs and figures of a results folder into the records (replacing older records of them).

    :param out_dir: the results folder.
    :param records_dir: the records folder.
    :return: what was copied.
    """
    out_dir, records_dir = Path(out_dir), Path(records_dir)
    summary = RecordsSummary()
    if not out_dir.is_dir():
        return summary
    for relative in finished_runs(out_dir):
        _copy_run(out_dir / relative, records_dir / relative)
        summary.runs.append(relative.as_posix())
    for relative in finished_figures(out_dir):
        _copy_figure(out_dir / relative, records_dir / relative)
        summary.figures.append(relative.as_posix())
    for relative in unfinished_figures(out_dir):
        if (records_dir / relative / "figure.json").exists():
            continue  # the records hold the finished figure already
        copied = _copy_partial_figure(out_dir / relative, records_dir / relative, overwrite=True)
        summary.seeds.extend(f"{relative.as_posix()}/{name}" for name in copied)
    _merge_sessions(out_dir, records_dir)
    _merge_anchors(out_dir, records_dir)
    return summary


def restore_records(records_dir: Path, out_dir: Path) -> RecordsSummary:
    """Copy recorded runs and figures into a results folder wherever it has no finished one of its own.

    :param records_dir: the records folder.
    :param out_dir: the results folder (created when missing).
    :return: what was copied, and what was kept.
    """
    records_dir, out_dir = Path(records_dir), Path(out_dir)
    summary = RecordsSummary()
    if not records_dir.is_dir():
        return summary

    for relative in finished_runs(records_dir):
        target = out_dir / relative
        # A folder another process trains in (it may be replacing a retired record) is left to that process.
        if _is_finished(target) or run_in_progress(target):
            summary.kept.append(relative.as_posix())
            continue
        for name in ("model.zip", "error.txt"):  # leftovers of an unfinished run would contradict the record
            (target / name).unlink(missing_ok=True)
        _copy_run(records_dir / relative, target)
        summary.runs.append(relative.as_posix())
    for relative in finished_figures(records_dir):
        target = out_dir / relative
        if (target / "figure.json").exists():
            summary.kept.append(relative.as_posix())
            continue
        _copy_figure(records_dir / relative, target)
        summary.figures.append(relative.as_posix())
    for relative in unfinished_figures(records_dir):
        if (out_dir / relative / "figure.json").exists():
            continue
        copied = _copy_partial_figure(records_dir / relative, out_dir / relative, overwrite=False)
        summary.seeds.extend(f"{relative.as_posix()}/{name}" for name in copied)
    _merge_sessions(records_dir, out_dir)
    _merge_anchors(records_dir, out_dir)
    return summary


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m eval.paper.records save|restore``.

    :param argv: the arguments.
    :return: 0.
    """
    parser = argparse.ArgumentParser(
        prog="python -m eval.paper.records",
        description="Keep the small files of finished runs and figures in the repository (save), or bring them back "
        "into a results folder (restore).",
    )
    parser.add_argument("action", choices=["save", "restore"])
    parser.add_argument("-f", "--out", default="runs/results", help="the results folder (default: runs/results)")
    parser.add_argument("--records", default=RECORDS_DIR, help=f"the records folder (default: {RECORDS_DIR})")
    args = parser.parse_args(argv)
    out, records = Path(args.out), Path(args.records)
    if args.action == "save":
        print(save_records(out, records).describe("recorded", out, records))
    else:
        print(restore_records(records, out).describe("restored", records, out))
    return 0


__all__ = [
    "FIGURE_STARTED",
    "FIGURE_SUFFIXES",
    "MAX_FIGURE_FILE_BYTES",
    "PUBLISHED",
    "RECORDS_DIR",
    "RUN_FILES",
    "SEED_FOLDER",
    "RecordsSummary",
    "default_docs",
    "default_records",
    "finished_figures",
    "finished_runs",
    "main",
    "restore_records",
    "save_records",
    "unfinished_figures",
]


if __name__ == "__main__":
    sys.exit(main())
