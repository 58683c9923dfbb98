"""Sanity anchors: computed standing-still and random scores, and the known optima of the paper's configurations."""

from __future__ import annotations

import pytest

from eval.anchors import KNOWN_OPTIMA, compute_anchors

pytest.importorskip("envs.particle")


def test_particle_paper_configuration():
    anchors = compute_anchors("ebm/Particle-v0", {"start": (0.0, 0.0), "goal": (0.5, 0.5)}, seed=0)
    assert anchors.optimum == -4.5
    assert "original_code.md" in (anchors.optimum_source or "")
    # Standing still at L1 distance 1.0 for the 100 steps of the time limit.
    assert anchors.still_score == pytest.approx(-100.0)
    assert anchors.random_episodes == 10
    # A random walk of 100 steps of at most 0.05 per axis stays within 10 of the start in L1 per step.
    assert -300.0 < anchors.random_mean < -4.5
    assert anchors.random_std > 0.0


def test_anchors_are_reproducible_and_follow_the_seed():
    first = compute_anchors("ebm/Particle-v0", {"start": (0.0, 0.0)}, seed=1, random_episodes=3)
    again = compute_anchors("ebm/Particle-v0", {"start": (0.0, 0.0)}, seed=1, random_episodes=3)
    other = compute_anchors("ebm/Particle-v0", {"start": (0.0, 0.0)}, seed=2, random_episodes=3)
    assert first == again
    assert first.random_mean != other.random_mean


def test_no_optimum_for_a_random_start_or_another_goal():
    assert compute_anchors("ebm/Particle-v0", {}, random_episodes=1).optimum is None
    assert compute_anchors("ebm/Particle-v0", {"start": (0.0, 0.0), "goal": (0.3, 0.5)}, random_episodes=1).optimum is None


def test_no_particle_optimum_with_an_obstacle_it_was_not_computed_for():
    anchors = compute_anchors("ebm/Particle-v0", {"start": (0.0, 0.0), "obstacle": (0.1, 0.1, 0.3, 0.3)}, random_episodes=1)
    assert anchors.optimum is None


def test_maze_optimum_and_standing_still():
    pytest.importorskip("envs.maze")
    anchors = compute_anchors("ebm/Maze-v0", random_episodes=1)
    from envs.maze import maze_optimal_score

    assert anchors.optimum == pytest.approx(maze_optimal_score(), abs=0.01)
    # Start (-0.85, -0.85), goal (0.7, -0.8): L1 1.6 for 1000 steps.
    assert anchors.still_score == pytest.approx(-1600.0, rel=1e-5)


def test_known_optima_cite_their_source():
    assert all(known.source.startswith(("original_code.md §6", "envs.maze.maze_optimal_score")) for known in KNOWN_OPTIMA)


def test_bad_episode_count_raises():
    with pytest.raises(ValueError, match="random_episodes"):
        compute_anchors("ebm/Particle-v0", random_episodes=0)
