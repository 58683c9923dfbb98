"""The reproduction's data files: ``paper.yaml`` (scales, experiments, cells, the paper's numbers, claims) and
``notes.md`` (why a cell or a claim's comparison differs from the paper, one section per id).

Everything else in ``eval.paper`` reads the paper through these two functions; they import nothing of the package.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import yaml

PAPER_FILE = Path(__file__).with_name("paper.yaml")
"""Scales, figure budgets, experiments (parts, cells, the paper's numbers) and claims."""

NOTES_FILE = Path(__file__).with_name("notes.md")
"""Why our numbers differ from the paper's: ``## <id>`` sections of one paragraph each."""

NOT_INVESTIGATED = "not investigated yet."
"""The reason shown for a differing cell whose ``why`` names no note."""


@functools.cache
def paper_data() -> dict[str, Any]:
    """``paper.yaml``, read once.

    :return: ``{"scales", "figure_budgets", "experiments", "claims"}``.
    :raises ValueError: when a section is missing.
    """
    data = yaml.safe_load(PAPER_FILE.read_text()) or {}
    missing = [key for key in ("scales", "figure_budgets", "experiments", "claims") if key not in data]
    if missing:
        raise ValueError(f"{PAPER_FILE} lacks the section(s) {missing}")
    return data


@functools.cache
def notes() -> dict[str, str]:
    """``notes.md`` as ``{id: paragraph}`` (a section's lines joined by spaces).

    :return: the notes by id.
    :raises ValueError: for a section id given twice.
    """
    found: dict[str, list[str]] = {}
    current: list[str] | None = None
    for line in NOTES_FILE.read_text().splitlines():
        if line.startswith("## "):
            key = line[3:].strip()
            if key in found:
                raise ValueError(f"{NOTES_FILE}: the note {key!r} is given twice")
            current = found[key] = []
        elif current is not None and line.strip():
            current.append(line.strip())
    return {key: " ".join(lines) for key, lines in found.items()}


def figure_entry(figure: str) -> tuple[str, dict[str, Any]]:
    """The experiment and the ``paper.yaml`` part of a figure.

    :param figure: a figure function's name (``obstacle_generalisation``).
    :return: (the experiment's name, the part: ``name``, ``figure``, ``agents``, ``env``, ``paper``).
    :raises KeyError: for a figure no part names.
    """
    for experiment in paper_data()["experiments"]:
        for part in experiment["parts"]:
            if part.get("figure") == figure:
                return experiment["name"], part
    raise KeyError(f"no part of {PAPER_FILE.name} makes the figure {figure!r}")


def note(key: str | None) -> str:
    """The note of an id.

    :param key: a section id of ``notes.md``, or None.
    :return: its paragraph, or ``NOT_INVESTIGATED`` for None.
    :raises KeyError: for an id ``notes.md`` does not have (a typo in ``paper.yaml``).
    """
    if key is None:
        return NOT_INVESTIGATED
    try:
        return notes()[key]
    except KeyError:
        raise KeyError(f"paper.yaml names the note {key!r}, which {NOTES_FILE.name} does not have") from None


__all__ = ["NOTES_FILE", "NOT_INVESTIGATED", "PAPER_FILE", "figure_entry", "note", "notes", "paper_data"]
