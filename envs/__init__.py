"""Goal-conditioned Gymnasium environments of the paper, registered under the ``ebm/`` namespace.

Importing this package registers:

- ``ebm/Particle-v0``: a point in [-1, 1]^2 moving by at most 0.05 per axis per step (optional box obstacle).
- ``ebm/Maze-v0``: the particle with the walls of the authors' final maze layout.
- ``ebm/Reacher-v0``: gymnasium's Reacher-v4 seen through the paper's normalised 4-D joint state.
- ``ebm/SawyerReach-v0``: a torque-controlled 7-DoF Sawyer arm built from Metaworld's assets.

``gym.make("envs:ebm/Particle-v0")`` imports the package first, so third-party CLIs need no import.

Every environment follows the same contract (what the agents rely on), on its *unwrapped* object:

- ``observation_space`` is a ``Dict`` with ``observation`` [D], ``achieved_goal`` [G] and ``desired_goal`` [G]
  (gymnasium-robotics' ``GoalEnv`` convention); ``achieved_goal == observation[goal_indices]``.
- ``compute_reward(achieved_goal, desired_goal, info)`` is vectorised over a leading batch axis.
- ``info["is_success"]`` is set on every step.
- ``goal_indices``: ``np.ndarray`` of int, the observation dims the goal constrains.
- ``target_indices``: ``np.ndarray`` of int, observation dims that *encode* the target (masked out of the
  energy's input, as the original code did for the arm); empty for most envs.
- ``goal_period``: ``float | None``; the goal dims are periodic with this period (Reacher angles: 2.0).
- ``state_low`` / ``state_high``: ``np.ndarray`` [D] bounds of ``observation`` that a planner may clip to, or
  ``None`` where the state is unbounded.
- ``inverse_dynamics(states [B, D], next_states [B, D]) -> actions [B, A]``: batched ground-truth inverse
  dynamics (exact for particle and maze, MuJoCo inverse dynamics for Reacher and Sawyer).
"""

from __future__ import annotations

import contextlib
import io
import sys
from collections.abc import Iterator

from gymnasium.envs.registration import register, registry

try:  # what Farama's packages print on import for some of their releases (a dependency of gymnasium)
    from farama_notifications import notifications as _notifications
except ImportError:  # pragma: no cover - gymnasium without it prints nothing either
    _notifications = {}

RELEASE_NOTICES: frozenset[str] = frozenset(
    message for project in _notifications.values() for message in project.values() if isinstance(message, str)
)
"""The release notices that Farama's packages print to stderr when imported (gymnasium-robotics 1.2.1-1.4.2: that
the Adroit envs' rewards changed, which concerns no env of ours): kept out of every command's output."""


@contextlib.contextmanager
def without_release_notices() -> Iterator[None]:
    """Within the block, stderr lines that are exactly a Farama release notice are dropped; all else passes through.

    :return: a context manager.
    """
    captured = io.StringIO()
    try:
        with contextlib.redirect_stderr(captured):
            yield
    finally:
        kept = [line for line in captured.getvalue().splitlines(keepends=True) if line.strip() not in RELEASE_NOTICES]
        sys.stderr.write("".join(kept))


with without_release_notices():  # registers gymnasium-robotics' envs (FetchReach-v4, PointMaze_UMaze-v3, ...)
    import gymnasium_robotics  # noqa: F401

ENV_IDS: dict[str, str] = {
    "particle": "ebm/Particle-v0",
    "maze": "ebm/Maze-v0",
    "reacher": "ebm/Reacher-v0",
    "sawyer": "ebm/SawyerReach-v0",
}
"""Short names used by the CLI and presets, mapped to registered ids."""

THIRD_PARTY_ENV_IDS: dict[str, str] = {
    "pointmaze": "PointMaze_UMaze-v3",
    "fetch-reach": "FetchReach-v4",
    "fetch-push": "FetchPush-v4",
}
"""Short names of the gymnasium-robotics envs the harness compares on, unmodified (docs/guide.md, "Your own env")."""

PROTOCOL_ENV_KWARGS: dict[str, dict[str, object]] = {
    # An episode ends at the goal (the registered default resamples the goal and goes on until the time limit, so
    # the final step's is_success would not say whether the goal was reached): the protocol of the D4RL-style
    # goal-reaching comparisons and of the third-party measurements (shared reference).
    "PointMaze_UMaze-v3": {"continuing_task": False},
}
"""Keyword arguments the harness gives an env for training and evaluation alike, before ``--env-kwargs``."""

PAPER_EVAL_KWARGS: dict[str, dict[str, object]] = {
    # The paper's particle evaluation: from (0, 0) to (0.5, 0.5), optimum -4.5 (original_code.md §6). Training uses
    # random starts (the registered default), so evaluation needs these explicitly.
    "ebm/Particle-v0": {"start": (0.0, 0.0), "goal": (0.5, 0.5)},
}
"""Keyword arguments of each env's evaluation configuration in the paper; the harness evaluates with them by
default. Envs not listed evaluate with their registered defaults (already the paper's: maze, Reacher, Sawyer)."""


def _register(env_id: str, entry_point: str, max_episode_steps: int) -> None:
    if env_id not in registry:
        register(id=env_id, entry_point=entry_point, max_episode_steps=max_episode_steps)


_register("ebm/Particle-v0", "envs.particle:ParticleEnv", 100)
_register("ebm/Maze-v0", "envs.maze:MazeEnv", 1000)
_register("ebm/Reacher-v0", "envs.reacher:ReacherEnv", 50)
_register("ebm/SawyerReach-v0", "envs.sawyer:SawyerReachEnv", 1000)


def resolve_env_id(name: str) -> str:
    """Map a short name (``particle``, ``maze``, ``reacher``, ``sawyer``, or a third-party one such as
    ``fetch-reach``) or a registered id to a registered id.

    :param name: short name or any Gymnasium id.
    :return: the Gymnasium id to pass to ``gym.make``.
    """
    key = name.lower()
    return ENV_IDS.get(key) or THIRD_PARTY_ENV_IDS.get(key) or name


__all__ = ["ENV_IDS", "PAPER_EVAL_KWARGS", "PROTOCOL_ENV_KWARGS", "THIRD_PARTY_ENV_IDS", "resolve_env_id"]
