"""What a planner needs to know about a goal-conditioned environment, read once from a VecEnv."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv

GOAL_KEYS = ("observation", "achieved_goal", "desired_goal")


@dataclass
class GoalSpec:
    """Layout of a goal-conditioned observation and the environment facts a state-space planner uses.

    :param state_dim: D, size of ``observation``.
    :param goal_dim: G, size of ``desired_goal``.
    :param action_dim: A, size of the (Box) action.
    :param goal_indices: [G] observation dims that ``achieved_goal`` reads (``achieved_goal == observation[goal_indices]``).
    :param target_indices: observation dims that encode the target, masked out of learned models' inputs.
    :param goal_period: period of the goal dims (angles) or None.
    :param state_low: [D] lower bounds a plan is clipped to, or None.
    :param state_high: [D] upper bounds, or None.
    :param action_low: [A] action lower bounds.
    :param action_high: [A] action upper bounds.
    :param goal_indices_inferred: whether ``goal_indices`` were inferred from a reset (the env declares none and
        none were given).
    """

    state_dim: int
    goal_dim: int
    action_dim: int
    goal_indices: np.ndarray
    target_indices: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    goal_period: float | None = None
    state_low: np.ndarray | None = None
    state_high: np.ndarray | None = None
    action_low: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.float32))
    action_high: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.float32))
    goal_indices_inferred: bool = False

    @property
    def model_dims(self) -> np.ndarray:
        """Observation dims a learned model sees (all but the target dims)."""
        return np.setdiff1d(np.arange(self.state_dim), self.target_indices)


def check_spaces(observation_space: spaces.Space, action_space: spaces.Space, owner: str = "EBMPlannerAgent") -> None:
    """Reject spaces a state-space planner cannot work with, with a message that names the fix.

    :param observation_space: the env's observation space.
    :param action_space: the env's action space.
    :param owner: the class name used in messages.
    :raises TypeError: for a non-Box action space or an observation without the goal keys.
    :raises ValueError: for unbounded actions.
    """
    if not isinstance(action_space, spaces.Box):
        raise TypeError(
            f"{owner} needs a continuous Box action space, got {action_space!r}. Planning in state space turns "
            "planned states into actions through inverse dynamics, which has no meaning for Discrete/MultiDiscrete "
            "actions; use PPO for discrete control."
        )
    if not (np.all(np.isfinite(action_space.low)) and np.all(np.isfinite(action_space.high))):
        raise ValueError(
            f"{owner} needs finite action bounds, got low={action_space.low} high={action_space.high}. "
            "Wrap the env with gymnasium.wrappers.ClipAction/RescaleAction to give the actions finite bounds."
        )
    if not isinstance(observation_space, spaces.Dict) or any(k not in observation_space.spaces for k in GOAL_KEYS):
        raise TypeError(
            f"{owner} needs a goal-conditioned Dict observation with keys {GOAL_KEYS}, got {observation_space!r}. "
            "Use one of the envs in `envs` (e.g. gym.make('ebm/Particle-v0')), or wrap your env so that it returns "
            "{'observation': state, 'achieved_goal': state[goal_dims], 'desired_goal': goal} like "
            "gymnasium-robotics' GoalEnv."
        )
    for key in GOAL_KEYS:
        sub = observation_space.spaces[key]
        if not isinstance(sub, spaces.Box) or len(sub.shape) != 1:
            raise TypeError(f"{owner} needs observation[{key!r}] to be a flat Box, got {sub!r}.")


def infer_goal_indices(observation: np.ndarray, achieved_goal: np.ndarray) -> np.ndarray:
    """Find the observation dims that ``achieved_goal`` copies, for envs that do not declare ``goal_indices``.

    :param observation: [N, D] observations.
    :param achieved_goal: [N, G] achieved goals of the same steps.
    :return: [G] indices such that ``observation[:, idx] == achieved_goal``.
    :raises ValueError: when some goal dim is not a copy of an observation dim.
    """
    indices = []
    for g in range(achieved_goal.shape[1]):
        matches = np.where(np.all(np.isclose(observation, achieved_goal[:, g : g + 1], atol=1e-6), axis=0))[0]
        if len(matches) == 0:
            raise ValueError(
                f"achieved_goal[{g}] is not a copy of any observation dim; declare `goal_indices` on the env "
                "(see envs/__init__.py for the contract)."
            )
        unused = [m for m in matches if m not in indices]
        indices.append(int(unused[0] if unused else matches[0]))
    return np.asarray(indices, dtype=np.int64)


def read_goal_spec(env: VecEnv, goal_indices: Sequence[int] | None = None) -> GoalSpec:
    """Read the planner-relevant facts from the first env of a VecEnv (the contract of ``envs``).

    Attributes missing on the env fall back to safe defaults: goal indices inferred from a reset observation,
    no target dims, no period, bounds from the observation space when finite.

    :param env: a VecEnv of goal-conditioned envs.
    :param goal_indices: [G] observation dims the goal reads, overriding the env's (None: the env's, or inferred).
    :return: the spec.
    :raises ValueError: for given ``goal_indices`` of the wrong length or outside the observation.
    """
    check_spaces(env.observation_space, env.action_space)
    obs_space = env.observation_space.spaces  # type: ignore[attr-defined]
    state_dim = int(obs_space["observation"].shape[0])
    goal_dim = int(obs_space["desired_goal"].shape[0])
    action_space = env.action_space
    assert isinstance(action_space, spaces.Box)

    def attr(name: str, default: object) -> object:
        try:
            return env.get_attr(name, indices=[0])[0]
        except AttributeError:
            return default

    declared: Any = goal_indices if goal_indices is not None else attr("goal_indices", None)
    if goal_indices is not None:
        given = np.asarray(goal_indices, dtype=np.int64)
        if given.shape != (goal_dim,) or np.any(given < 0) or np.any(given >= state_dim):
            raise ValueError(
                f"goal_indices={list(goal_indices)} must name {goal_dim} observation dims (desired_goal has {goal_dim}) "
                f"in [0, {state_dim})."
            )
    inferred = declared is None
    if inferred:
        obs = env.reset()
        declared = infer_goal_indices(obs["observation"], obs["achieved_goal"])  # type: ignore[call-overload,index]
    low = attr("state_low", None)
    high = attr("state_high", None)
    if low is None and high is None:
        box = obs_space["observation"]
        if np.all(np.isfinite(box.low)) and np.all(np.isfinite(box.high)):
            low, high = box.low, box.high
    spec = GoalSpec(
        state_dim=state_dim,
        goal_dim=goal_dim,
        action_dim=int(action_space.shape[0]),
        goal_indices=np.asarray(declared, dtype=np.int64),
        target_indices=np.asarray(attr("target_indices", np.zeros(0)), dtype=np.int64),
        goal_period=attr("goal_period", None),  # type: ignore[arg-type]
        state_low=None if low is None else np.asarray(low, dtype=np.float32),
        state_high=None if high is None else np.asarray(high, dtype=np.float32),
        action_low=np.asarray(action_space.low, dtype=np.float32),
        action_high=np.asarray(action_space.high, dtype=np.float32),
        goal_indices_inferred=inferred,
    )
    if len(spec.goal_indices) != goal_dim:
        raise ValueError(f"The env declares {len(spec.goal_indices)} goal_indices but desired_goal has {goal_dim} dims.")
    return spec


def env_inverse_dynamics(env: VecEnv) -> Callable[[np.ndarray, np.ndarray], np.ndarray] | None:
    """Return the env's batched ground-truth inverse dynamics as a function, or None if it has none.

    The call goes through ``env_method`` on env 0 (all envs of a VecEnv share their dynamics), so it also works
    for ``SubprocVecEnv``.

    :param env: the VecEnv.
    :return: ``fn(states [B, D], next_states [B, D]) -> actions [B, A]`` or None.
    """
    if not env.has_attr("inverse_dynamics"):
        return None

    def inverse_dynamics(states: np.ndarray, next_states: np.ndarray) -> np.ndarray:
        return np.asarray(env.env_method("inverse_dynamics", states, next_states, indices=[0])[0], dtype=np.float32)

    return inverse_dynamics


def check_finite_observation(observation: dict[str, np.ndarray], where: str) -> None:
    """Raise a clear error for NaN/inf in an observation dict.

    :param observation: the observation dict (any batch shape).
    :param where: name of the caller for the message.
    :raises ValueError: when a value is not finite.
    """
    for key in ("observation", "desired_goal"):
        value = np.asarray(observation[key])
        if not np.all(np.isfinite(value)):
            raise ValueError(
                f"{where}: observation[{key!r}] contains NaN or inf ({value.tolist()}). Check the environment's "
                "state, or the goal you set; the planner cannot plan from non-finite states."
            )
