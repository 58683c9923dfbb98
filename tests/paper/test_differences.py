"""The 'where we differ from the paper' section: computed from the numbers, explained from eval/paper/differences.py."""

from __future__ import annotations

import numpy as np

from eval.paper.differences import explain, find_differences, render_differences
from eval.paper.parts import Cell


def _cell(agent: str = "ebm", paper: float | None = -20.0) -> Cell:
    return Cell("online", "maze", agent, (), paper)


def test_a_cell_differs_only_when_the_paper_lies_outside_our_interval():
    close = ("table1/maze/online", _cell(), np.array([-19.0, -21.0, -20.5]))
    far = ("table1/maze/online", _cell(), np.array([-1200.0, -1210.0, -1190.0]))
    better = ("table1/particle/online", _cell(), np.array([-5.0, -5.5, -4.8]))
    few = ("table1/maze/online", _cell(), np.array([-1200.0, -1210.0]))
    no_paper = ("table1/maze/online", _cell(paper=None), np.array([-1200.0, -1210.0, -1190.0]))
    found = find_differences([close, far, better, few, no_paper])
    assert [(d.part, d.direction) for d in found] == [("table1/maze/online", "worse"), ("table1/particle/online", "better")]
    assert found[0].low <= found[0].mean <= found[0].high and found[0].seeds == 3


def test_explanations_match_by_part_and_agent_and_say_so_when_unknown():
    assert "first wall" in explain("table1/maze/pretrained", "action-ff")
    assert "untrained agent" in explain("table1/particle/online", "ebm")
    assert "off by one" in explain("table1/particle/online", "action-ff")
    assert "change of state" in explain("table1/reacher/pretrained", "action-ff")
    assert "no inverse dynamics" in explain("table2/sawyer/online_fixed", "action-ff")
    assert "no inverse dynamics" in explain("fixed_on_variable/sawyer", "action-ff")
    assert "residual=false" in explain("table2/sawyer/pretrained_random", "action-ff")
    assert "matches the planned finger" in explain("inverse_dynamics/sawyer", "ebm")
    assert "left the finger's move unlearned" in explain("table2/sawyer/pretrained_directed", "action-ff")
    assert "left the finger's move unlearned" in explain("table2/sawyer/pretrained_directed_sequential", "action-ff")
    assert explain("table2/sawyer/pretrained_random", "ppo") == "not investigated yet."


def test_a_setting_pattern_picks_the_rows_of_a_part_that_differ_in_more_than_the_agent():
    assert "learned inverse model fails" in explain("inverse_dynamics/sawyer", "ebm", "RLS")
    assert "matches the planned finger" in explain("inverse_dynamics/sawyer", "ebm", "ground truth")
    rls = Cell("RLS", "sawyer", "ebm", (), -4694.0)
    ground_truth = Cell("ground truth", "sawyer", "ebm", (), -3782.0)
    found = find_differences(
        [
            ("inverse_dynamics/sawyer", ground_truth, np.array([-280.0, -270.0, -290.0])),
            ("inverse_dynamics/sawyer", rls, np.array([-13000.0, -12000.0, -14000.0])),
        ]
    )
    assert ["matches the planned finger" in d.explanation for d in found] == [True, False]
    assert "learned inverse model fails" in found[1].explanation


def test_the_section_lists_each_difference_with_its_reason():
    found = find_differences([("table1/maze/online", _cell(), np.array([-1200.0, -1210.0, -1190.0]))])
    text = "\n".join(render_differences(found))
    assert "## Where we differ from the paper, and why" in text
    assert "**table1/maze/online, EBM** (online): ours -1200.00" in text and "worse than the paper's -20" in text
    assert "Why: Our agents reach the first wall" in text
    assert "No finished cell differs" in "\n".join(render_differences([]))


def test_cells_with_one_reason_share_it_and_the_reason_is_written_once():
    scores = np.array([-1200.0, -1210.0, -1190.0])
    cells = [
        ("table1/maze/pretrained", _cell("ebm"), scores),
        ("table1/particle/online", _cell("action-ff"), np.array([-5.0, -5.5, -4.8])),
        ("table1/maze/online", _cell("action-ff"), scores),
    ]
    text = "\n".join(render_differences(find_differences(cells)))
    assert text.count("Our agents reach the first wall") == 1
    assert "- 2 cells with one reason:" in text
    maze = text.index("**table1/maze/pretrained, EBM**"), text.index("**table1/maze/online, Action FF**")
    assert maze[0] < maze[1] < text.index("Why: Our agents reach the first wall")
    assert text.count("off by one") == 1 and "**table1/particle/online, Action FF** (online)" in text
