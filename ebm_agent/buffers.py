"""Array-backed ring buffer of transitions (s, s', a) with its own seeded random generator."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["TransitionBatch", "TransitionBuffer"]


@dataclass
class TransitionBatch:
    """
    A batch of transitions sampled from a :class:`TransitionBuffer`.

    :param states: [B, D] states s_t.
    :param next_states: [B, D] next states s_{t+1}.
    :param actions: [B, A] executed actions, or None for a buffer that stores none.
    """

    states: np.ndarray
    next_states: np.ndarray
    actions: np.ndarray | None

    def __len__(self) -> int:
        return int(self.states.shape[0])


class TransitionBuffer:
    """
    Array-backed ring buffer of (s, s', a) transitions with its own seeded ``np.random.Generator``.

    Used for both of the original's replay buffers: real transitions (positives, capacity 1e6) and planned
    transitions (negatives, capacity 1e4). Once full, the oldest transitions are overwritten first. Sampling is
    uniform with replacement, like the original, but from a seeded generator (the original used unseeded Python
    ``random``), and the generator state is part of :meth:`state_dict` so a resumed run continues the same stream.

    :param capacity: maximum number of transitions kept.
    :param state_dim: D.
    :param action_dim: A, or None to store no actions (e.g. for negatives).
    :param seed: seed of the sampling generator (None: fresh entropy).
    """

    def __init__(self, capacity: int, state_dim: int, action_dim: int | None = None, seed: int | None = None) -> None:
        for name, value in (("capacity", capacity), ("state_dim", state_dim)):
            if not _is_positive_int(value):
                raise ValueError(f"TransitionBuffer: {name} must be a positive int, got {value!r}.")
        if action_dim is not None and not _is_positive_int(action_dim):
            raise ValueError(f"TransitionBuffer: action_dim must be a positive int or None, got {action_dim!r}.")
        self._capacity = int(capacity)
        self.state_dim = int(state_dim)
        self.action_dim = None if action_dim is None else int(action_dim)
        self._states = np.zeros((self._capacity, self.state_dim), dtype=np.float32)  # [C, D]
        self._next_states = np.zeros((self._capacity, self.state_dim), dtype=np.float32)  # [C, D]
        self._actions = None if self.action_dim is None else np.zeros((self._capacity, self.action_dim), dtype=np.float32)
        self._pos = 0  # next slot to write
        self._size = 0
        self._rng = np.random.default_rng(seed)

    @property
    def capacity(self) -> int:
        """Maximum number of transitions kept."""
        return self._capacity

    @property
    def full(self) -> bool:
        """Whether the buffer holds ``capacity`` transitions (new ones now overwrite the oldest)."""
        return self._size == self._capacity

    @property
    def rng(self) -> np.random.Generator:
        """The buffer's sampling generator (shared, e.g. for the original's 50 % negative replacement mask)."""
        return self._rng

    def __len__(self) -> int:
        return self._size

    def seed(self, seed: int | None) -> None:
        """
        Reset the sampling generator.

        :param seed: new seed (None: fresh entropy).
        """
        self._rng = np.random.default_rng(seed)

    def add(self, states: np.ndarray, next_states: np.ndarray, actions: np.ndarray | None = None) -> None:
        """
        Append transitions, overwriting the oldest ones once full.

        :param states: [B, D] (or [D] for one transition).
        :param next_states: [B, D] (or [D]).
        :param actions: [B, A] (or [A]); required if and only if the buffer was built with ``action_dim``.
        :raises ValueError: for wrong shapes, missing/unexpected actions, or NaN/inf values.
        """
        states_2d = self._as_rows(states, self.state_dim, "states")
        next_2d = self._as_rows(next_states, self.state_dim, "next_states")
        if next_2d.shape[0] != states_2d.shape[0]:
            raise ValueError(
                f"TransitionBuffer.add: states and next_states must have the same batch size, got "
                f"{states_2d.shape[0]} and {next_2d.shape[0]}."
            )
        actions_2d = None
        if self.action_dim is None:
            if actions is not None:
                raise ValueError("TransitionBuffer.add: got actions but the buffer stores none; build it with action_dim=A.")
        else:
            if actions is None:
                raise ValueError(f"TransitionBuffer.add: this buffer stores actions (action_dim={self.action_dim}).")
            actions_2d = self._as_rows(actions, self.action_dim, "actions")
            if actions_2d.shape[0] != states_2d.shape[0]:
                raise ValueError(
                    f"TransitionBuffer.add: actions must have batch size {states_2d.shape[0]}, got {actions_2d.shape[0]}."
                )

        count = states_2d.shape[0]
        if count == 0:
            return
        if count > self._capacity:  # only the newest `capacity` transitions would survive anyway
            states_2d, next_2d = states_2d[-self._capacity :], next_2d[-self._capacity :]
            actions_2d = None if actions_2d is None else actions_2d[-self._capacity :]
            self._pos = (self._pos + count - self._capacity) % self._capacity
            count = self._capacity
        slots = (self._pos + np.arange(count)) % self._capacity  # [B] ring positions, wrapping around
        self._states[slots] = states_2d
        self._next_states[slots] = next_2d
        if self._actions is not None and actions_2d is not None:
            self._actions[slots] = actions_2d
        self._pos = int((self._pos + count) % self._capacity)
        self._size = min(self._size + count, self._capacity)

    def sample(self, batch_size: int) -> TransitionBatch:
        """
        Draw transitions uniformly with replacement (as the original).

        :param batch_size: number of transitions B (>= 1).
        :return: a :class:`TransitionBatch` of copies ([B, D], [B, D], [B, A] or None), float32.
        :raises ValueError: for an empty buffer or a non-positive batch size.
        """
        if not _is_positive_int(batch_size):
            raise ValueError(f"TransitionBuffer.sample: batch_size must be a positive int, got {batch_size!r}.")
        if self._size == 0:
            raise ValueError("TransitionBuffer.sample: the buffer is empty; add transitions before sampling.")
        indices = self._rng.integers(0, self._size, size=int(batch_size))  # [B]
        return self.get(indices)

    def contents(self) -> TransitionBatch:
        """Every stored transition, in storage order (copies).

        :return: a :class:`TransitionBatch` of ``len(self)`` rows.
        """
        return self.get(np.arange(self._size))

    def get(self, indices: np.ndarray) -> TransitionBatch:
        """
        Transitions at given storage indices (0 <= index < len(self)).

        :param indices: [B] int indices into storage.
        :return: a :class:`TransitionBatch` of copies.
        """
        indices = np.asarray(indices)
        if indices.size and (indices.min() < 0 or indices.max() >= self._size):
            raise ValueError(f"TransitionBuffer.get: indices must lie in [0, {self._size}).")
        actions = None if self._actions is None else self._actions[indices]
        return TransitionBatch(self._states[indices], self._next_states[indices], actions)

    def state_dict(self) -> dict[str, Any]:
        """
        Everything needed to resume: the stored transitions, write position, size and generator state.

        Only the filled part of the arrays is copied, so a checkpoint of a large, mostly empty buffer stays small.

        :return: a dict of numpy arrays and plain Python values (picklable, ``torch.save``-able).
        """
        return {
            "capacity": self._capacity,
            "state_dim": self.state_dim,
            "action_dim": self.action_dim,
            "states": self._states[: self._size].copy(),
            "next_states": self._next_states[: self._size].copy(),
            "actions": None if self._actions is None else self._actions[: self._size].copy(),
            "position": self._pos,
            "size": self._size,
            "rng_state": self._rng.bit_generator.state,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """
        Restore a :meth:`state_dict`, including the sampling stream.

        :param state: a dict from :meth:`state_dict` of a buffer with the same capacity and dims.
        :raises ValueError: for missing keys or mismatched capacity/dims.
        """
        required = ("capacity", "state_dim", "action_dim", "states", "next_states", "actions", "position", "size")
        missing = [key for key in required if key not in state]
        if missing:
            raise ValueError(f"TransitionBuffer.load_state_dict: missing keys {missing}; pass a dict from state_dict().")
        saved = (state["capacity"], state["state_dim"], state["action_dim"])
        mine = (self._capacity, self.state_dim, self.action_dim)
        if tuple(saved) != mine:
            raise ValueError(
                f"TransitionBuffer.load_state_dict: saved (capacity, state_dim, action_dim) = {saved} does not match "
                f"this buffer's {mine}; build the buffer with the saved sizes."
            )
        size = int(state["size"])
        self._states[:size] = state["states"]
        self._next_states[:size] = state["next_states"]
        if self._actions is not None:
            self._actions[:size] = state["actions"]
        self._size = size
        self._pos = int(state["position"])
        if state.get("rng_state") is not None:
            bit_generator = getattr(np.random, state["rng_state"]["bit_generator"])()
            bit_generator.state = state["rng_state"]
            self._rng = np.random.Generator(bit_generator)

    def _as_rows(self, array: np.ndarray, dim: int, name: str) -> np.ndarray:
        rows = np.asarray(array, dtype=np.float32)
        if rows.ndim == 1:
            rows = rows[None]
        if rows.ndim != 2 or rows.shape[1] != dim:
            raise ValueError(f"TransitionBuffer.add: expected {name} of shape [B, {dim}], got {np.shape(array)}.")
        if not np.all(np.isfinite(rows)):
            raise ValueError(
                f"TransitionBuffer.add: {name} contains NaN or inf (after casting to float32); drop or fix those "
                "transitions before adding them."
            )
        return rows


def _is_positive_int(value: Any) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool) and bool(value >= 1)
