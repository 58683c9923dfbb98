"""Graph subgoals (ebm_agent.subgoals): paths over visited states that the energy allows, and subgoals along them."""

from __future__ import annotations

import inspect
from types import SimpleNamespace
from typing import ClassVar

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3.common.callbacks import BaseCallback

import envs  # noqa: F401  (registers the ids)
from baselines.action_ff import ActionFFAgent
from ebm_agent import EBMPlannerAgent
from ebm_agent.moves import state_periods
from ebm_agent.subgoals import ExploreConfig, FrontierSubgoals, GraphSubgoals, SubgoalGraphConfig


def _build(layout: SimpleNamespace, states: np.ndarray, following: np.ndarray, **kwargs) -> GraphSubgoals:
    """The graph an agent with ``layout``'s goal dims, horizon and energy (if any) builds: the keywords it hands the
    builder (never the agent itself)."""
    kwargs.setdefault("lookahead", layout.horizon)
    return GraphSubgoals.from_transitions(
        states,
        following,
        goal_indices=layout.goal_spec.goal_indices,
        energy=getattr(layout, "energy_model", None),
        period=state_periods(layout.goal_spec, states.shape[1]),
        **kwargs,
    )


class WallEnergy(torch.nn.Module):
    """A stand-in energy for the graph's logic: 0 for a move, 10 for one that crosses the wall x = 0 below y = 0.5."""

    def forward(self, states: torch.Tensor, next_states: torch.Tensor) -> torch.Tensor:
        crosses = (torch.sign(states[..., 0]) != torch.sign(next_states[..., 0])) & (
            torch.maximum(states[..., 1], next_states[..., 1]) < 0.5
        )
        return 10.0 * crosses.float()  # [...]


def _walk(seed: int = 0, steps: int = 20_000) -> tuple[np.ndarray, np.ndarray]:
    """Random moves of at most 0.05 per axis in [-1, 1]^2 that never cross the wall: (states, next states)."""
    rng = np.random.default_rng(seed)
    states = rng.uniform(-1, 1, size=(steps, 2)).astype(np.float32)
    states[np.abs(states[:, 0]) < 0.03, 0] += 0.06  # keep off the wall line
    moves = rng.uniform(-0.05, 0.05, size=states.shape).astype(np.float32)
    following = np.clip(states + moves, -1, 1)
    blocked = (np.sign(states[:, 0]) != np.sign(following[:, 0])) & (np.maximum(states[:, 1], following[:, 1]) < 0.5)
    following[blocked] = states[blocked]
    return states, following


def _graph(**kwargs) -> GraphSubgoals:
    agent = SimpleNamespace(
        energy_model=WallEnergy(), device="cpu", horizon=10, goal_spec=SimpleNamespace(goal_indices=[0, 1])
    )
    states, following = _walk()
    return _build(agent, states, following, **kwargs)


def test_paths_go_round_the_wall_the_energy_knows():
    graph = _graph()
    path = graph.path(np.array([-0.8, -0.8], np.float32), np.array([0.8, -0.8], np.float32))
    assert len(path) > 0 and path[:, 1].max() > 0.5  # up and over: the wall ends at y = 0.5
    crossings = np.sign(path[:-1, 0]) != np.sign(path[1:, 0])
    assert np.all(np.maximum(path[:-1, 1], path[1:, 1])[crossings] >= 0.5)  # never through it
    steps = np.abs(np.diff(path, axis=0)).max(axis=1)
    assert steps.max() <= 0.05 + 1e-6  # each edge is one move


def test_a_subgoal_lies_lookahead_moves_along_the_path_and_the_goal_itself_once_near():
    graph = _graph(lookahead=5)
    start, goal = np.array([[-0.8, -0.8]], np.float32), np.array([[0.8, -0.8]], np.float32)
    subgoal = graph.subgoals(start, goal)[0]
    path = graph.path(start[0], goal[0])
    assert np.allclose(subgoal, path[5])
    near = np.array([[0.78, -0.78]], np.float32)
    assert np.allclose(graph.subgoals(near, goal), goal)


def test_without_a_path_the_goal_is_kept():
    agent = SimpleNamespace(
        energy_model=WallEnergy(), device="cpu", horizon=10, goal_spec=SimpleNamespace(goal_indices=[0, 1])
    )
    states, following = _walk()
    left = states[:, 0] < 0  # visited only the left half: the right half is not in the graph
    graph = _build(agent, states[left & (states[:, 1] < 0.4)], following[left & (states[:, 1] < 0.4)])
    goal = np.array([[0.8, -0.8]], np.float32)
    # The goal's nearest node is on the left; a start beyond the graph's reach still gets a path or the goal.
    out = graph.subgoals(np.array([[-0.5, -0.5]], np.float32), goal)
    assert out.shape == (1, 2) and np.all(np.isfinite(out))
    with pytest.raises(ValueError, match="non-empty"):
        _build(agent, states[:0], following[:0])
    with pytest.raises(ValueError, match="quantile"):
        _build(agent, states, following, quantile=0.0)


def test_the_agent_plans_towards_the_subgoals_and_does_not_save_them(tmp_path, monkeypatch):
    agent = EBMPlannerAgent(
        "MultiInputPolicy", gym.make("ebm/Maze-v0"), seed=0, planner_config={"num_samples": 8, "iterations": 2}
    )
    states, following = _walk(steps=4000)
    agent.subgoals = _build(agent, states, following)
    seen = []
    original = agent._plan

    def spy(states, goals, *args, **kwargs):
        seen.append(np.array(goals))
        return original(states, goals, *args, **kwargs)

    monkeypatch.setattr(agent, "_plan", spy)
    obs, _ = gym.make("ebm/Maze-v0").reset(seed=0)
    agent.predict(obs, deterministic=True)
    expected = agent.subgoals.subgoals(obs["observation"][None], obs["desired_goal"][None])
    assert np.allclose(seen[0], expected) and not np.allclose(seen[0], obs["desired_goal"][None])
    monkeypatch.undo()  # the spy is an instance attribute: not something to save
    agent.save(tmp_path / "model.zip")
    assert EBMPlannerAgent.load(tmp_path / "model.zip", env=gym.make("ebm/Maze-v0")).subgoals is None


def test_the_subgoal_graph_option_builds_the_graph_after_pretraining_and_rejects_unknown_keys():
    from ebm_agent import collect_random_transitions

    env = gym.make("ebm/Maze-v0", start=None)
    agent = EBMPlannerAgent(
        "MultiInputPolicy", env, seed=0, planner_config={"num_samples": 8, "iterations": 2}, subgoal_graph={"lookahead": 4}
    )
    data = collect_random_transitions(env, 2000, seed=0)
    agent.learn_offline(data, epochs=1)
    assert isinstance(agent.subgoals, GraphSubgoals) and agent.subgoals.lookahead == 4 and len(agent.subgoals.nodes) > 10
    with pytest.raises(ValueError, match="unknown"):
        EBMPlannerAgent("MultiInputPolicy", env, subgoal_graph={"radius": 2})
    with pytest.raises(ValueError, match="must be a SubgoalGraphConfig, a dict of its fields, or None"):
        EBMPlannerAgent("MultiInputPolicy", env, subgoal_graph=10)


def test_a_subgoal_is_never_across_cells_nobody_visited():
    """A block no transition entered: the straight line to a subgoal must not cut through it, even when the energy
    (here flat) would allow the move."""
    rng = np.random.default_rng(1)
    states = rng.uniform(-1, 1, size=(30_000, 2)).astype(np.float32)
    outside = ~((np.abs(states[:, 0]) < 0.3) & (np.abs(states[:, 1]) < 0.3))  # the block [-0.3, 0.3]^2 is never visited
    states = states[outside]
    following = np.clip(states + rng.uniform(-0.05, 0.05, size=states.shape).astype(np.float32), -1, 1)
    keep = ~((np.abs(following[:, 0]) < 0.3) & (np.abs(following[:, 1]) < 0.3))

    class Flat(torch.nn.Module):
        def forward(self, states: torch.Tensor, next_states: torch.Tensor) -> torch.Tensor:
            return torch.zeros(states.shape[:-1])

    flat = SimpleNamespace(
        energy_model=Flat(),
        device="cpu",
        horizon=40,
        goal_spec=SimpleNamespace(goal_indices=[0, 1]),
    )
    graph = _build(flat, states[keep], following[keep], lookahead=40)
    start, goal = np.array([[-0.6, 0.0]], np.float32), np.array([[0.6, 0.0]], np.float32)
    subgoal = graph.subgoals(start, goal)[0]
    segment = start[0] + np.linspace(0, 1, 200)[:, None] * (subgoal - start[0])
    assert not np.any((np.abs(segment[:, 0]) < 0.28) & (np.abs(segment[:, 1]) < 0.28))


def _left_graph(**kwargs) -> GraphSubgoals:
    """The graph of a walk that never left x < -0.2: everything right of it is unvisited."""
    agent = SimpleNamespace(
        energy_model=WallEnergy(), device="cpu", horizon=10, goal_spec=SimpleNamespace(goal_indices=[0, 1])
    )
    states, following = _walk()
    keep = (states[:, 0] < -0.2) & (following[:, 0] < -0.2)
    return _build(agent, states[keep], following[keep], **kwargs)


def test_the_frontier_chosen_is_the_visited_edge_nearest_the_unseen_goal():
    frontier = FrontierSubgoals(_left_graph())
    assert frontier.num_frontiers > 0
    start, goal = np.array([[-0.8, -0.8]], np.float32), np.array([[0.8, -0.8]], np.float32)
    subgoal = frontier.subgoals(start, goal)[0]
    assert subgoal[0] > -0.8 + 0.1  # towards the visited region's right edge, the side of the goal
    near_edge = np.array([[-0.25, -0.8]], np.float32)
    pushed = frontier.subgoals(near_edge, goal)[0]
    assert pushed[0] > -0.2  # at the frontier: past the visited edge, into the unvisited side


def test_plans_that_do_not_get_through_make_the_frontier_give_way():
    graph = _left_graph()
    frontier = FrontierSubgoals(graph, revisit_cost=1.0)
    edge = graph.nodes[np.argmin(np.abs(graph.nodes - [-0.2, -0.8]).max(axis=1))]  # a visited node at the right edge
    state, goal = edge[None].astype(np.float32), np.array([[0.8, -0.8]], np.float32)
    first = frontier.subgoals(state, goal)[0]
    for _ in range(200):  # stuck: every plan is made in the same cell
        frontier.subgoals(state, goal)
    later = frontier.subgoals(state, goal)[0]
    assert first[0] > edge[0] and np.abs(later - first).max() > 0.01  # pushed right first; another frontier now
    assert max(frontier.plan_counts.values()) >= 202  # every plan made in the stuck cell counts against it


def test_goal_free_exploration_heads_for_the_nearest_frontier():
    frontier = FrontierSubgoals(_left_graph(), goal_heuristic=0.0)
    state = np.array([[-0.95, 0.0]], np.float32)  # beside the left border of [-1, 1]^2: its frontier is next door
    subgoal = frontier.subgoals(state, np.array([[0.8, -0.8]], np.float32))[0]
    assert subgoal[0] < -0.95 and abs(subgoal[1]) < 0.1


def test_once_the_goal_was_seen_the_plans_follow_the_graph_to_it():
    graph = _graph(lookahead=5)
    frontier = FrontierSubgoals(graph)
    start, goal = np.array([[-0.8, -0.8]], np.float32), np.array([[0.8, -0.8]], np.float32)
    np.testing.assert_array_equal(frontier.subgoals(start, goal), graph.subgoals(start, goal))


def test_the_explore_option_explores_during_learn_only():
    seen = []

    class Record(BaseCallback):
        def _on_step(self) -> bool:
            seen.append(type(self.model.explorer).__name__)
            return True

    agent = EBMPlannerAgent(
        "MultiInputPolicy",
        gym.make("ebm/Particle-v0"),
        seed=0,
        planner_config={"num_samples": 8, "iterations": 2},
        explore={"every": 40},
        image_log_interval=0,
    )
    agent.learn(120, callback=Record())
    assert seen[0] == "NoneType" and seen[-1] == "FrontierSubgoals"  # built once the buffer holds transitions
    assert agent.explorer is None and agent.subgoals is None  # no subgoal_graph: after learn, plans aim at the goal
    with pytest.raises(ValueError, match=r"explore: unknown keys \['rebuild'\]"):
        EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Particle-v0"), explore={"rebuild": 5})
    with pytest.raises(ValueError, match="positive int"):
        EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Particle-v0"), explore={"every": 0})
    with pytest.raises(ValueError, match="revisit_cost"):
        EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Particle-v0"), explore={"revisit_cost": float("nan")})
    with pytest.raises(ValueError, match="goal_heuristic"):
        EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Particle-v0"), explore={"goal_heuristic": -1.0})


def test_while_exploring_the_evaluations_follow_the_graph_and_the_training_plans_the_frontier():
    agent = EBMPlannerAgent(
        "MultiInputPolicy",
        gym.make("ebm/Maze-v0"),
        seed=0,
        planner_config={"num_samples": 8, "iterations": 2},
        explore={"every": 50},
        subgoal_graph={},
        image_log_interval=0,
    )
    agent.learn(100)
    agent.build_frontier()
    assert isinstance(agent.explorer, FrontierSubgoals) and agent.subgoals is agent.explorer.graph
    state, goal = np.array([[-0.85, -0.85]], np.float32), np.array([[0.7, -0.8]], np.float32)
    np.testing.assert_array_equal(agent._plan_goals(state, goal), agent.subgoals.subgoals(state, goal))
    counts = dict(agent.explorer.plan_counts)
    agent._plan_goals(state, goal, training=True)
    assert sum(agent.explorer.plan_counts.values()) > sum(counts.values())  # the frontier aimed this plan


def _energy_free_agent() -> SimpleNamespace:
    """An agent with a goal layout and a horizon but no energy (as Action FF)."""
    return SimpleNamespace(horizon=10, goal_spec=SimpleNamespace(goal_indices=[0, 1]))


def test_real_edges_are_the_moves_made_and_need_no_energy():
    states, following = _walk()
    graph = _build(_energy_free_agent(), states, following, edges="real")
    assert graph.energy is None and graph.num_edges > 0
    path = graph.path(np.array([-0.8, -0.8], np.float32), np.array([0.8, -0.8], np.float32))
    assert len(path) > 0 and path[:, 1].max() > 0.5  # round the wall that no real move crossed
    crossings = np.sign(path[:-1, 0]) != np.sign(path[1:, 0])
    assert np.all(np.maximum(path[:-1, 1], path[1:, 1])[crossings] >= 0.5)
    # Every edge joins two neighbouring cells that some real transition went between, in that direction.
    side = graph.cell * graph.step
    made = {
        (tuple(a), tuple(b))
        for a, b in zip(np.floor(states / side).astype(int).tolist(), np.floor(following / side).astype(int).tolist())
    }
    rows, cols = graph.graph.nonzero()
    cells = graph._cell_of(graph.nodes)
    assert all((tuple(cells[u].tolist()), tuple(cells[v].tolist())) in made for u, v in zip(rows, cols))


def test_edges_from_both_join_the_energys_and_the_real_moves_and_bad_edges_are_refused():
    agent = SimpleNamespace(
        energy_model=WallEnergy(), device="cpu", horizon=10, goal_spec=SimpleNamespace(goal_indices=[0, 1])
    )
    states, following = _walk(steps=5000)
    energy = _build(agent, states, following)
    real = _build(agent, states, following, edges="real")
    both = _build(agent, states, following, edges="both")
    union = set(zip(*energy.graph.nonzero())) | set(zip(*real.graph.nonzero()))
    assert set(zip(*both.graph.nonzero())) == union and real.num_edges > 0
    assert both.energy is not None and np.isfinite(both.energy_threshold)
    with pytest.raises(ValueError, match="edges must be one of"):
        _build(agent, states, following, edges="walls")
    with pytest.raises(ValueError, match="needs a learned energy"):
        _build(_energy_free_agent(), states, following, edges="both")


def test_action_ff_explores_with_a_graph_of_its_real_moves_and_refuses_energy_edges():
    env = gym.make("ebm/Maze-v0")
    graph, explore = {"edges": "real"}, {"every": 100}
    planner = {"iterations": 2}
    agent = ActionFFAgent("MultiInputPolicy", env, seed=0, subgoal_graph=graph, explore=explore, planner_config=planner)
    agent.learn(300)
    assert isinstance(agent.subgoals, GraphSubgoals) and agent.subgoals.energy is None and agent.explorer is None
    assert len(agent.subgoals.nodes) > 1
    with pytest.raises(ValueError, match="edges='real'"):
        ActionFFAgent("MultiInputPolicy", env, subgoal_graph={})
    with pytest.raises(ValueError, match="edges='real'"):
        ActionFFAgent("MultiInputPolicy", env, explore={})


def test_a_stalled_plan_repeats_a_real_move_from_nearby_that_got_closer_trying_the_next_one_each_time():
    states, following = _walk()
    graph = _build(_energy_free_agent(), states, following, edges="real", patience=2, unstick="real_move")
    here, goal = np.array([[-0.9, -0.4]], np.float32), np.array([[-0.2, -0.8]], np.float32)
    target = graph._goal_node(goal[0])
    distance, _ = graph._paths_to(target)
    node = graph._start_node(here[0], distance)
    plain = graph.subgoals(here, goal)[0]
    assert node is not None and not np.allclose(plain, goal[0])  # a path, longer than the lookahead
    graph.subgoals(here, goal)  # one stalled call: patience 2 not reached yet
    moves = []
    for _ in range(3):  # stalled: each call repeats another real move
        out = graph.subgoals(here, goal)[0]
        assert not np.allclose(out, plain)
        moves.append(out - here[0])
    for move in moves:
        made = np.flatnonzero(np.all(np.isclose(following - states, move, atol=1e-6), axis=1))
        assert len(made) > 0  # a displacement a real transition made ...
        starts_near = np.abs(states[made] - here[0]).max(axis=1) <= 0.5 * graph.step.max() + 1e-6
        assert starts_near.any()  # ... from within half a step of here ...
        cells = graph._cell_of(following[made[starts_near]])
        costs = [distance[graph._node_of_cell[tuple(c)]] for c in cells.tolist() if tuple(c) in graph._node_of_cell]
        assert min(costs) < distance[node]  # ... that ended closer to the goal along the graph
    assert len({tuple(np.round(m, 6)) for m in moves}) == 3  # the next one each time


def test_unstick_is_checked():
    states, following = _walk(steps=2000)
    with pytest.raises(ValueError, match="unstick must be one of"):
        _build(_energy_free_agent(), states, following, edges="real", unstick="jump")
    graph = _build(_energy_free_agent(), states, following, edges="real")
    with pytest.raises(ValueError, match="needs the real transitions"):
        GraphSubgoals(graph.nodes, graph.goal_indices, graph.step, graph.graph, 10, np.inf, unstick="real_move")


def test_real_hops_keeps_the_real_moves_that_crossed_a_cell_at_the_cost_of_the_cells_they_span():
    states, following = _walk(steps=5000)
    one = _build(_energy_free_agent(), states, following, edges="real", clearance=0.0)
    two = _build(_energy_free_agent(), states, following, edges="real", clearance=0.0, real_hops=2)
    assert set(zip(*one.graph.nonzero())) < set(zip(*two.graph.nonzero()))
    cells = two._cell_of(two.nodes)
    rows, cols = two.graph.nonzero()
    spans = np.abs(cells[rows] - cells[cols]).max(axis=1)
    assert set(spans.tolist()) == {1, 2} and np.allclose(np.asarray(two.graph[rows, cols]).ravel(), spans)
    with pytest.raises(ValueError, match="real_hops"):
        _build(_energy_free_agent(), states, following, edges="real", real_hops=0)


def test_a_stalled_plan_never_repeats_a_move_that_went_nowhere():
    states, following = _walk()
    here, goal = np.array([[-0.9, -0.4]], np.float32), np.array([[-0.2, -0.8]], np.float32)
    offsets = np.stack(np.meshgrid(*[np.linspace(-0.02, 0.02, 5)] * 2), axis=-1).reshape(-1, 2)  # [25, 2]
    stuck = (here + offsets).astype(np.float32)  # moves refused from right beside here, some in cells nearer the goal
    states, following = np.concatenate([states, stuck]), np.concatenate([following, stuck])
    graph = _build(_energy_free_agent(), states, following, edges="real", patience=1, unstick="real_move")
    graph.subgoals(here, goal)
    for _ in range(5):  # stalled: each call repeats a real move, never one that stayed put
        out = graph.subgoals(here, goal)[0]
        assert np.abs(out - here[0]).max() >= 0.25 * graph.step.max() - 1e-6


def test_aim_visited_puts_the_subgoals_on_states_the_agent_was_at():
    states, following = _walk()
    agent = _energy_free_agent()
    centre = _build(agent, states, following, edges="real")
    visited = _build(agent, states, following, edges="real", aim="visited")
    assert centre.aims is None and np.array_equal(visited.nodes, centre.nodes)  # the same graph
    assert visited.aims is not None and visited.aims.shape == visited.nodes.shape
    assert np.array_equal(visited._cell_of(visited.aims), visited._cell_of(visited.nodes))  # each in its node's cell
    seen = {tuple(s) for s in states.tolist()}
    assert all(tuple(a) in seen for a in visited.aims.tolist())  # each a state the agent was at
    start, goal = np.array([[-0.8, -0.8]], np.float32), np.array([[0.8, -0.8]], np.float32)
    subgoal = visited.subgoals(start, goal)[0]
    assert any(np.array_equal(subgoal, a) for a in visited.aims) and not np.allclose(subgoal, goal[0])
    with pytest.raises(ValueError, match="aim must be one of"):
        _build(agent, states, following, edges="real", aim="corner")


def test_the_visited_state_of_a_cell_is_the_one_nearest_its_mean():
    from ebm_agent.subgoals import _visited_in_cells

    states = np.array([[0.0, 0.0], [0.4, 0.4], [1.0, 1.0], [5.0, 5.0], [5.2, 5.0]], np.float32)  # [5, 2]
    cells = np.array([0, 0, 0, 1, 1])
    chosen = _visited_in_cells(states, cells, 2)
    assert chosen.tolist() == [[0.4000000059604645, 0.4000000059604645], [5.0, 5.0]]  # mean 0.467; a tie: the first


def test_a_stall_makes_the_first_edge_of_the_path_dearer_and_the_path_goes_another_way():
    states, following = _walk()
    here, goal = np.array([[-0.9, -0.4]], np.float32), np.array([[-0.2, -0.8]], np.float32)
    graph = _build(_energy_free_agent(), states, following, edges="real", patience=1, stall_penalty=1000.0)
    target = graph._goal_node(goal[0])
    before = graph._path_ahead(here[0], target)
    assert before is not None and len(before) > 1
    cost = graph.graph[before[0], before[1]]
    graph.subgoals(here, goal)  # the first call: not stalled yet
    assert graph.graph[before[0], before[1]] == cost
    graph.subgoals(here, goal)  # stalled at the same state: its path's first move is evidence-against
    assert graph.graph[before[0], before[1]] == cost + 1000.0
    after = graph._path_ahead(here[0], target)
    assert after is not None and after[:2] != before[:2]  # searched again: another first move
    plain = _build(_energy_free_agent(), states, following, edges="real", patience=1)
    for _ in range(3):
        plain.subgoals(here, goal)
    fresh = _build(_energy_free_agent(), states, following, edges="real")
    assert (plain.graph != fresh.graph).nnz == 0  # without the penalty the graph never changes


def test_stall_penalty_needs_patience_and_a_positive_value():
    states, following = _walk(steps=2000)
    for kwargs in ({"stall_penalty": 5.0}, {"stall_penalty": 0.0, "patience": 2}):
        with pytest.raises(ValueError, match="stall_penalty must be None or > 0"):
            _build(_energy_free_agent(), states, following, edges="real", **kwargs)


def test_direct_when_nearer_plans_straight_at_a_goal_past_the_graph():
    states, following = _walk()
    keep = states[:, 0] < 0.5  # nothing visited right of x = 0.5: the goal lies outside the graph
    states, following = states[keep], np.minimum(following[keep], 0.499)
    goal = np.array([[0.9, -0.8]], np.float32)
    past = np.array([[0.7, -0.75]], np.float32)  # nearer the goal than any node
    behind = np.array([[-0.8, -0.8]], np.float32)  # across the wall: the graph's way round still counts
    follow = _build(_energy_free_agent(), states, following, edges="real")
    direct = _build(_energy_free_agent(), states, following, edges="real", direct_when_nearer=True)
    assert not np.allclose(follow.subgoals(past, goal), goal)  # back to the graph's node nearest the goal
    assert np.allclose(direct.subgoals(past, goal), goal)
    assert np.array_equal(direct.subgoals(behind, goal), follow.subgoals(behind, goal))


# ------------------------------------------------------------------------------------------------ periodic dims
def _torus_walk(seed: int = 0, steps: int = 20_000) -> tuple[np.ndarray, np.ndarray]:
    """Random moves of at most 0.05 per axis on the torus [-1, 1)^2 (both dims periodic, period 2)."""
    rng = np.random.default_rng(seed)
    states = rng.uniform(-1, 1, size=(steps, 2)).astype(np.float32)
    moves = rng.uniform(-0.05, 0.05, size=states.shape).astype(np.float32)
    return states, (np.mod(states + moves + 1.0, 2.0) - 1.0).astype(np.float32)


def _periodic_agent() -> SimpleNamespace:
    """An energy-free agent whose two goal dims are periodic angles (as Reacher's: period 2)."""
    return SimpleNamespace(horizon=10, goal_spec=SimpleNamespace(goal_indices=[0, 1], goal_period=2.0))


def test_a_periodic_dim_wraps_its_cells_steps_and_paths():
    states, following = _torus_walk()
    graph = _build(_periodic_agent(), states, following, edges="real")
    np.testing.assert_allclose(graph.step, 0.05, atol=1e-3)  # the wrapped moves, not the 2.0 jump across the wrap
    cells = graph._cell_of(graph.nodes)
    assert cells.min() == 0 and np.all(cells.max(axis=0) == graph._around - 1)  # the cells tile each circle
    np.testing.assert_allclose(graph._around * graph._side, 2.0, rtol=1e-6)
    start, goal = np.array([-0.9, 0.0], np.float32), np.array([0.9, 0.0], np.float32)
    path = graph.path(start, goal)  # 0.2 apart across the wrap, 1.8 the other way
    assert 0 < len(path) <= 15 and np.all(np.abs(path) <= 1.0)  # 0.2 is 6 cells; 1.8 would be 49
    hops = np.abs(np.mod(np.diff(path, axis=0) + 1.0, 2.0) - 1.0).max(axis=1)
    assert hops.max() <= 0.05 + 1e-5  # each edge one move, the short way round
    subgoal = graph.subgoals(start[None], goal[None])[0]
    gap = np.abs(np.mod(subgoal - goal + 1.0, 2.0) - 1.0)
    assert gap[0] < 0.2  # across the wrap, towards the goal
    # Without the period the same states make a graph whose steps span the circle (a move across the wrap is 2 long).
    flat = _build(_energy_free_agent(), states, following, edges="real")
    assert flat.step.max() > 1.9


def test_the_wrap_is_no_frontier_and_a_visited_aim_sits_on_its_side_of_the_wrap():
    states, following = _torus_walk()
    keep = np.abs(states[:, 0]) > 0.5  # a band across the wrap: x in [-1, -0.5) and (0.5, 1)
    graph = _build(_periodic_agent(), states[keep], following[keep], edges="real", aim="visited")
    frontier = FrontierSubgoals(graph, goal_heuristic=0.0)
    assert frontier.num_frontiers > 0
    assert np.all(np.abs(np.abs(frontier._frontier_points[:, 0]) - 0.5) < 0.2)  # only at the band's open sides
    assert graph.aims is not None
    gaps = np.abs(np.mod(graph.aims - graph.nodes + 1.0, 2.0) - 1.0)  # [V, 2] aim to its cell's centre
    assert gaps.max() <= 0.5 * graph._side.max() + 1e-5  # in its own cell, not averaged across the wrap


@pytest.mark.parametrize("env_id", ["ebm/Particle-v0", "ebm/Maze-v0", "ebm/Reacher-v0", "ebm/SawyerReach-v0"])
def test_graph_subgoals_and_exploration_run_on_every_env(env_id):
    env = gym.make(env_id)
    agent = EBMPlannerAgent(
        "MultiInputPolicy",
        env,
        seed=0,
        planner_config={"num_samples": 8, "iterations": 2},
        explore={"every": 30},
        subgoal_graph={"quantile": 0.99, "patience": 2, "edges": "both", "unstick": "real_move", "aim": "visited"},
        image_log_interval=0,
    )
    agent.learn(90)
    assert isinstance(agent.subgoals, GraphSubgoals) and len(agent.subgoals.nodes) > 0
    periodic = getattr(agent.goal_spec, "goal_period", None) is not None
    assert (agent.subgoals.period is not None) == periodic  # only Reacher's angles wrap
    obs, _ = env.reset(seed=1)
    state = None
    for _ in range(5):
        action, state = agent.predict(obs, state=state, deterministic=True)
        assert env.action_space.contains(action)
        obs, *_ = env.step(action)


def test_the_long_horizon_settings_are_typed_configs(tmp_path):
    graph = SubgoalGraphConfig(patience=2, aim="visited")
    agent = EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Maze-v0"), subgoal_graph=graph, explore={"every": 50})
    assert agent.subgoal_graph == graph and agent.explore == ExploreConfig(every=50)
    # the config's defaults are the builder's: a graph from {} is the graph from no keywords at all
    builder = inspect.signature(GraphSubgoals.from_transitions).parameters
    defaults = {name: builder[name].default for name in SubgoalGraphConfig().kwargs() if name != "lookahead"}
    assert defaults == {k: v for k, v in SubgoalGraphConfig().kwargs().items() if k != "lookahead"}
    assert SubgoalGraphConfig().lookahead is None and builder["lookahead"].default is inspect.Parameter.empty
    with pytest.raises(ValueError, match=r"aim must be one of \('centre', 'visited'\)"):
        SubgoalGraphConfig(aim="middle")
    with pytest.raises(ValueError, match="edges must be one of"):
        EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Maze-v0"), subgoal_graph={"edges": "walls"})
    with pytest.raises(ValueError, match=r"SubgoalGraphConfig\.patience must be"):
        EBMPlannerAgent("MultiInputPolicy", gym.make("ebm/Maze-v0"), subgoal_graph={"patience": "2"})
    # a model saved before the settings were typed holds dicts: load() turns them into the configs
    agent.subgoal_graph, agent.explore = {"patience": 2, "aim": "visited"}, {"every": 50, "goal_heuristic": 1.0}
    agent.save(tmp_path / "old.zip")
    loaded = EBMPlannerAgent.load(tmp_path / "old.zip", env=gym.make("ebm/Maze-v0"), device="cpu")
    assert loaded.subgoal_graph == graph and loaded.explore == ExploreConfig(every=50)


def test_the_graph_is_built_from_an_energy_function_not_from_an_agent():
    states, following = _walk()
    graph = GraphSubgoals.from_transitions(states, following, goal_indices=[0, 1], lookahead=10, energy=WallEnergy())
    start, goal = np.array([[-0.6, -0.6]], np.float32), np.array([[0.6, -0.6]], np.float32)
    assert graph.subgoals(start, goal)[0, 1] > -0.6 + 0.1  # the path climbs round the wall's end at y = 0.5
    with pytest.raises(ValueError, match=r"edges='energy' needs a learned energy, and the builder \(energy=None\) has none"):
        GraphSubgoals.from_transitions(states, following, goal_indices=[0, 1], lookahead=10)
    with pytest.raises(ValueError, match="lookahead must be a positive int"):
        GraphSubgoals.from_transitions(states, following, goal_indices=[0, 1], lookahead=0, edges="real")
    with pytest.raises(ValueError, match=r"period must be a \[D\] = \[2\] array"):
        GraphSubgoals.from_transitions(states, following, goal_indices=[0, 1], lookahead=10, edges="real", period=[2.0])


class HalfwaySubgoals:
    """A stand-in subgoal provider: aims each plan ``fraction`` of the way from the state's goal dims to the goal, and
    records what the agent handed its builder."""

    built: ClassVar[list[dict]] = []

    def __init__(self, goal_indices: np.ndarray, fraction: float) -> None:
        self.goal_indices, self.fraction = goal_indices, fraction

    @classmethod
    def from_transitions(cls, states, next_states, *, goal_indices, lookahead, energy, period, fraction=0.5):
        cls.built.append(
            {"states": states.shape, "goal_indices": list(goal_indices), "lookahead": lookahead, "energy": energy}
        )
        return cls(np.asarray(goal_indices), fraction)

    def subgoals(self, states: np.ndarray, goals: np.ndarray) -> np.ndarray:
        here = states[:, self.goal_indices]  # [N, G]
        return (here + self.fraction * (goals - here)).astype(np.float32)  # [N, G]


def test_an_agent_takes_another_subgoal_class_with_its_keywords():
    HalfwaySubgoals.built.clear()
    env = gym.make("ebm/Particle-v0")
    agent = EBMPlannerAgent(
        "MultiInputPolicy", env, horizon=4, subgoal_class=HalfwaySubgoals, subgoal_graph={"fraction": 0.25}, seed=0
    )
    states = np.zeros((8, 2), np.float32)
    provider = agent.build_subgoals(states, states + 0.05)
    assert isinstance(provider, HalfwaySubgoals) and provider.fraction == 0.25 and agent.subgoals is provider
    (built,) = HalfwaySubgoals.built
    assert built["states"] == (8, 2) and built["goal_indices"] == [0, 1] and built["lookahead"] == 4
    assert built["energy"] is agent.energy_model  # the learned energy, not the agent
    state, goal = np.zeros((1, 2), np.float32), np.ones((1, 2), np.float32)
    np.testing.assert_allclose(agent._plan_goals(state, goal), 0.25)  # the plans aim where the provider says
    # Action FF hands it no energy; a subclass of GraphSubgoals takes the typed config, built with {} when none is given
    HalfwaySubgoals.built.clear()
    ActionFFAgent("MultiInputPolicy", env, subgoal_class=HalfwaySubgoals).build_subgoals(states, states + 0.05)
    assert HalfwaySubgoals.built[0]["energy"] is None

    class Wider(GraphSubgoals):
        pass

    assert EBMPlannerAgent("MultiInputPolicy", env, subgoal_class=Wider).subgoal_graph == SubgoalGraphConfig()


def test_a_bad_subgoal_class_fails_at_construction():
    env = gym.make("ebm/Particle-v0")
    with pytest.raises(TypeError, match=r"subgoal_class must be a class with a from_transitions"):
        EBMPlannerAgent("MultiInputPolicy", env, subgoal_class=dict)
    with pytest.raises(TypeError, match="pass its keywords as a dict"):
        EBMPlannerAgent("MultiInputPolicy", env, subgoal_class=HalfwaySubgoals, subgoal_graph=SubgoalGraphConfig())
    with pytest.raises(ValueError, match="explore needs a GraphSubgoals graph"):
        EBMPlannerAgent("MultiInputPolicy", env, subgoal_class=HalfwaySubgoals, explore={})
    with pytest.raises(ValueError, match="needs a learned energy, and ActionFFAgent has none"):
        ActionFFAgent("MultiInputPolicy", env, subgoal_graph={})
