"""scripts/maze_explore_probe.py: the goal-free explorer's coverage with changed settings."""

from __future__ import annotations


def test_it_prints_a_coverage_curve_with_the_changes(load_script, capsys):
    script = load_script("maze_explore_probe")
    curve = script.main(["online={replay_positives: false}", "--scale", "smoke", "--points", "2"])
    assert len(curve) == 2 and all(0.0 < coverage <= 1.0 for _, coverage in curve)
    assert curve[0][0] < curve[1][0]
    out = capsys.readouterr().out
    assert "'replay_positives': False" in out and "'goal_weight': 0.0" in out
