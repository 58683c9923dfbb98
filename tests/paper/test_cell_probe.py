"""python -m eval.paper.probe: one experiment cell with the agent's settings changed, in its own folder."""

from __future__ import annotations

import json

import pytest

import eval.paper.probe as cell_probe


@pytest.fixture(scope="module")
def probe():
    return cell_probe


def test_a_probe_runs_the_cell_with_the_change_into_its_own_folder(probe, tmp_path, capsys):
    argv = ["table1/particle/pretrained", "action-ff", "residual=true", "--scale", "smoke", "--out", str(tmp_path)]
    scores = probe.main(argv)
    assert len(scores) == 1
    (metrics,) = tmp_path.rglob("metrics.json")
    assert "residual-True" in str(metrics) and json.loads(metrics.read_text())["score_mean"] == pytest.approx(scores[0])
    config = (metrics.parent / "config.yaml").read_text()
    assert "residual: true" in config
    assert probe.main(argv) == scores  # a finished probe run is read back, not rerun
    assert "seed 0:" in capsys.readouterr().out


def test_a_change_needs_a_key_and_a_value(probe):
    assert probe.parse_change("cost={goal_weight: 0.1}") == ("cost", {"goal_weight": 0.1})
    with pytest.raises(Exception, match="KEY=VALUE"):
        probe.parse_change("residual")


def test_an_unknown_part_is_a_usage_error(probe, tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        probe.main(["table9/particle/online", "ebm", "--scale", "smoke", "--out", str(tmp_path)])
    assert stop.value.code == 2 and "unknown experiment" in capsys.readouterr().err


def test_datasets_of_another_results_folder_are_linked_once_and_never_over_a_folder(tmp_path):
    script = cell_probe
    source = tmp_path / "results" / "datasets"
    (source / "sawyer").mkdir(parents=True)
    (source / "sawyer" / "directed_n100000_s0_x.npz").write_bytes(b"data")
    out = tmp_path / "probe" / "cell"
    script.link_datasets(source, out)
    script.link_datasets(source, out)  # the same link again: nothing to do
    assert (out / "datasets").is_symlink()
    assert (out / "datasets" / "sawyer" / "directed_n100000_s0_x.npz").read_bytes() == b"data"
    with pytest.raises(SystemExit, match="no such folder"):
        script.link_datasets(tmp_path / "missing", out)
    other = tmp_path / "probe" / "other"
    (other / "datasets").mkdir(parents=True)
    with pytest.raises(SystemExit, match="already exists"):
        script.link_datasets(source, other)
