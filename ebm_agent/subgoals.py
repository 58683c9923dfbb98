"""Long-horizon goal reaching through the learned energy: a graph over visited states, and subgoals along its paths.

A plan of T steps cannot find a way round a wall that first leads away from the goal (issue #36): every goal energy
rises along the detour. SoRB (Eysenbach et al. 2019) plans over states the agent has seen instead, with learned edge
costs. Here the edges come from what an energy over transitions is for: which short moves are possible.

:class:`GraphSubgoals` keeps one node per occupied cell of a grid over visited states (the cell's centre; side 3/4 of
the largest real step of each dim), joins neighbouring cells when the learned energy says the move between their
centres is possible (E(u, v) at most a quantile of the energies of real transitions), and before each plan replaces
the goal with the node ``lookahead`` edges along the shortest path from the state to the goal (the goal itself once
the path is shorter). Where no path exists the goal is kept, so the agent plans as before.

It uses only what the agent learned and saw (states, real step sizes, its energy): no wall map, no env internals.
Any agent whose ``subgoals`` attribute the planning loop reads (:class:`~ebm_agent.base.PlannerAgentBase`) can use it;
the edges need an energy (``energy_model``), so the EBM agent.

Usage::

    agent.learn_offline(dataset, epochs=10)
    agent.subgoals = GraphSubgoals.from_transitions(agent, dataset.states, dataset.next_states)
    # predict() now plans towards subgoals; agent.subgoals = None restores the plain goal
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from ebm_agent.probe import transition_energies

__all__ = ["GraphSubgoals"]


@dataclass
class GraphSubgoals:
    """Subgoals along shortest paths of a graph over visited states whose edges the learned energy allows.

    Build it with :meth:`from_transitions`; the fields are the built graph.

    :param nodes: [V, D] the graph's states (centres of visited cells).
    :param goal_indices: [G] the state dims a goal is compared with (``GoalSpec.goal_indices``).
    :param step: [D] the largest real one-step change of each dim (the scale of the node searches).
    :param graph: [V, V] sparse costs of the allowed moves u -> v (1 plus the clearance term).
    :param lookahead: edges along the path to the subgoal (about the plan's horizon).
    :param energy_threshold: the energy below which a move is allowed (a quantile of real transitions' energies).
    :param energy: ``energy(states [K, D], next_states [K, D]) -> [K]`` numpy energies, or None. With it, a subgoal is
        the farthest path node within ``lookahead`` in sight of the state: the straight segment to it stays in visited
        cells and the energy allows each move of at most one cell along it (under ``energy_threshold``), so that plans
        do not cut corners through walls; without it, the node ``lookahead`` edges along.
    :param cell: the grid's cell side, in units of ``step``.
    """

    nodes: np.ndarray
    goal_indices: np.ndarray
    step: np.ndarray
    graph: csr_matrix
    lookahead: int
    energy_threshold: float
    energy: Any = None
    cell: float = 0.75
    _tree: cKDTree = field(init=False, repr=False)
    _cells: set[tuple[int, ...]] = field(init=False, repr=False)
    _paths: dict[int, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        self._tree = cKDTree(self.nodes / self.step)  # Chebyshev queries in units of one step
        self._cells = set(map(tuple, self._cell_of(self.nodes).tolist()))  # the visited cells

    @classmethod
    def from_transitions(
        cls,
        agent: Any,
        states: np.ndarray,
        next_states: np.ndarray,
        lookahead: int | None = None,
        quantile: float = 0.95,
        cell: float = 0.75,
        clearance: float = 2.0,
        max_nodes: int = 5000,
        seed: int = 0,
    ) -> GraphSubgoals:
        """Build the graph from real transitions (a dataset, or an online agent's replay buffer).

        :param agent: an agent with ``energy_model`` (E(s [..., D], s' [..., D]) -> [...]), ``goal_spec``, ``device``
            and ``horizon``.
        :param states: [M, D] real states.
        :param next_states: [M, D] their real next states.
        :param lookahead: edges to the subgoal (default: the agent's horizon).
        :param quantile: a move is allowed when its energy is at most this quantile of the real transitions'.
        :param cell: the grid's cell side in units of the largest real step of each dim (below 1, so that a move
            between neighbouring cells' centres is one a single step can make).
        :param clearance: extra cost of entering a node with few allowed moves out (1 - its out-degree / the
            largest), which keeps paths and subgoals off walls; 0: every move costs the same.
        :param max_nodes: cap on the nodes (a random subset of the occupied cells beyond it).
        :param seed: seed of that subset and of the transitions the threshold is read from.
        :return: the graph.
        :raises ValueError: for empty or mismatched transitions, or a quantile outside (0, 1].
        """
        states, next_states = np.asarray(states, np.float32), np.asarray(next_states, np.float32)  # [M, D] each
        if states.ndim != 2 or states.shape != next_states.shape or len(states) == 0:
            raise ValueError(
                f"states and next_states must be non-empty [M, D] arrays, got {states.shape} and {next_states.shape}."
            )
        if not 0.0 < quantile <= 1.0:
            raise ValueError(f"quantile must be in (0, 1], got {quantile!r}.")
        if not 0.0 < cell <= 1.0:
            raise ValueError(f"cell must be in (0, 1] (a fraction of one real step), got {cell!r}.")
        rng = np.random.default_rng(seed)
        step = np.maximum(np.abs(next_states - states).max(axis=0), 1e-6)  # [D]
        side = cell * step  # [D]
        occupied = np.unique(np.floor(states / side).astype(np.int64), axis=0)  # [V, D] visited cells
        if len(occupied) > max_nodes:
            occupied = occupied[np.sort(rng.choice(len(occupied), max_nodes, replace=False))]
        nodes = ((occupied + 0.5) * side).astype(np.float32)  # [V, D] cell centres: neighbours are one move apart
        energy = functools.partial(transition_energies, agent)
        sample = rng.choice(len(states), min(len(states), 20_000), replace=False)
        threshold = float(np.quantile(energy(states[sample], next_states[sample]), quantile))
        pairs = cKDTree(occupied).query_pairs(1.0, p=np.inf, output_type="ndarray")  # [P, 2] neighbouring cells
        pairs = np.concatenate([pairs, pairs[:, ::-1]])  # both directions: feasibility is directional
        allowed = pairs[energy(nodes[pairs[:, 0]], nodes[pairs[:, 1]]) <= threshold]  # [E, 2]
        # An edge costs one move, plus ``clearance`` for entering a node that few allowed moves leave (one beside a
        # wall, or at the edge of what was visited): paths keep to the open, where the plans' moves are reliable.
        degree = np.bincount(allowed[:, 0], minlength=len(nodes))  # [V]
        cost = 1.0 + clearance * (1.0 - degree[allowed[:, 1]] / max(int(degree.max(initial=0)), 1))  # [E]
        graph = csr_matrix((cost, (allowed[:, 0], allowed[:, 1])), shape=(len(nodes), len(nodes)))
        spec = agent.goal_spec
        horizon = int(agent.horizon) if lookahead is None else int(lookahead)
        return cls(nodes, np.asarray(spec.goal_indices), step, graph, max(horizon, 1), threshold, energy, cell)

    @property
    def num_edges(self) -> int:
        """Allowed moves in the graph."""
        return int(self.graph.nnz)

    def subgoals(self, states: np.ndarray, goals: np.ndarray) -> np.ndarray:
        """The goal each plan should aim at: ``lookahead`` edges along the shortest path to the goal.

        :param states: [N, D] current states.
        :param goals: [N, G] the goals.
        :return: [N, G] subgoals (a goal itself where the path is shorter than ``lookahead``, or where none exists).
        """
        out = np.array(goals, dtype=np.float32, copy=True)  # [N, G]
        for i, (state, goal) in enumerate(zip(np.asarray(states, np.float32), out)):
            target = self._goal_node(goal)
            distance, toward = self._paths_to(target)
            node = self._start_node(state, distance)
            if node is None:
                continue  # no path from here: plan towards the goal as before
            path = [node]
            while len(path) <= self.lookahead and path[-1] != target:
                path.append(int(toward[path[-1]]))
            chosen = self._in_sight(state, path) if self.energy is not None else path[-1]
            if chosen != target:
                out[i] = self.nodes[chosen, self.goal_indices]
        return out

    def _in_sight(self, state: np.ndarray, path: list[int]) -> int:
        """The farthest node of ``path`` (the first one at least) whose straight approach from ``state`` the energy allows."""
        for node in reversed(path[1:]):
            segment = self.nodes[node] - state  # [D]
            moves = max(int(np.ceil(np.abs(segment / (self.cell * self.step)).max())), 1)
            points = state + np.linspace(0.0, 1.0, 2 * moves + 1)[:, None] * segment  # [2 moves + 1, D]
            if not all(cell in self._cells for cell in map(tuple, self._cell_of(points[1:]).tolist())):
                continue  # the segment leaves the visited cells (into a wall, or where nothing was seen)
            if np.all(self.energy(points[:-2:2].astype(np.float32), points[2::2].astype(np.float32)) <= self.energy_threshold):
                return node
        return path[1] if len(path) > 1 else path[0]

    def path(self, state: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """The graph's shortest path from a state to a goal, for inspection and plots.

        :param state: [D].
        :param goal: [G].
        :return: [L, D] the path's nodes (empty when there is none).
        """
        target = self._goal_node(np.asarray(goal, np.float32))
        distance, toward = self._paths_to(target)
        node = self._start_node(np.asarray(state, np.float32), distance)
        if node is None:
            return np.zeros((0, self.nodes.shape[1]), np.float32)
        path = [node]
        while node != target:
            node = int(toward[node])
            path.append(node)
        return self.nodes[path]

    def _cell_of(self, points: np.ndarray) -> np.ndarray:
        """[K, D] points -> [K, D] the integer indices of their grid cells."""
        return np.floor(points / (self.cell * self.step)).astype(np.int64)

    def _goal_node(self, goal: np.ndarray) -> int:
        """The node nearest the goal in the goal dims."""
        gaps = np.abs(self.nodes[:, self.goal_indices] - goal) / self.step[self.goal_indices]  # [V, G]
        return int(np.argmin(gaps.max(axis=1)))

    def _paths_to(self, target: int) -> tuple[np.ndarray, np.ndarray]:
        """The path cost from every node to ``target`` and each node's next node on its path (cached per target)."""
        if target not in self._paths:
            distance, predecessors = dijkstra(self.graph.T.tocsr(), indices=target, return_predecessors=True)
            self._paths[target] = (distance, predecessors)  # in the reversed graph, a predecessor is the next hop
        return self._paths[target]

    def _start_node(self, state: np.ndarray, distance: np.ndarray, candidates: int = 8) -> int | None:
        """The node nearest the state that has a path to the target (among the ``candidates`` nearest)."""
        _, near = self._tree.query(state / self.step, k=min(candidates, len(self.nodes)), p=np.inf)
        for node in np.atleast_1d(near):
            if np.isfinite(distance[int(node)]):
                return int(node)
        return None
