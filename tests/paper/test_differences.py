"""The 'where we differ from the paper' section: computed from the numbers, explained from eval/paper/notes.md."""

from __future__ import annotations

import numpy as np
import pytest

from eval.paper.data import NOT_INVESTIGATED, note, notes, paper_data
from eval.paper.differences import find_differences, render_differences
from eval.paper.experiments import build_parts, make_context
from eval.paper.parts import Cell


def _cell(agent: str = "ebm", paper: float | None = -20.0, why: str | None = "maze-first-wall") -> Cell:
    return Cell("online", "maze", agent, (), paper, why=why)


def _paper_cells(tmp_path) -> dict[str, Cell]:
    parts = build_parts(["all"], make_context("paper", str(tmp_path)))
    return {cell.id: cell for part in parts for cell in part.cells}


def test_a_cell_differs_only_when_the_paper_lies_outside_our_interval():
    close = ("table1/maze/online", _cell(), np.array([-19.0, -21.0, -20.5]))
    far = ("table1/maze/online", _cell(), np.array([-1200.0, -1210.0, -1190.0]))
    better = ("table1/particle/online", _cell(), np.array([-5.0, -5.5, -4.8]))
    few = ("table1/maze/online", _cell(), np.array([-1200.0, -1210.0]))
    no_paper = ("table1/maze/online", _cell(paper=None), np.array([-1200.0, -1210.0, -1190.0]))
    found = find_differences([close, far, better, few, no_paper])
    assert [(d.part, d.direction) for d in found] == [("table1/maze/online", "worse"), ("table1/particle/online", "better")]
    assert found[0].low <= found[0].mean <= found[0].high and found[0].seeds == 3


def test_each_cell_names_its_note_and_an_unnamed_one_says_so(tmp_path):
    cells = _paper_cells(tmp_path)
    assert "first wall" in note(cells["table1/maze/pretrained:action-ff"].why)
    assert "untrained agent" in note(cells["table1/particle/online:ebm"].why)
    assert "off by one" in note(cells["table1/particle/online:action-ff"].why)
    assert "change of state" in note(cells["table1/reacher/pretrained:action-ff"].why)
    assert "no inverse dynamics" in note(cells["table2/sawyer/online_fixed:action-ff"].why)
    assert "residual=false" in note(cells["table2/sawyer/pretrained_random:action-ff"].why)
    assert "left the finger's move unlearned" in note(cells["table2/sawyer/pretrained_directed_sequential:action-ff"].why)
    assert "learned inverse model fails" in note(cells["inverse_dynamics/sawyer:ebm:rls"].why)
    assert "matches the planned finger" in note(cells["inverse_dynamics/sawyer:ebm:ground_truth"].why)
    assert note(None) == NOT_INVESTIGATED


def test_every_note_named_in_paper_yaml_exists_and_every_note_is_named():
    named = set()
    for experiment in paper_data()["experiments"]:
        for part in experiment["parts"]:
            named |= {cell["why"] for cell in part.get("cells", ()) if "why" in cell}
    for claim in paper_data()["claims"]:
        named |= {comparison["why"] for comparison in claim["compare"] if "why" in comparison}
    assert named == set(notes())
    with pytest.raises(KeyError, match="does not have"):
        note("no-such-note")


def test_the_section_lists_each_difference_with_its_reason():
    found = find_differences([("table1/maze/online", _cell(), np.array([-1200.0, -1210.0, -1190.0]))])
    text = "\n".join(render_differences(found))
    assert "## Where we differ from the paper, and why" in text
    assert "**table1/maze/online, EBM** (online): ours -1200.00" in text and "worse than the paper's -20" in text
    assert "Why: Our agents reach the first wall" in text
    assert "No finished cell differs" in "\n".join(render_differences([]))
    unexplained = find_differences([("table1/maze/online", _cell(why=None), np.array([-1200.0, -1210.0, -1190.0]))])
    assert "Why: not investigated yet." in "\n".join(render_differences(unexplained))


def test_cells_with_one_reason_share_it_and_the_reason_is_written_once():
    scores = np.array([-1200.0, -1210.0, -1190.0])
    cells = [
        ("table1/maze/pretrained", _cell("ebm"), scores),
        ("table1/particle/online", _cell("action-ff", why="particle-action-ff-original-bug"), np.array([-5.0, -5.5, -4.8])),
        ("table1/maze/online", _cell("action-ff"), scores),
    ]
    text = "\n".join(render_differences(find_differences(cells)))
    assert text.count("Our agents reach the first wall") == 1
    assert "- 2 cells with one reason:" in text
    maze = text.index("**table1/maze/pretrained, EBM**"), text.index("**table1/maze/online, Action FF**")
    assert maze[0] < maze[1] < text.index("Why: Our agents reach the first wall")
    assert text.count("off by one") == 1 and "**table1/particle/online, Action FF** (online)" in text
