"""Helpers of the eval tests."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import pytest

SCRIPTS = Path(__file__).resolve().parents[2] / "scripts"


def _load_script(name: str) -> ModuleType:
    """Import ``scripts/<name>.py`` (not a package) as the module ``<name>_script``."""
    spec = importlib.util.spec_from_file_location(f"{name}_script", SCRIPTS / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="session")
def load_script():
    """The loader of ``scripts/<name>.py`` modules: ``load_script("probe")``."""
    return _load_script


def _save_untrained_model(env_id: str, path: Path) -> Path:
    """Save an untrained EBM on ``env_id`` with a tiny planner (8 samples, 2 iterations) to ``path``."""
    import gymnasium as gym

    import envs  # noqa: F401  (registers the ebm/ ids)
    from ebm_agent import EBMPlannerAgent

    env = gym.make(env_id)
    agent = EBMPlannerAgent("MultiInputPolicy", env, seed=0, device="cpu", planner_config={"num_samples": 8, "iterations": 2})
    agent.save(path)
    return path


@pytest.fixture
def untrained_sawyer_model(tmp_path) -> Path:
    """A saved, untrained EBM on ``ebm/SawyerReach-v0`` with a tiny planner (8 samples, 2 iterations)."""
    return _save_untrained_model("ebm/SawyerReach-v0", tmp_path / "sawyer.zip")


@pytest.fixture
def untrained_reacher_model(tmp_path) -> Path:
    """A saved, untrained EBM on ``ebm/Reacher-v0`` with a tiny planner (8 samples, 2 iterations)."""
    return _save_untrained_model("ebm/Reacher-v0", tmp_path / "reacher.zip")


def _kill_training_after(monkeypatch: pytest.MonkeyPatch, agent: str, transitions: int) -> None:
    """Make the agent's training step raise once ``transitions`` are consumed, as a killed process would stop.

    :param monkeypatch: the patcher (a ``monkeypatch.context()`` undoes it at the end of its block).
    :param agent: ``"ebm"`` or ``"action-ff"``.
    :param transitions: the transitions after which the next training step raises ``RuntimeError("killed")``.
    """
    from baselines.action_ff import ActionFFAgent
    from ebm_agent.agent import EBMPlannerAgent

    agent_class = EBMPlannerAgent if agent == "ebm" else ActionFFAgent
    original = agent_class._train_on_segments

    def dies_late(self, segments):
        if self.num_timesteps > transitions:
            raise RuntimeError("killed")
        return original(self, segments)

    monkeypatch.setattr(agent_class, "_train_on_segments", dies_late)


@pytest.fixture(scope="session")
def kill_training_after():
    """``kill_training_after(monkeypatch, agent, transitions)``: a training step that raises past ``transitions``."""
    return _kill_training_after


def _signal_training_after(monkeypatch: pytest.MonkeyPatch, agent: str, transitions: int, signum: int) -> None:
    """Make the agent's training send ``signum`` to this process once, at its first step past ``transitions``.

    :param monkeypatch: the patcher.
    :param agent: ``"ebm"`` or ``"action-ff"``.
    :param transitions: the transitions after which the signal is sent.
    :param signum: the signal (SIGTERM, SIGINT).
    """
    import os

    from baselines.action_ff import ActionFFAgent
    from ebm_agent.agent import EBMPlannerAgent

    agent_class = EBMPlannerAgent if agent == "ebm" else ActionFFAgent
    original = agent_class._train_on_segments
    sent: list[int] = []

    def signals_once(self, segments):
        if self.num_timesteps > transitions and not sent:
            sent.append(self.num_timesteps)
            os.kill(os.getpid(), signum)
        return original(self, segments)

    monkeypatch.setattr(agent_class, "_train_on_segments", signals_once)


@pytest.fixture(scope="session")
def signal_training_after():
    """``signal_training_after(monkeypatch, agent, transitions, signum)``: a training step that signals once."""
    return _signal_training_after
