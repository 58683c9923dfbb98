"""Sanity anchors printed beside the scores: the optimum where it is known, a random policy, standing still.

The random-policy and standing-still scores are *computed* by rolling the env itself, so they follow its
configuration. Only the optima are constants: they are analytical or lattice-search results for the
paper's evaluation configurations, taken from reference/original_code.md §6, and are reported only when
the env really starts at the paper's start and aims at the paper's goal.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  registers the ebm/ ids


@dataclass(frozen=True)
class KnownOptimum:
    """The best achievable score of one evaluation configuration.

    :param env_id: the registered id it applies to.
    :param start: the start state the configuration uses.
    :param goal: the goal it uses.
    :param score: the best achievable score (sum of per-step rewards).
    :param source: where the number comes from.
    :param obstacle: True if it is the obstacle variant's optimum.
    """

    env_id: str
    start: tuple[float, ...]
    goal: tuple[float, ...]
    score: float
    source: str
    obstacle: bool = False


KNOWN_OPTIMA: tuple[KnownOptimum, ...] = (
    # 10 diagonal moves of 0.05 per axis from (0,0) to (0.5,0.5): -(0.9 + 0.8 + ... + 0.0) = -4.5.
    KnownOptimum("ebm/Particle-v0", (0.0, 0.0), (0.5, 0.5), -4.5, "original_code.md §6 (10 diagonal steps)"),
    # The authors' default box touches the goal corner, so the goal is out of reach: a lattice estimate.
    KnownOptimum("ebm/Particle-v0", (0.0, 0.0), (0.5, 0.5), -10.0, "original_code.md §6 (lattice estimate)", True),
    # Value iteration on a 0.01 lattice with moves up to 0.05 per axis through the final maze layout, computed by
    # envs.maze.maze_optimal_score(): -73.67 in 54 steps under the strict y > 0.25 / y < -0.25 wall rule (the -71.9
    # of original_code.md §6 counted y = 0.25 as free through a float artefact; see docs/environments.md).
    KnownOptimum(
        "ebm/Maze-v0", (-0.85, -0.85), (0.7, -0.8), -73.67, "envs.maze.maze_optimal_score() (0.01 lattice, 54 steps)"
    ),
)
"""Optima of the paper's evaluation configurations; Reacher and Sawyer have none (Sawyer: see standing still)."""

_OBSTACLE_ATTRIBUTES = ("obstacle", "obstacles", "obstacle_box")


@dataclass(frozen=True)
class EnvAnchors:
    """Reference scores of one env configuration.

    :param env_id: registered id.
    :param optimum: best achievable score, or None when unknown for this configuration.
    :param optimum_source: where the optimum comes from.
    :param random_mean: mean score of uniform random actions.
    :param random_std: population std of that score over episodes.
    :param random_episodes: episodes behind ``random_mean``.
    :param still_score: score of the zero action held for one deterministic episode.
    """

    env_id: str
    optimum: float | None
    optimum_source: str | None
    random_mean: float
    random_std: float
    random_episodes: int
    still_score: float


def rollout_score(env: gym.Env, policy: Any, seed: int) -> float:
    """Undiscounted sum of rewards of one episode.

    :param env: the env (with its ``TimeLimit``, so the episode ends).
    :param policy: maps an observation to an action.
    :param seed: seed of ``reset``.
    :return: the episode's score.
    """
    observation, _ = env.reset(seed=seed)
    total, done = 0.0, False
    while not done:
        observation, reward, terminated, truncated, _ = env.step(policy(observation))
        total += float(reward)
        done = terminated or truncated
    return total


def compute_anchors(
    env_id: str, env_kwargs: dict[str, Any] | None = None, seed: int = 0, random_episodes: int = 10
) -> EnvAnchors:
    """Roll the random and standing-still policies in the env, and look its optimum up.

    :param env_id: registered Gymnasium id.
    :param env_kwargs: keyword arguments of ``gym.make``.
    :param seed: seed of the resets and of the random actions (episode ``i`` uses ``seed + i``).
    :param random_episodes: number of random-policy episodes.
    :return: the anchors.
    """

    if random_episodes < 1:
        raise ValueError(f"random_episodes must be at least 1, got {random_episodes}")
    env = gym.make(env_id, **(env_kwargs or {}))
    try:
        space = env.action_space
        if not isinstance(space, gym.spaces.Box):
            raise TypeError(f"anchors need a Box action space (the zero action stands still), got {space}")
        space.seed(seed)
        random_scores = [rollout_score(env, lambda _obs: space.sample(), seed + i) for i in range(random_episodes)]
        zero_action = np.zeros(space.shape, dtype=space.dtype)
        still_score = rollout_score(env, lambda _obs: zero_action, seed)
        optimum = _match_optimum(env_id, env, seed)
    finally:
        env.close()
    return EnvAnchors(
        env_id=env_id,
        optimum=optimum.score if optimum else None,
        optimum_source=optimum.source if optimum else None,
        random_mean=float(np.mean(random_scores)),
        random_std=float(np.std(random_scores)),
        random_episodes=random_episodes,
        still_score=still_score,
    )


def _match_optimum(env_id: str, env: gym.Env, seed: int) -> KnownOptimum | None:
    """The known optimum whose start and goal the env really uses (checked on two resets), if any."""
    first, _ = env.reset(seed=seed)
    second, _ = env.reset(seed=seed + 1)
    if not (isinstance(first, dict) and {"observation", "desired_goal"} <= first.keys()):
        return None
    fixed = np.allclose(first["observation"], second["observation"]) and np.allclose(
        first["desired_goal"], second["desired_goal"]
    )
    if not fixed:
        return None  # a random start or goal has no single optimum
    has_obstacle = any(getattr(env.unwrapped, name, None) is not None for name in _OBSTACLE_ATTRIBUTES)
    for known in KNOWN_OPTIMA:
        if known.env_id != env_id or known.obstacle != has_obstacle:
            continue
        start, goal = np.asarray(first["observation"]), np.asarray(first["desired_goal"])
        if start.shape == np.shape(known.start) and np.allclose(start, known.start) and np.allclose(goal, known.goal):
            if known.obstacle and not _is_paper_obstacle(env.unwrapped):
                return None
            return known
    return None


def _is_paper_obstacle(unwrapped: Any) -> bool:
    """True for the authors' default box x in [0.1, 0.5], y in [0.1, 0.5], the one the -10 estimate is for."""
    for name in _OBSTACLE_ATTRIBUTES:
        box = getattr(unwrapped, name, None)
        if box is not None:
            values = np.sort(np.asarray(box, dtype=np.float64).ravel())
            return values.shape == (4,) and np.allclose(values, [0.1, 0.1, 0.5, 0.5])
    return False


__all__ = ["KNOWN_OPTIMA", "EnvAnchors", "KnownOptimum", "compute_anchors", "rollout_score"]
