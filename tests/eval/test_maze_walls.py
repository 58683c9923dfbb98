"""scripts/maze_walls.py: the energies of blocked and free maze moves, and where a maze agent goes."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401
from ebm_agent import EBMPlannerAgent
from envs.maze import maze_valid


@pytest.fixture(scope="module")
def script(load_script):
    return load_script("maze_walls")


def test_the_transitions_are_what_they_say(script):
    for what, start, end in script.TRANSITIONS:
        start_ok, end_ok = maze_valid(np.array([start, end]))
        assert start_ok, what
        assert end_ok == (not what.startswith("blocked")), what


def test_it_reports_an_energy_per_transition_and_the_rollout(script, tmp_path, capsys):
    agent = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Maze-v0"), seed=0, device="cpu")
    agent.save(tmp_path / "maze.zip")
    energies, positions = script.main([str(tmp_path / "maze.zip"), "--steps", "50"])
    assert len(energies) == 7 and all(np.isfinite(list(energies.values())))
    assert positions[0] == [-0.85, -0.85] and len(positions) == 3
    assert maze_valid(np.array(positions)).all()
    assert "| blocked: into the first wall |" in capsys.readouterr().out
