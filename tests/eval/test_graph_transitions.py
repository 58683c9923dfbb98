"""A harness run of an agent with graph subgoals keeps the transitions its final graph was built from."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ebm_agent.buffers import TransitionBuffer
from eval.run import save_graph_transitions


def test_a_run_with_graph_subgoals_keeps_the_transitions_its_graph_was_built_from(tmp_path):
    buffer = TransitionBuffer(100, 2, 2, seed=0)
    rng = np.random.default_rng(0)
    states = rng.normal(size=(30, 2)).astype(np.float32)  # [30, 2]
    buffer.add(states, states + 0.01, np.zeros((30, 2), np.float32))
    path = tmp_path / "graph_transitions.npz"
    assert not save_graph_transitions(SimpleNamespace(subgoal_graph=None, pos_buffer=buffer), path)
    assert not path.exists()
    assert not save_graph_transitions(SimpleNamespace(subgoal_graph={}, pos_buffer=TransitionBuffer(10, 2, 2)), path)
    assert save_graph_transitions(SimpleNamespace(subgoal_graph={}, pos_buffer=buffer), path)
    data = np.load(path)
    np.testing.assert_array_equal(data["states"], states)
    np.testing.assert_array_equal(data["next_states"], states + 0.01)
    assert not list(tmp_path.glob("*.partial"))
