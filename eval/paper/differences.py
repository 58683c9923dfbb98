"""Where our numbers differ from the paper's, and why: the "differences" section of ``docs/results.md``.

Which cells differ is computed, never written down: a cell with at least 3 finished seeds differs from the paper
when the paper's number lies outside the 95% stratified-bootstrap interval of our mean (``eval.stats``). Why it
differs is written down: ``notes.md`` holds what we know, in words and without numbers (the numbers come from the
table beside it, so a note cannot go stale with a rerun), under the id the cell's ``why`` names in ``paper.yaml``.
A differing cell without one says "not investigated yet".
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from eval import stats
from eval.paper.data import note
from eval.paper.parts import Cell


@dataclass(frozen=True)
class Difference:
    """One cell whose numbers differ from the paper's.

    :param part: the cell's part.
    :param cell: the cell.
    :param mean: our mean over seeds.
    :param low: the lower end of its 95% interval.
    :param high: the upper end.
    :param seeds: how many seeds.
    :param explanation: why, or "not investigated yet".
    """

    part: str
    cell: Cell
    mean: float
    low: float
    high: float
    seeds: int
    explanation: str

    @property
    def direction(self) -> str:
        """``"better"`` or ``"worse"`` than the paper (scores are sums of rewards: higher is better)."""
        assert self.cell.paper is not None
        return "better" if self.mean > self.cell.paper else "worse"


def find_differences(cells: Sequence[tuple[str, Cell, np.ndarray]]) -> list[Difference]:
    """The cells whose 95% interval excludes the paper's number.

    :param cells: (part name, cell, per-seed scores [seeds]) of every cell.
    :return: the differing cells, in the order given; cells without a paper number or with fewer than 3 seeds are
        not judged.
    """
    found = []
    for part, cell, scores in cells:
        if cell.paper is None or len(scores) < stats.MIN_SEEDS_FOR_CI:
            continue
        low, high = stats.bootstrap_ci(np.asarray(scores, dtype=np.float64), stats.mean)
        if low <= cell.paper <= high:
            continue
        mean = float(stats.mean(np.asarray(scores, dtype=np.float64)))
        reason = note(cell.why)
        found.append(Difference(part, cell, mean, float(low), float(high), len(scores), reason))
    return found


def render_differences(differences: Sequence[Difference]) -> list[str]:
    """The markdown section: the differing cells grouped by their explanation, each reason written once.

    Cells that share a reason (the maze's four cells, say) are listed together, in the order given, with the reason
    once below them; a cell with a reason of its own is one line.

    :param differences: from :func:`find_differences`.
    :return: markdown lines.
    """
    lines = [
        "## Where we differ from the paper, and why",
        "",
        f"A cell differs when it has at least {stats.MIN_SEEDS_FOR_CI} seeds and the paper's number lies outside the 95% "
        "interval of our mean (computed); the reasons are written in `eval/paper/notes.md`.",
        "",
    ]
    if not differences:
        return [*lines, "No finished cell differs from the paper so far.", ""]
    groups: dict[str, list[Difference]] = {}
    for difference in differences:
        groups.setdefault(difference.explanation, []).append(difference)
    for explanation, members in groups.items():
        if len(members) == 1:
            lines.append(f"- {_describe(members[0])}. Why: {explanation}")
            continue
        lines.append(f"- {len(members)} cells with one reason:")
        lines.extend(f"  - {_describe(member)}" for member in members)
        lines.extend(["", f"  Why: {explanation}", ""])
    return [*lines, ""]


def _describe(difference: Difference) -> str:
    """One differing cell: its part, agent and setting, our mean and interval, and the paper's number."""
    cell = difference.cell
    return (
        f"**{difference.part}, {cell.label}** ({cell.setting}): ours {difference.mean:.2f} "
        f"[95% CI {difference.low:.2f}, {difference.high:.2f}] ({difference.seeds} seeds), {difference.direction} "
        f"than the paper's {cell.paper:g}"
    )


__all__ = ["Difference", "find_differences", "render_differences"]
