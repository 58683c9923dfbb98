"""scripts/maze_walls.py: the energies of blocked and free maze moves, and where a maze agent goes."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

import envs  # noqa: F401
from ebm_agent import EBMPlannerAgent
from envs.maze import maze_valid

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "maze_walls.py"


def _script():
    spec = importlib.util.spec_from_file_location("maze_walls_script", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules["maze_walls_script"] = module
    spec.loader.exec_module(module)
    return module


def test_the_transitions_are_what_they_say():
    for what, start, end in _script().TRANSITIONS:
        start_ok, end_ok = maze_valid(np.array([start, end]))
        assert start_ok, what
        assert end_ok == (not what.startswith("blocked")), what


def test_it_reports_an_energy_per_transition_and_the_rollout(tmp_path, capsys):
    agent = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Maze-v0"), seed=0, device="cpu")
    agent.save(tmp_path / "maze.zip")
    energies, positions = _script().main([str(tmp_path / "maze.zip"), "--steps", "50"])
    assert len(energies) == 7 and all(np.isfinite(list(energies.values())))
    assert positions[0] == [-0.85, -0.85] and len(positions) == 3
    assert maze_valid(np.array(positions)).all()
    assert "| blocked: into the first wall |" in capsys.readouterr().out
