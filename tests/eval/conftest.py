"""Helpers of the eval tests."""

from __future__ import annotations

import pytest


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
