"""Long-horizon goal reaching through the learned energy: a graph over visited states, and subgoals along its paths.

A plan of T steps cannot find a way round a wall that first leads away from the goal (issue #36): every goal energy
rises along the detour. SoRB (Eysenbach et al. 2019) plans over states the agent has seen instead, with learned edge
costs. Here the edges come from what an energy over transitions is for: which short moves are possible.

:class:`GraphSubgoals` keeps one node per occupied cell of a grid over visited states (the cell's centre; side 3/4 of
the largest real step of each dim), joins neighbouring cells when the learned energy says the move between their
centres is possible (E(u, v) at most a quantile of the energies of real transitions), and before each plan replaces
the goal with the node ``lookahead`` edges along the shortest path from the state to the goal (the goal itself once
the path is shorter). Where no path exists the goal is kept, so the agent plans as before.

It uses only what the agent learned and saw (states, real step sizes, its energy): no wall map, no env internals;
the builder is handed those (real transitions, goal dims, a lookahead, an energy function, state periods), never the
agent, so any energy over transitions can stand in (an agent takes another provider as ``subgoal_class``).
The edges come from the energy (``edges="energy"``, the EBM agent's ``energy_model``), from the moves the agent made
(``edges="real"``: a real transition between two neighbouring cells is a move that can be made; any agent, Action FF
included, which has no energy) or from both. Any agent whose ``subgoals`` attribute the planning loop reads
(:class:`~ebm_agent.base.PlannerAgentBase`) can use it.

Usage::

    agent.learn_offline(dataset, epochs=10)
    agent.subgoals = GraphSubgoals.from_transitions(
        dataset.states, dataset.next_states, goal_indices=agent.goal_spec.goal_indices, lookahead=agent.horizon,
        energy=agent.energy_model,
    )
    # predict() now plans towards subgoals; agent.subgoals = None restores the plain goal.
    # agent.build_subgoals(states, next_states) does the same with the agent's subgoal_graph settings.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree
from stable_baselines3.common.callbacks import BaseCallback

from ebm_agent.config import check_field_types, make_config
from ebm_agent.costs import TransitionEnergy, wrap_array
from ebm_agent.energy import transition_energies

__all__ = [
    "AIMS",
    "EDGES",
    "UNSTICK",
    "ExploreConfig",
    "FrontierSubgoals",
    "GraphSubgoals",
    "SubgoalGraphConfig",
    "check_long_horizon",
    "long_horizon_configs",
    "subgoal_settings",
]

AIMS: tuple[str, ...] = ("centre", "visited")
"""Where a subgoal at a node sits (``aim=``): the node's cell centre, or a state visited in that cell."""

UNSTICK: tuple[str, ...] = ("next_node", "real_move")
"""What a stalled plan aims at (``unstick=``): the path's next node, or the end of a real move made nearby."""

EDGES: tuple[str, ...] = ("energy", "real", "both")
"""Where a graph's edges come from (``edges=``): the learned energy, the real transitions, or either."""


@dataclass
class SubgoalGraphConfig:
    """How an agent's subgoal graph is built and followed (the agent's ``subgoal_graph``; each field is the keyword of
    :meth:`GraphSubgoals.from_transitions` of the same name, which documents it).

    ``subgoal_graph=None`` (the agent's default, the paper's): no graph; ``{}`` or ``SubgoalGraphConfig()``: a graph
    with these defaults.
    """

    lookahead: int | None = None
    quantile: float = 0.95
    cell: float = 0.75
    clearance: float = 2.0
    max_nodes: int = 5000
    seed: int = 0
    patience: int | None = None
    edges: str = "energy"
    unstick: str = "next_node"
    real_hops: int = 1
    aim: str = "centre"
    stall_penalty: float | None = None
    direct_when_nearer: bool = False

    def __post_init__(self) -> None:
        check_field_types(self)
        check_edges(self.edges)
        for name, choices in (("unstick", UNSTICK), ("aim", AIMS)):
            if getattr(self, name) not in choices:
                raise ValueError(f"subgoal_graph {name} must be one of {choices}, got {getattr(self, name)!r}.")

    def kwargs(self) -> dict[str, Any]:
        """The fields as keywords of :meth:`GraphSubgoals.from_transitions`."""
        return dataclasses.asdict(self)


@dataclass
class ExploreConfig:
    """Frontier exploration while learning (the agent's ``explore``; :class:`FrontierSubgoals`).

    :param every: transitions between rebuilds of the graph over the replay buffer.
    :param goal_heuristic: weight of a frontier's distance to the goal (0: explore without regard to the goal).
    :param revisit_cost: cost of a frontier per plan already made in its cell.
    """

    every: int = 1000
    goal_heuristic: float = 1.0
    revisit_cost: float = 1.0

    def __post_init__(self) -> None:
        if isinstance(self.every, bool) or not isinstance(self.every, int) or self.every < 1:
            raise ValueError(f"explore every must be a positive int (transitions between rebuilds), got {self.every!r}.")
        for name in ("goal_heuristic", "revisit_cost"):
            weight = getattr(self, name)
            if isinstance(weight, bool) or not isinstance(weight, int | float) or not (np.isfinite(weight) and weight >= 0):
                raise ValueError(f"explore {name} must be a finite number >= 0 (a cost weight), got {weight!r}.")


def long_horizon_configs(
    subgoal_graph: SubgoalGraphConfig | dict[str, Any] | None, explore: ExploreConfig | dict[str, Any] | None
) -> tuple[SubgoalGraphConfig | None, ExploreConfig | None]:
    """An agent's ``subgoal_graph`` and ``explore`` arguments as configs (None stays None: off).

    :param subgoal_graph: a :class:`SubgoalGraphConfig`, a dict of its fields, or None.
    :param explore: an :class:`ExploreConfig`, a dict of its fields, or None.
    :return: the configs.
    :raises ValueError: naming unknown keys (and the valid ones) or a bad value.
    """

    def build(cls: type, value: Any, owner: str) -> Any:
        if value is None:
            return None
        try:
            return make_config(cls, value, owner)
        except TypeError as error:  # an unknown key or a value of another type: a bad setting, as for the fields
            raise ValueError(str(error)) from None

    return build(SubgoalGraphConfig, subgoal_graph, "subgoal_graph"), build(ExploreConfig, explore, "explore")


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
    :param energy: ``energy(states [K, D], next_states [K, D]) -> [K]`` numpy energies, or None. A subgoal is the
        farthest path node within ``lookahead`` in sight of the state: the straight segment to it stays in visited
        cells and (with an energy) the energy allows each move of at most one cell along it (under
        ``energy_threshold``), so that plans do not cut corners through walls.
    :param cell: the grid's cell side, in units of ``step``.
    :param patience: with a number, a row of :meth:`subgoals` whose state has not moved a quarter of a real step since
        the previous call that many times in a row (a plan that keeps running into something the graph's segment
        test let through, such as a wall's corner) aims as ``unstick`` says; None (the default): never.
    :param unstick: where a stalled row aims: ``"next_node"`` (the next node of its path) or ``"real_move"``: the state
        plus the move of a real transition that started within half a real step of it, moved at least a quarter of a
        real step (a refused move goes nowhere) and ended in a cell closer to the goal along the graph (the nearest
        such start first, the next nearest at each further stalled call; the
        path's next node where none did). A node's centre one move away can lie across a wall's corner from the
        state, where a move from a nearby visited state did get through: a move the agent made is one it can make
        again.
    :param move_starts: [M, D] the real transitions' states (for ``unstick="real_move"``), or None.
    :param move_ends: [M, D] their next states, or None.
    :param stall_penalty: with a number, each stalled call (see ``patience``) adds it to the cost of the first edge of
        the row's path (its node to the next), and the paths are searched again: a real step that stays put where the
        graph said a move was possible is evidence against that move (e.g. a cell that straddles a wall's corner, which
        visited states on either side make look open). The graph is changed for good (later episodes avoid the move
        too) until it is rebuilt. None (the default): the graph never changes.
    :param direct_when_nearer: plan straight at the goal where the state is nearer it (max over the goal dims, in real
        steps) than the graph's node nearest the goal is. With a goal outside what was visited, that node is the
        graph's best stand-in for the goal; once the agent is past it, following the graph leads back to it (and a
        replan on arrival then turns the agent to and fro). False (the default): the graph is followed wherever the
        agent is.
    :param aims: [V, D] where a subgoal at each node sits (``aim="visited"``: a state visited in the node's cell), or
        None: the nodes themselves (the cell centres). A cell that overlaps a wall can have its centre inside the
        wall; a plan aimed there presses against the wall for its whole length. A state the agent was at is one it
        can be at again.
    :param period: [D] the period of each periodic state dim, 0 for the others (Reacher's normalised angles: 2 for its
        two angle dims, the agent's ``goal_spec.goal_period``), or None: no dim is periodic. A periodic dim's cells
        tile its circle (a whole number of cells of side at most ``cell`` steps), so that states on either side of
        the wrap fall in neighbouring cells, and every gap and move is taken the short way round.
    """

    nodes: np.ndarray
    goal_indices: np.ndarray
    step: np.ndarray
    graph: csr_matrix
    lookahead: int
    energy_threshold: float
    energy: Any = None
    cell: float = 0.75
    patience: int | None = None
    unstick: str = "next_node"
    move_starts: np.ndarray | None = field(default=None, repr=False)
    move_ends: np.ndarray | None = field(default=None, repr=False)
    aims: np.ndarray | None = field(default=None, repr=False)
    stall_penalty: float | None = None
    direct_when_nearer: bool = False
    period: np.ndarray | None = None
    _side: np.ndarray = field(init=False, repr=False)  # [D] the cells' side
    _around: np.ndarray = field(init=False, repr=False)  # [D] cells around each periodic dim, 0 for the others
    _tree: cKDTree = field(init=False, repr=False)
    _move_tree: cKDTree | None = field(default=None, init=False, repr=False)
    _node_of_cell: dict[tuple[int, ...], int] = field(init=False, repr=False)  # the visited cells -> their nodes
    _paths: dict[int, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict, init=False, repr=False)
    _last: dict[int, tuple[np.ndarray, int]] = field(default_factory=dict, init=False, repr=False)  # row -> (state, stalls)

    def __post_init__(self) -> None:
        self._side, self._around = _grid(self.step, self.cell, self.period)
        self._tree = self._step_tree(self.nodes)  # Chebyshev queries in units of one step
        self._node_of_cell = {cell: i for i, cell in enumerate(map(tuple, self._cell_of(self.nodes).tolist()))}
        if self.unstick not in UNSTICK:
            raise ValueError(f"unstick must be one of {UNSTICK}, got {self.unstick!r}.")
        if self.unstick == "real_move":
            if self.move_starts is None or self.move_ends is None or len(self.move_starts) == 0:
                raise ValueError("unstick='real_move' needs the real transitions (move_starts, move_ends).")
            self._move_tree = self._step_tree(self.move_starts)

    @classmethod
    def from_transitions(
        cls,
        states: np.ndarray,
        next_states: np.ndarray,
        *,
        goal_indices: Sequence[int],
        lookahead: int,
        energy: TransitionEnergy | None = None,
        period: np.ndarray | None = None,
        quantile: float = 0.95,
        cell: float = 0.75,
        clearance: float = 2.0,
        max_nodes: int = 5000,
        seed: int = 0,
        patience: int | None = None,
        edges: str = "energy",
        unstick: str = "next_node",
        real_hops: int = 1,
        aim: str = "centre",
        stall_penalty: float | None = None,
        direct_when_nearer: bool = False,
    ) -> GraphSubgoals:
        """Build the graph from real transitions (a dataset, or an online agent's replay buffer).

        :param states: [M, D] real states.
        :param next_states: [M, D] their real next states.
        :param goal_indices: [G] the state dims the goal constrains (a goal spec's ``goal_indices``).
        :param lookahead: edges to the subgoal (an agent passes its planning horizon).
        :param energy: the learned energy E(s [..., D], s' [..., D]) -> [...] (a torch module or callable, e.g. an
            EBM agent's ``energy_model``), read whenever the graph asks whether a move is possible; needed for
            ``edges="energy"`` or ``"both"``, None for a graph of the real moves only.
        :param period: [D] the period of each state dim (0: not periodic), or None where none is
            (:func:`~ebm_agent.moves.state_periods` of a goal spec).
        :param quantile: a move is allowed when its energy is at most this quantile of the real transitions'.
        :param cell: the grid's cell side in units of the largest real step of each dim (below 1, so that a move
            between neighbouring cells' centres is one a single step can make).
        :param clearance: extra cost of entering a node with few allowed moves out (1 - its out-degree / the
            largest), which keeps paths and subgoals off walls; 0: every move costs the same.
        :param max_nodes: cap on the nodes (a random subset of the occupied cells beyond it).
        :param seed: seed of that subset and of the transitions the threshold is read from.
        :param patience: calls without moving after which a subgoal is the path's next node (see the class); None:
            never.
        :param edges: ``"energy"``: neighbouring cells are joined where the energy allows the move between their
            centres; ``"real"``: where a real transition went from one to the other (no energy needed; the graph then
            knows only the moves made); ``"both"``: either.
        :param unstick: where a stalled plan aims (see the class): ``"next_node"`` or ``"real_move"`` (the graph then
            keeps the transitions).
        :param real_hops: the real-move edges join cells at most this many cells apart (per dim): 1, neighbouring
            cells only; 2 also keeps the moves that crossed a cell (a real step is up to 1/``cell`` cells long, so
            about a third of full steps at the default ``cell``), which a graph without energy edges needs to hold
            together. An edge costs the cells it spans.
        :param aim: where a subgoal at a node sits: ``"centre"``, its cell's centre (the node itself), or
            ``"visited"``, the real state in its cell nearest the mean of the real states there. The edges and paths
            are the same either way (between cell centres).
        :param stall_penalty: cost added to a path's first edge each time a plan stalls on it (see the class; needs
            ``patience``); None: never.
        :param direct_when_nearer: plan straight at a goal the state is nearer than the graph's nearest node is (see
            the class).
        :return: the graph.
        :raises ValueError: for empty or mismatched transitions, a quantile outside (0, 1], an unknown ``edges``, or
            edges from the energy without an ``energy``.
        """
        states, next_states = np.asarray(states, np.float32), np.asarray(next_states, np.float32)  # [M, D] each
        if states.ndim != 2 or states.shape != next_states.shape or len(states) == 0:
            raise ValueError(
                f"states and next_states must be non-empty [M, D] arrays, got {states.shape} and {next_states.shape}."
            )
        _check_graph_settings(quantile, cell, edges, energy, aim, real_hops)
        rng = np.random.default_rng(seed)
        if period is not None:
            period = np.asarray(period, dtype=np.float32)  # [D]
            if period.shape != (states.shape[1],):
                raise ValueError(f"period must be a [D] = [{states.shape[1]}] array of periods, got shape {period.shape}.")
            period = period if np.any(period > 0) else None
        step = np.maximum(np.abs(wrap_array(next_states - states, period)).max(axis=0), 1e-6)  # [D]
        side, around = _grid(step, cell, period)  # [D] each
        cells = _cells(states, side, around)  # [M, D]
        occupied, inverse = np.unique(cells, axis=0, return_inverse=True)  # [V, D]
        centres = ((occupied + 0.5) * side).astype(np.float32)  # [V, D] cell centres: neighbours are one move apart
        if period is not None:  # periodic dims' centres in [-period / 2, period / 2), as the env's angles
            centres = wrap_array(centres, period)
        if aim == "visited":
            aims = _visited_in_cells(states, inverse.reshape(-1), len(occupied), centres, period)  # [V, D]
        else:
            aims = None
        if len(occupied) > max_nodes:
            subset = np.sort(rng.choice(len(occupied), max_nodes, replace=False))
            occupied, centres = occupied[subset], centres[subset]
            aims = None if aims is None else aims[subset]
        nodes = centres  # [V, D]
        boxsize = around if period is not None else None  # periodic dims: their cells wrap round
        pairs = cKDTree(occupied, boxsize=boxsize).query_pairs(1.0, p=np.inf, output_type="ndarray")  # [P, 2]
        pairs = np.concatenate([pairs, pairs[:, ::-1]])  # both directions: feasibility is directional
        energy_of, threshold = None, float("inf")
        allowed = np.zeros((0, 2), dtype=np.int64)  # [E, 2]
        if edges in ("energy", "both"):
            energy_of = functools.partial(transition_energies, energy)
            sample = rng.choice(len(states), min(len(states), 20_000), replace=False)
            threshold = float(np.quantile(energy_of(states[sample], next_states[sample]), quantile))
            allowed = pairs[energy_of(nodes[pairs[:, 0]], nodes[pairs[:, 1]]) <= threshold]
        if edges in ("real", "both"):
            real = _real_moves(occupied, states, next_states, side, real_hops, around)
            allowed = np.unique(np.concatenate([allowed, real]), axis=0)
        # An edge costs one move, plus ``clearance`` for entering a node that few allowed moves leave (one beside a
        # wall, or at the edge of what was visited): paths keep to the open, where the plans' moves are reliable.
        degree = np.bincount(allowed[:, 0], minlength=len(nodes))  # [V]
        span = _cell_gaps(occupied[allowed[:, 0]] - occupied[allowed[:, 1]], around).max(axis=1, initial=1)  # [E]
        cost = span + clearance * (1.0 - degree[allowed[:, 1]] / max(int(degree.max(initial=0)), 1))  # [E]
        graph = csr_matrix((cost, (allowed[:, 0], allowed[:, 1])), shape=(len(nodes), len(nodes)))
        if isinstance(lookahead, bool) or not isinstance(lookahead, (int, np.integer)) or lookahead < 1:
            raise ValueError(f"lookahead must be a positive int (edges to the subgoal), got {lookahead!r}.")
        if patience is not None and (isinstance(patience, bool) or not isinstance(patience, int) or patience < 1):
            raise ValueError(f"patience must be None or a positive int, got {patience!r}.")
        if stall_penalty is not None and (patience is None or not stall_penalty > 0):
            raise ValueError(
                f"stall_penalty must be None or > 0 and needs patience (when a plan has stalled), got {stall_penalty!r} "
                f"with patience {patience!r}."
            )
        moves = (states, next_states) if unstick == "real_move" else (None, None)
        return cls(
            nodes,
            np.asarray(goal_indices),
            step,
            graph,
            int(lookahead),
            threshold,
            energy_of,
            cell,
            patience,
            unstick,
            move_starts=moves[0],
            move_ends=moves[1],
            aims=aims,
            stall_penalty=stall_penalty,
            direct_when_nearer=bool(direct_when_nearer),
            period=period,
        )

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
            if self.direct_when_nearer and self._nearer_than(state, goal, target):
                continue  # past the graph's best stand-in for the goal: plan straight at it
            path = self._path_ahead(state, target)
            if path is None:
                continue  # no path from here: plan towards the goal as before
            stalled = self._stalled(i, state)
            if stalled and len(path) > 1 and self.stall_penalty is not None:
                self.graph[path[0], path[1]] += self.stall_penalty  # an existing edge: the sparsity stays the same
                self._paths.clear()
                path = self._path_ahead(state, target)
                if path is None:
                    continue
            node = path[0]
            distance, _ = self._paths_to(target)
            chosen = self._in_sight(state, path)
            if stalled and len(path) > 1:
                move = self._real_move(i, state, node, distance) if self.unstick == "real_move" else None
                if move is not None:
                    out[i] = move[self.goal_indices]  # stuck: where a real move from nearby went, along the path
                    continue
                chosen = path[1]  # stuck: the next node, one move away, instead of the farthest in sight
            if chosen != target:
                out[i] = self._aim(chosen)[self.goal_indices]
        return out

    def _nearer_than(self, state: np.ndarray, goal: np.ndarray, node: int) -> bool:
        """Whether ``state`` is nearer ``goal`` than ``node`` is (max over the goal dims, in real steps)."""
        here, there = self._goal_gaps(state[None], goal)[0], self._goal_gaps(self.nodes[node][None], goal)[0]  # [G]
        return bool(here.max() < there.max())

    def _goal_gaps(self, points: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """[K, D] points -> [K, G] their distance to ``goal`` [G] in each goal dim, in real steps (the short way round
        a periodic dim)."""
        dims = self.goal_indices
        period = None if self.period is None else self.period[dims]
        return np.abs(wrap_array(points[:, dims] - goal, period)) / self.step[dims]

    def _step_tree(self, points: np.ndarray) -> cKDTree:
        """A k-d tree over [K, D] points in units of one real step, periodic dims on their circle."""
        if self.period is None:
            return cKDTree(points / self.step)
        return cKDTree(self._in_box(points), boxsize=np.where(self.period > 0, self.period / self.step, 0.0))

    def _in_box(self, points: np.ndarray) -> np.ndarray:
        """[K, D] points in units of one real step, as :meth:`_step_tree` holds them (periodic dims in [0, period))."""
        scaled = points / self.step  # [K, D]
        if self.period is None:
            return scaled
        box = self.period / self.step  # [D]
        periodic = self.period > 0
        scaled[..., periodic] = np.mod(scaled[..., periodic], box[periodic])
        scaled[..., periodic] = np.where(scaled[..., periodic] >= box[periodic], 0.0, scaled[..., periodic])  # float edge
        return scaled

    def _nearest_nodes(self, state: np.ndarray, k: int) -> np.ndarray:
        """The ``k`` nodes nearest ``state`` [D] (Chebyshev, in real steps), nearest first."""
        _, near = self._tree.query(self._in_box(state[None])[0], k=min(k, len(self.nodes)), p=np.inf)
        return np.atleast_1d(near)

    def _aim(self, node: int) -> np.ndarray:
        """Where a subgoal at ``node`` sits ([D]): its visited state with ``aims``, else the node (its cell's centre)."""
        return self.nodes[node] if self.aims is None else self.aims[node]

    def _path_ahead(self, state: np.ndarray, target: int) -> list[int] | None:
        """The first ``lookahead`` edges of the shortest path from the state's node to ``target`` (nodes), or None
        where no node near the state has a path."""
        distance, toward = self._paths_to(target)
        node = self._start_node(state, distance)
        if node is None:
            return None
        path = [node]
        while len(path) <= self.lookahead and path[-1] != target:
            path.append(int(toward[path[-1]]))
        return path

    def _stalled(self, row: int, state: np.ndarray) -> bool:
        """Whether row ``row``'s state stayed put (within a quarter step) for ``patience`` calls in a row."""
        if self.patience is None:
            return False
        last = self._last.get(row)
        stalls = 0
        if last is not None and np.all(np.abs(wrap_array(state - last[0], self.period)) < 0.25 * self.step):
            stalls = last[1] + 1
        self._last[row] = (state.copy(), stalls)
        return stalls >= self.patience

    def _real_move(self, row: int, state: np.ndarray, node: int, distance: np.ndarray) -> np.ndarray | None:
        """A real move from within half a step of ``state`` that ended closer to the target along the graph than
        ``node``, made again from ``state`` (its displacement added to the state, [D]): the one that started nearest
        at the first stalled call, the next nearest at the next (a move across a wall's corner from a state on its
        other side fails from here). None where no such move was made."""
        assert self._move_tree is not None and self.move_starts is not None and self.move_ends is not None
        here = self._in_box(state[None])[0]
        near = np.asarray(self._move_tree.query_ball_point(here, r=0.5, p=np.inf), dtype=np.int64)  # [K]
        if len(near) == 0:
            return None
        cells = map(tuple, self._cell_of(self.move_ends[near]).tolist())
        cost = np.array([distance[self._node_of_cell[c]] if c in self._node_of_cell else np.inf for c in cells])  # [K]
        displacement = wrap_array(self.move_ends[near] - self.move_starts[near], self.period)  # [K, D]
        moved = (np.abs(displacement) / self.step).max(axis=1) >= 0.25  # [K]
        better = (cost < distance[node]) & moved  # [K] moves that went somewhere and got closer
        if not better.any():
            return None
        gaps = np.abs(wrap_array(self.move_starts[near[better]] - state, self.period)) / self.step  # [B, D]
        order = np.flatnonzero(better)[np.argsort(gaps.max(axis=1), kind="stable")]  # nearest start first
        tries = self._last[row][1] - (self.patience or 0)  # stalled calls so far beyond the patience
        return state + displacement[order[tries % len(order)]]

    def _in_sight(self, state: np.ndarray, path: list[int]) -> int:
        """The farthest node of ``path`` (the first one at least) whose straight approach from ``state`` stays in
        visited cells and, with an energy, the energy allows."""
        for node in reversed(path[1:]):
            segment = wrap_array(self._aim(node) - state, self.period)  # [D] the short way round a periodic dim
            moves = max(int(np.ceil(np.abs(segment / self._side).max())), 1)
            points = state + np.linspace(0.0, 1.0, 2 * moves + 1)[:, None] * segment  # [2 moves + 1, D]
            if not all(cell in self._node_of_cell for cell in map(tuple, self._cell_of(points[1:]).tolist())):
                continue  # the segment leaves the visited cells (into a wall, or where nothing was seen)
            if self.energy is None:
                return node
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
        """[K, D] points -> [K, D] the integer indices of their grid cells (periodic dims modulo their cells)."""
        return _cells(points, self._side, self._around)

    def _goal_node(self, goal: np.ndarray) -> int:
        """The node nearest the goal in the goal dims."""
        return int(np.argmin(self._goal_gaps(self.nodes, goal).max(axis=1)))

    def _paths_to(self, target: int) -> tuple[np.ndarray, np.ndarray]:
        """The path cost from every node to ``target`` and each node's next node on its path (cached per target)."""
        if target not in self._paths:
            distance, predecessors = dijkstra(self.graph.T.tocsr(), indices=target, return_predecessors=True)
            self._paths[target] = (distance, predecessors)  # in the reversed graph, a predecessor is the next hop
        return self._paths[target]

    def _start_node(self, state: np.ndarray, distance: np.ndarray, candidates: int = 8) -> int | None:
        """The node nearest the state that has a path to the target (among the ``candidates`` nearest)."""
        for node in self._nearest_nodes(state, candidates):
            if np.isfinite(distance[int(node)]):
                return int(node)
        return None


@dataclass
class FrontierSubgoals:
    """Exploration while learning online: towards the goal along the graph where the goal was seen, else towards the
    frontier of what was visited, chosen optimistically and away from frontiers already tried.

    A frontier is a visited cell of the graph (:class:`GraphSubgoals`) with an unvisited neighbour cell along one
    state dim. From the current node, each frontier F with unvisited neighbour U costs

        path cost to F (the graph's edges)  +  ``goal_heuristic`` x (distance from U to the goal, in real moves)
                                            +  ``revisit_cost`` x (plans already made in F's cell)

    and the cheapest is chosen: with the heuristic, the frontier whose unexplored side looks closest to the goal, as
    A* expands nodes (greedily: the Euclidean distance in moves can overestimate the diagonal moves left), so that a
    detour is tried once the direct way is found closed; with ``goal_heuristic=0``, the nearest frontier (goal-free
    coverage). Each plan made in a cell counts against it, and so does each plan that pushes past a frontier
    (wherever the agent is: it may be beyond F, in cells the graph does not hold yet), so that a frontier whose
    unvisited side is a wall, or out of the env's bounds, is given up after a few plans that do not get through. The
    subgoal is the farthest node in sight along the graph's path to F, and once F is within the plan's lookahead and
    in sight, a point past F towards U, as many real moves away as the plan has left. Where a node lies within one
    cell of the goal, the plans aim along the graph's shortest path to the goal (:meth:`GraphSubgoals.subgoals`)
    instead (unless ``goal_heuristic`` is 0: goal-free exploration never turns to the goal).

    It uses only the visited states, the energy (through the graph's edges) and the goal; never the env's layout.

    :param graph: the graph over the visited states.
    :param goal_heuristic: weight of the distance, in real moves, from a frontier's unvisited side to the goal (0:
        goal-free exploration).
    :param revisit_cost: cost of a frontier per plan already made in its cell.
    :param plan_counts: plans made per cell (cell index tuple -> count), kept across rebuilds of the graph.
    :param depth: a frontier's side counts as unvisited when this many cells that way are (1: any unvisited
        neighbour; more leaves out the small holes inside what was visited, which are not worth a trip).
    """

    graph: GraphSubgoals
    goal_heuristic: float = 1.0
    revisit_cost: float = 1.0
    plan_counts: dict[tuple[int, ...], int] = field(default_factory=dict)
    depth: int = 3
    _frontier_nodes: np.ndarray = field(init=False, repr=False)  # [F] node index of each frontier
    _frontier_points: np.ndarray = field(init=False, repr=False)  # [F, D] centre of its unvisited neighbour cell
    _frontier_push: np.ndarray = field(init=False, repr=False)  # [F, D] one real move from the node towards it
    _frontier_cells: list[tuple[int, ...]] = field(init=False, repr=False)  # [F] the node's cell

    def __post_init__(self) -> None:
        graph = self.graph
        node_cells = graph._cell_of(graph.nodes)  # [V, D]
        side, around = graph._side, graph._around  # [D] each
        periodic = around > 0  # [D]
        nodes, points, pushes, cells = [], [], [], []
        for index, cell in enumerate(node_cells):
            for dim in range(len(cell)):
                for sign in (-1, 1):
                    beyond = cell[None].repeat(self.depth, axis=0)  # [depth, D] the next cells that way
                    beyond[:, dim] += sign * np.arange(1, self.depth + 1)
                    if periodic[dim]:
                        beyond[:, dim] %= around[dim]
                    if not any(tuple(other) in graph._node_of_cell for other in beyond.tolist()):
                        neighbour = beyond[0]
                        nodes.append(index)
                        points.append((neighbour + 0.5) * side)
                        push = np.zeros(len(cell))
                        push[dim] = sign * graph.step[dim]
                        pushes.append(push)
                        cells.append(tuple(cell.tolist()))
        dim = graph.nodes.shape[1]
        self._frontier_nodes = np.asarray(nodes, dtype=np.int64)
        self._frontier_points = wrap_array(np.asarray(points, dtype=np.float32).reshape(-1, dim), graph.period)
        self._frontier_push = np.asarray(pushes, dtype=np.float32).reshape(-1, dim)
        self._frontier_cells = cells

    @property
    def num_frontiers(self) -> int:
        """(visited cell, unvisited neighbour) pairs of the graph."""
        return len(self._frontier_nodes)

    def subgoals(self, states: np.ndarray, goals: np.ndarray) -> np.ndarray:
        """The goal each plan should aim at while exploring; counts a plan in each state's cell.

        :param states: [N, D] current states.
        :param goals: [N, G] the goals.
        :return: [N, G] subgoals (the goals themselves where the graph has no node near the state).
        """
        graph = self.graph
        out = np.array(goals, dtype=np.float32, copy=True)  # [N, G]
        known = graph.subgoals(states, goals)  # [N, G] along the graph to the goal, where a path exists
        for i, (state, goal) in enumerate(zip(np.asarray(states, np.float32), out)):
            cell = tuple(graph._cell_of(state[None])[0].tolist())
            self.plan_counts[cell] = self.plan_counts.get(cell, 0) + 1
            if self.goal_heuristic > 0 and self._goal_seen(goal):
                distance, _ = graph._paths_to(graph._goal_node(goal))
                if graph._start_node(state, distance) is not None:  # a known way to the goal: take it
                    out[i] = known[i]
                    continue
            chosen = self._frontier_subgoal(state, goal)
            if chosen is not None:
                out[i] = chosen
        return out

    def _goal_seen(self, goal: np.ndarray) -> bool:
        """Whether a node lies within one cell of the goal (in the goal dims)."""
        graph = self.graph
        dims = graph.goal_indices
        period = None if graph.period is None else graph.period[dims]
        gaps = np.abs(wrap_array(graph.nodes[:, dims] - goal, period)) / graph._side[dims]  # [V, G] in cells
        return bool((gaps.max(axis=1) <= 1.0).any())

    def _frontier_subgoal(self, state: np.ndarray, goal: np.ndarray) -> np.ndarray | None:
        """The subgoal towards the cheapest frontier from ``state`` ([G]), or None without a reachable one."""
        graph = self.graph
        if self.num_frontiers == 0:
            return None
        start = int(graph._nearest_nodes(state, 1)[0])
        distance, predecessors = dijkstra(graph.graph, indices=start, return_predecessors=True)  # [V] each
        dims = graph.goal_indices
        moves_left = np.linalg.norm(graph._goal_gaps(self._frontier_points, goal), axis=1)  # [F]
        tried = np.array([self.plan_counts.get(cell, 0) for cell in self._frontier_cells], dtype=np.float64)  # [F]
        cost = distance[self._frontier_nodes] + self.goal_heuristic * moves_left + self.revisit_cost * tried
        best = int(np.argmin(cost))
        if not np.isfinite(cost[best]):
            return None
        target = int(self._frontier_nodes[best])
        path = [target]
        while path[-1] != start:
            path.append(int(predecessors[path[-1]]))
        path = path[::-1][: graph.lookahead + 1]  # [start, ..., at most lookahead edges along]
        chosen = graph._in_sight(state, path) if len(path) > 1 else path[-1]
        if chosen != target:
            return graph._aim(chosen)[dims]
        # The frontier is in sight: push past it into the unvisited cell for the rest of the plan's moves, so that
        # a plan explores a whole horizon's worth (a wall there stops the agent, and the plans made count against F).
        moves = max(graph.lookahead - (len(path) - 1), 1)
        cell = self._frontier_cells[best]  # the push counts against F wherever the agent is (it may be past F)
        self.plan_counts[cell] = self.plan_counts.get(cell, 0) + 1
        return (graph.nodes[target] + moves * self._frontier_push[best])[dims]


def _check_graph_settings(quantile: Any, cell: Any, edges: Any, energy: Any, aim: Any, real_hops: Any) -> None:
    """Refuse a bad setting of :meth:`GraphSubgoals.from_transitions`, naming it and what it must be."""
    if not 0.0 < quantile <= 1.0:
        raise ValueError(f"quantile must be in (0, 1], got {quantile!r}.")
    if not 0.0 < cell <= 1.0:
        raise ValueError(f"cell must be in (0, 1] (a fraction of one real step), got {cell!r}.")
    check_edges(edges, energy is not None, "the builder (energy=None)")
    if aim not in AIMS:
        raise ValueError(f"aim must be one of {AIMS}, got {aim!r}.")
    if isinstance(real_hops, bool) or not isinstance(real_hops, int) or real_hops < 1:
        raise ValueError(f"real_hops must be a positive int (cells a real-move edge may span), got {real_hops!r}.")


def _grid(step: np.ndarray, cell: float, period: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The cells' side [D] (``cell`` real steps; on a periodic dim the largest side at most that which divides the
    period) and the number of cells around each periodic dim ([D], 0 for the others)."""
    side = cell * step  # [D]
    around = np.zeros(len(step), dtype=np.int64)  # [D]
    if period is not None:
        periodic = period > 0
        around[periodic] = np.ceil(period[periodic] / side[periodic]).astype(np.int64)
        side = side.copy()
        side[periodic] = (period[periodic] / around[periodic]).astype(side.dtype)
    return side, around


def _cells(points: np.ndarray, side: np.ndarray, around: np.ndarray) -> np.ndarray:
    """[K, D] points -> [K, D] integer cell indices (periodic dims, ``around`` > 0, modulo their cells)."""
    cells = np.floor(points / side).astype(np.int64)  # [K, D]
    periodic = around > 0
    if periodic.any():
        cells[..., periodic] = np.mod(cells[..., periodic], around[periodic])
    return cells


def _cell_gaps(difference: np.ndarray, around: np.ndarray) -> np.ndarray:
    """[..., D] differences of cell indices -> their size in cells (the short way round a periodic dim)."""
    gaps = np.abs(difference)
    periodic = around > 0
    if periodic.any():
        gaps[..., periodic] = np.minimum(gaps[..., periodic], around[periodic] - gaps[..., periodic])
    return gaps


def _visited_in_cells(
    states: np.ndarray,
    cell_of_state: np.ndarray,
    num_cells: int,
    centres: np.ndarray | None = None,
    period: np.ndarray | None = None,
) -> np.ndarray:
    """For each cell, the state in it nearest (max over dims) the mean of the states in it.

    :param states: [M, D] states.
    :param cell_of_state: [M] the index of each state's cell (every cell holds at least one state).
    :param num_cells: V, the number of cells.
    :param centres: [V, D] the cells' centres (needed with ``period``).
    :param period: [D] periods (0: not periodic) or None: a cell on a periodic dim can hold states from either side
        of the wrap, so their mean is taken as offsets from the cell's centre, the short way round.
    :return: [V, D] one visited state per cell.
    """
    counts = np.bincount(cell_of_state, minlength=num_cells)  # [V]
    sums = np.zeros((num_cells, states.shape[1]), dtype=np.float64)  # [V, D]
    if period is None:
        np.add.at(sums, cell_of_state, states)
        means = sums / counts[:, None]  # [V, D]
        gap = np.abs(states - means[cell_of_state]).max(axis=1)  # [M]
    else:
        assert centres is not None, "periodic dims need the cells' centres"
        np.add.at(sums, cell_of_state, wrap_array(states - centres[cell_of_state], period))
        offsets = sums / counts[:, None]  # [V, D] the mean offset from each centre
        gap = np.abs(wrap_array(states - centres[cell_of_state] - offsets[cell_of_state], period)).max(axis=1)  # [M]
    order = np.lexsort((gap, cell_of_state))  # by cell, nearest the mean first
    first = order[np.concatenate([[0], np.flatnonzero(np.diff(cell_of_state[order])) + 1])]  # [V]
    return states[first].astype(np.float32)


def _real_moves(
    occupied: np.ndarray,
    states: np.ndarray,
    next_states: np.ndarray,
    side: np.ndarray,
    hops: int = 1,
    around: np.ndarray | None = None,
) -> np.ndarray:
    """The moves between nodes at most ``hops`` cells apart that real transitions made.

    :param occupied: [V, D] the nodes' integer cell indices.
    :param states: [M, D] real states.
    :param next_states: [M, D] their real next states.
    :param side: [D] the cells' side.
    :param hops: the most cells (per dim) between the two ends' cells.
    :param around: [D] cells around each periodic dim (0 for the others), or None: none periodic.
    :return: [E, 2] (from, to) node indices of the distinct moves from a cell to another at most ``hops`` away (a
        transition that stayed in its cell, jumped further, or left the nodes, e.g. those a ``max_nodes`` cap dropped,
        gives none).
    """
    index = {cell: i for i, cell in enumerate(map(tuple, occupied.tolist()))}
    around = np.zeros(occupied.shape[1], dtype=np.int64) if around is None else around
    start = _cells(states, side, around)  # [M, D]
    end = _cells(next_states, side, around)  # [M, D]
    span = _cell_gaps(end - start, around).max(axis=1)  # [M]
    hop = (span >= 1) & (span <= hops)  # [M] to another cell, near enough
    moves = np.unique(np.concatenate([start[hop], end[hop]], axis=1), axis=0)  # [K, 2 D] distinct cell pairs
    dim = occupied.shape[1]
    found = [
        (index[a], index[b])
        for a, b in ((tuple(row[:dim]), tuple(row[dim:])) for row in moves.tolist())
        if a in index and b in index
    ]
    return np.asarray(found, dtype=np.int64).reshape(-1, 2)


def check_edges(edges: Any, has_energy: bool = True, owner: str = "the agent") -> None:
    """Refuse an unknown ``edges``, or edges from the energy where there is no energy.

    :param edges: the ``edges`` argument of :meth:`GraphSubgoals.from_transitions`.
    :param has_energy: whether the graph's owner has a learned energy (Action FF has none).
    :param owner: the owner's name, for the message.
    :raises ValueError: naming the problem and the fix.
    """
    if edges not in EDGES:
        raise ValueError(f"edges must be one of {EDGES}, got {edges!r}.")
    if edges != "real" and not has_energy:
        raise ValueError(
            f"edges={edges!r} needs a learned energy, and {owner} has none; use edges='real' (a graph of the moves the "
            "agent made)."
        )


def subgoal_settings(
    subgoal_class: type | None, subgoal_graph: SubgoalGraphConfig | dict[str, Any] | None
) -> SubgoalGraphConfig | dict[str, Any] | None:
    """The keywords an agent builds its subgoals with: a :class:`SubgoalGraphConfig` for :class:`GraphSubgoals` (and
    its subclasses), a plain dict for any other ``subgoal_class``; None: no subgoals.

    :param subgoal_class: the agent's ``subgoal_class`` (None: :class:`GraphSubgoals`).
    :param subgoal_graph: the agent's ``subgoal_graph`` (its keywords), or None; a ``subgoal_class`` given without
        keywords builds with ``{}``.
    :return: the settings.
    :raises TypeError: a ``subgoal_class`` without ``from_transitions``, or a config given to a class that is not a
        :class:`GraphSubgoals`.
    :raises ValueError: naming unknown keys or a bad value of a :class:`SubgoalGraphConfig`.
    """
    if subgoal_class is None or (isinstance(subgoal_class, type) and issubclass(subgoal_class, GraphSubgoals)):
        if subgoal_graph is None and subgoal_class is not None:
            subgoal_graph = {}
        return long_horizon_configs(subgoal_graph, None)[0]
    if not isinstance(subgoal_class, type) or not callable(getattr(subgoal_class, "from_transitions", None)):
        raise TypeError(
            f"subgoal_class must be a class with a from_transitions(states, next_states, *, goal_indices, lookahead, "
            f"energy, period, **subgoal_graph) builder (as GraphSubgoals), got {subgoal_class!r}."
        )
    if isinstance(subgoal_graph, SubgoalGraphConfig):
        raise TypeError(
            f"subgoal_graph is a SubgoalGraphConfig, the keywords of GraphSubgoals, but subgoal_class is "
            f"{subgoal_class.__name__}; pass its keywords as a dict."
        )
    if subgoal_graph is not None and not isinstance(subgoal_graph, dict):
        raise TypeError(f"subgoal_graph must be a dict of {subgoal_class.__name__}'s keywords, got {subgoal_graph!r}.")
    return dict(subgoal_graph or {})


def check_long_horizon(
    subgoal_graph: SubgoalGraphConfig | dict[str, Any] | None,
    explore: ExploreConfig | None,
    subgoal_class: type | None,
    has_energy: bool,
    owner: str,
) -> None:
    """Refuse a graph whose edges need an energy for an agent that has none, and exploration without a graph.

    :param subgoal_graph: the agent's subgoal settings (:func:`subgoal_settings`), or None.
    :param explore: the agent's exploration config, or None (exploring builds a graph with the default config).
    :param subgoal_class: the agent's ``subgoal_class`` (None: :class:`GraphSubgoals`).
    :param has_energy: whether the agent has a learned energy.
    :param owner: the agent's class name, for messages.
    :raises ValueError: naming the problem and the fix.
    """
    graph_class = subgoal_class is None or issubclass(subgoal_class, GraphSubgoals)
    if explore is not None and not graph_class:
        raise ValueError(
            f"explore needs a GraphSubgoals graph (its frontier is read from the graph's cells), but subgoal_class is "
            f"{subgoal_class.__name__}; leave subgoal_class None or pass a subclass of GraphSubgoals."  # type: ignore[union-attr]
        )
    if graph_class and (subgoal_graph is not None or explore is not None):
        edges = subgoal_graph.edges if isinstance(subgoal_graph, SubgoalGraphConfig) else SubgoalGraphConfig().edges
        check_edges(edges, has_energy, owner)


class FrontierRebuild(BaseCallback):
    """Rebuild an exploring agent's frontier (:meth:`~ebm_agent.base.PlannerAgentBase.build_frontier`) every
    ``every`` transitions of ``learn``."""

    def __init__(self, every: int) -> None:
        super().__init__()
        self.every = every
        self._next = 0

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next:
            if self.model.build_frontier() is not None:  # type: ignore[attr-defined]
                self._next = self.num_timesteps + self.every
        return True
