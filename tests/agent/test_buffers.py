"""Transition ring buffer: overwrite order, seeded sampling, checkpoint round trip and input validation."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from ebm_agent.buffers import TransitionBatch, TransitionBuffer


def _transitions(start: int, count: int, state_dim: int = 2, action_dim: int = 1) -> tuple[np.ndarray, ...]:
    ids = np.arange(start, start + count, dtype=np.float64)
    states = np.repeat(ids[:, None], state_dim, axis=1)  # row i is filled with its transition id
    return states, states + 0.5, np.repeat(-ids[:, None], action_dim, axis=1)


def test_ring_overwrites_oldest_first() -> None:
    buffer = TransitionBuffer(capacity=5, state_dim=2, action_dim=1, seed=0)
    buffer.add(*_transitions(0, 3))
    assert len(buffer) == 3 and not buffer.full
    buffer.add(*_transitions(3, 4))  # ids 3..6; 0 and 1 are overwritten
    assert len(buffer) == 5 and buffer.full and buffer.capacity == 5
    stored = buffer.get(np.arange(5))
    np.testing.assert_array_equal(stored.states[:, 0], [5, 6, 2, 3, 4])
    np.testing.assert_array_equal(stored.next_states[:, 1], [5.5, 6.5, 2.5, 3.5, 4.5])
    np.testing.assert_array_equal(stored.actions[:, 0], [-5, -6, -2, -3, -4])
    buffer.add(*_transitions(7, 1))  # next write goes to slot 2, the oldest
    np.testing.assert_array_equal(buffer.get(np.arange(5)).states[:, 0], [5, 6, 7, 3, 4])


def test_add_more_than_capacity_keeps_the_newest() -> None:
    buffer = TransitionBuffer(capacity=4, state_dim=2, action_dim=1)
    buffer.add(*_transitions(0, 2))
    buffer.add(*_transitions(2, 9))  # ids 2..10, only 7..10 survive
    assert sorted(buffer.get(np.arange(4)).states[:, 0]) == [7, 8, 9, 10]
    buffer.add(*_transitions(11, 1))  # and 7, the oldest, goes next
    assert sorted(buffer.get(np.arange(4)).states[:, 0]) == [8, 9, 10, 11]


def test_sample_is_seeded_and_uniform_with_replacement() -> None:
    def draw(seed: int) -> np.ndarray:
        buffer = TransitionBuffer(capacity=100, state_dim=2, action_dim=1, seed=seed)
        buffer.add(*_transitions(0, 50))
        return np.concatenate([buffer.sample(20).states[:, 0] for _ in range(3)])

    np.testing.assert_array_equal(draw(3), draw(3))
    assert not np.array_equal(draw(3), draw(4))
    values = draw(5)
    assert values.min() >= 0 and values.max() < 50  # never the unfilled part
    small = TransitionBuffer(capacity=100, state_dim=2, action_dim=1, seed=0)
    small.add(*_transitions(0, 5))
    counts = np.bincount(small.sample(1000).states[:, 0].astype(int), minlength=5)
    assert counts.sum() == 1000 and counts.min() > 150  # more draws than items: with replacement, about uniform


def test_sample_returns_float32_copies() -> None:
    buffer = TransitionBuffer(capacity=10, state_dim=2, action_dim=1, seed=0)
    buffer.add(*_transitions(0, 10))
    batch = buffer.sample(4)
    assert isinstance(batch, TransitionBatch) and len(batch) == 4
    assert batch.states.dtype == np.float32 and batch.actions is not None and batch.actions.dtype == np.float32
    batch.states[:] = 99.0
    assert buffer.get(np.arange(10)).states.max() < 10  # storage untouched


def test_buffer_without_actions() -> None:
    buffer = TransitionBuffer(capacity=10, state_dim=3, seed=0)
    buffer.add(np.zeros((4, 3)), np.ones((4, 3)))
    assert buffer.sample(2).actions is None
    with pytest.raises(ValueError, match="action_dim"):
        buffer.add(np.zeros((1, 3)), np.ones((1, 3)), np.zeros((1, 1)))


def test_state_dict_round_trip_continues_the_same_stream() -> None:
    buffer = TransitionBuffer(capacity=8, state_dim=2, action_dim=1, seed=11)
    buffer.add(*_transitions(0, 11))  # wrapped around
    buffer.sample(5)
    state = pickle.loads(pickle.dumps(buffer.state_dict()))  # as through a checkpoint file
    assert state["states"].shape == (8, 2)
    restored = TransitionBuffer(capacity=8, state_dim=2, action_dim=1, seed=999)
    restored.load_state_dict(state)
    assert len(restored) == len(buffer) and restored.full
    for _ in range(3):
        mine, theirs = buffer.sample(6), restored.sample(6)
        np.testing.assert_array_equal(mine.states, theirs.states)
        np.testing.assert_array_equal(mine.actions, theirs.actions)
    # The write position survives too: both overwrite the same slot next.
    buffer.add(*_transitions(50, 1))
    restored.add(*_transitions(50, 1))
    np.testing.assert_array_equal(buffer.get(np.arange(8)).states, restored.get(np.arange(8)).states)


def test_state_dict_of_partly_filled_buffer_is_small_and_restores() -> None:
    buffer = TransitionBuffer(capacity=1000, state_dim=2, action_dim=1, seed=0)
    buffer.add(*_transitions(0, 3))
    state = buffer.state_dict()
    assert state["states"].shape == (3, 2)
    restored = TransitionBuffer(capacity=1000, state_dim=2, action_dim=1)
    restored.load_state_dict(state)
    np.testing.assert_array_equal(restored.get(np.arange(3)).states, buffer.get(np.arange(3)).states)
    with pytest.raises(ValueError, match="capacity"):
        TransitionBuffer(capacity=10, state_dim=2, action_dim=1).load_state_dict(state)


def test_seed_resets_the_stream() -> None:
    buffer = TransitionBuffer(capacity=10, state_dim=2, action_dim=1)
    buffer.add(*_transitions(0, 10))
    buffer.seed(7)
    first = buffer.sample(8).states
    buffer.seed(7)
    np.testing.assert_array_equal(buffer.sample(8).states, first)


def test_bad_inputs_raise_clear_errors() -> None:
    buffer = TransitionBuffer(capacity=10, state_dim=2, action_dim=1)
    with pytest.raises(ValueError, match="empty"):
        buffer.sample(1)
    with pytest.raises(ValueError, match=r"states of shape \[B, 2\]"):
        buffer.add(np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 1)))
    with pytest.raises(ValueError, match="same batch size"):
        buffer.add(np.zeros((3, 2)), np.zeros((2, 2)), np.zeros((3, 1)))
    with pytest.raises(ValueError, match="stores actions"):
        buffer.add(np.zeros((3, 2)), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="NaN or inf"):
        buffer.add(np.array([[0.0, np.nan]]), np.zeros((1, 2)), np.zeros((1, 1)))
    with pytest.raises(ValueError, match="NaN or inf"):
        buffer.add(np.zeros((1, 2)), np.zeros((1, 2)), np.array([[np.inf]]))
    assert len(buffer) == 0  # rejected batches leave nothing behind
    with pytest.raises(ValueError, match="capacity"):
        TransitionBuffer(capacity=0, state_dim=2)
    buffer.add(np.zeros(2), np.ones(2), np.zeros(1))  # a single unbatched transition is fine
    with pytest.raises(ValueError, match="batch_size"):
        buffer.sample(0)


def test_contents_is_every_stored_transition_in_storage_order_and_leaves_the_stream_alone() -> None:
    buffer = TransitionBuffer(4, 2, 1, seed=0)
    assert len(buffer.contents().states) == 0
    states = np.arange(12, dtype=np.float32).reshape(6, 2)  # [6, 2]: the first two are overwritten
    buffer.add(states, states + 1, np.zeros((6, 1), np.float32))
    before = buffer.rng.bit_generator.state
    batch = buffer.contents()
    assert buffer.rng.bit_generator.state == before
    np.testing.assert_array_equal(batch.states, buffer.get(np.arange(4)).states)
    assert sorted(map(tuple, batch.states.tolist())) == sorted(map(tuple, states[2:].tolist()))
