"""Model-quality probe of a learned energy E(s, s'): does it tell moves the env rejects, and the real next state?

Two measures (issue #34), both deterministic given a seed and free of side effects on the agent (its weights, modes,
buffers and random streams are left as they were):

- :func:`feasibility_auroc`, for envs that can label feasibility (the maze, the particle with a box obstacle): the
  AUROC of E(s, s') at telling infeasible from feasible moves, over uniform valid states (or states near given data,
  e.g. an online agent's replay buffer) and uniform moves in the action box. 1.0 is a perfect separation, 0.5 chance
  (a constant energy gets exactly 0.5). Each move is labelled by the env itself: set to s, stepped with the env's
  ``inverse_dynamics(s, s')`` and compared with s'.
- :func:`next_state_rank`, for every env: on held-out real transitions (s, s'), how often the real s' has the
  lowest energy among itself and ``n_candidates`` perturbed copies s' + N(0, (scale * std(s' - s))^2).

Usage on a saved agent::

    import gymnasium as gym, torch, envs
    from ebm_agent import EBMPlannerAgent, collect_random_transitions
    from ebm_agent.probe import feasibility_auroc, next_state_rank

    torch.set_num_threads(1)
    env = gym.make("ebm/Maze-v0")
    agent = EBMPlannerAgent.load("model.zip", env=env, device="cpu")
    print(feasibility_auroc(agent, env, n_moves=4000, seed=0))
    held_out = collect_random_transitions(gym.make("ebm/Maze-v0"), 2000, seed=12345)
    print(next_state_rank(agent, held_out, n_candidates=64, seed=0))

or ``python -m ebm_agent.probe model.zip envs:ebm/Maze-v0``. During ``learn``, :class:`~ebm_agent.callbacks.
ModelProbeCallback` logs both to TensorBoard (``probe/*``).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import Tensor

from ebm_agent.agent import EBMPlannerAgent
from ebm_agent.costs import wrap_array
from ebm_agent.datasets import TransitionDataset, collect_random_transitions
from ebm_agent.energy import energy_function, transition_energies

__all__ = [
    "FeasibilityResult",
    "NextStateRankResult",
    "auroc",
    "buffer_states",
    "can_label_feasibility",
    "feasibility_auroc",
    "label_moves",
    "measure_reach",
    "model_quality",
    "next_state_rank",
    "sample_valid_states",
    "transition_energies",
]

EnergyFn = Callable[[Tensor, Tensor], Tensor]
"""E(states [..., D], next_states [..., D]) -> energies [...]."""

LABEL_TOLERANCE = 1e-5
"""A move is feasible when the env lands within this of s' per dim (the point envs' inverse dynamics is exact to 1e-7)."""


@dataclass(frozen=True)
class FeasibilityResult:
    """What :func:`feasibility_auroc` measured.

    :param auroc: P(E(infeasible) > E(feasible)), ties counted one half; NaN when one class is missing.
    :param num_feasible: moves the env accepted.
    :param num_infeasible: moves the env rejected (or could not make).
    :param mean_energy_feasible: mean energy of the accepted moves.
    :param mean_energy_infeasible: mean energy of the rejected moves.
    :param move_radius: [D] half-width of the uniform move box.
    """

    auroc: float
    num_feasible: int
    num_infeasible: int
    mean_energy_feasible: float
    mean_energy_infeasible: float
    move_radius: np.ndarray


@dataclass(frozen=True)
class NextStateRankResult:
    """What :func:`next_state_rank` measured.

    :param top1: fraction of transitions whose real s' has the lowest energy among itself and its candidates (a tie
        at the minimum with m candidates counts 1 / (m + 1)); chance is ``1 / (n_candidates + 1)``.
    :param mean_rank: mean fraction of candidates with a lower energy than the real s' (ties one half): 0 is
        perfect, 0.5 chance.
    :param chance: ``1 / (n_candidates + 1)``, the top-1 of an energy that cannot tell them apart.
    :param num_transitions: N, held-out transitions scored.
    :param num_candidates: K, perturbed candidates per transition.
    :param noise_std: [D] standard deviation of the perturbation per state dim.
    """

    top1: float
    mean_rank: float
    chance: float
    num_transitions: int
    num_candidates: int
    noise_std: np.ndarray


def auroc(scores: np.ndarray, labels: np.ndarray) -> float:
    """Area under the ROC curve of ``scores`` at picking the positives, by the Mann-Whitney U statistic.

    Tied scores get their average rank, so a tie between a positive and a negative counts one half (a constant score
    gives exactly 0.5). Pure numpy, O(n log n).

    :param scores: [N] scores, higher meaning "more likely positive" (here: the energy, for an infeasible move).
    :param labels: [N] bool (or 0/1) labels, True for a positive.
    :return: the AUROC in [0, 1]; NaN when there are no positives or no negatives.
    :raises ValueError: for shapes that differ or are not 1-D, or non-finite scores.
    """
    scores = np.asarray(scores, dtype=np.float64)
    labels = np.asarray(labels).astype(bool)
    if scores.ndim != 1 or labels.shape != scores.shape:
        raise ValueError(f"auroc: scores and labels must be [N] each, got {scores.shape} and {labels.shape}.")
    if not np.all(np.isfinite(scores)):
        raise ValueError("auroc: scores contain NaN or inf.")
    num_pos = int(labels.sum())
    num_neg = labels.size - num_pos
    if num_pos == 0 or num_neg == 0:
        return float("nan")
    order = np.argsort(scores, kind="mergesort")
    sorted_scores = scores[order]
    # Average 1-based rank of each run of equal scores: (first + last) / 2 over the run's positions.
    run_starts = np.flatnonzero(np.r_[True, sorted_scores[1:] != sorted_scores[:-1]])  # [U]
    run_ends = np.r_[run_starts[1:], scores.size]  # [U] exclusive
    run_ranks = (run_starts + 1 + run_ends) / 2.0  # [U]
    ranks = np.empty(scores.size)
    ranks[order] = np.repeat(run_ranks, run_ends - run_starts)
    u_statistic = ranks[labels].sum() - num_pos * (num_pos + 1) / 2.0
    return float(u_statistic / (num_pos * num_neg))


def feasibility_auroc(
    agent: Any,
    env: gym.Env,
    n_moves: int = 4000,
    near: np.ndarray | None = None,
    near_radius: float | np.ndarray | None = None,
    move_radius: float | np.ndarray | None = None,
    seed: int = 0,
) -> FeasibilityResult:
    """AUROC of the energy at telling the moves the env rejects from those it makes.

    Each of ``n_moves`` samples is a state s (uniform over the env's valid states, or near the ``near`` states) and
    a move s' = s + u with u ~ U(-r, r)^D, r = ``move_radius``: for the point envs, whose move is action / 20, the
    default r (the env's one-step reach) makes u a uniform action in the action box. The env labels each move
    (:func:`label_moves`); the energy is the score of "infeasible". The env is reset many times: pass one that
    nothing else is stepping.

    :param agent: an agent with an ``energy_model`` (e.g. :class:`~ebm_agent.agent.EBMPlannerAgent`), or an energy
        module / callable E(states [..., D], next_states [..., D]) -> [...].
    :param env: a gymnasium env that can label feasibility (:func:`can_label_feasibility`), not a VecEnv.
    :param n_moves: number of (state, move) samples.
    :param near: [M, D] states (e.g. an online agent's replay buffer); None draws uniform valid states.
    :param near_radius: half-width of the box around a ``near`` state a probe state is drawn from (default: the move
        radius, i.e. one step away from the data).
    :param move_radius: [D] or scalar half-width of the move box; default: the env's one-step reach, measured as the
        largest |s' - s| of the action box's low and high corner actions from a few valid states.
    :param seed: seeds the states and moves.
    :return: the AUROC and the class counts.
    :raises ValueError: when the env cannot label feasibility.
    """
    _check_positive_int(n_moves, "n_moves")
    if not can_label_feasibility(env):
        raise ValueError(
            "feasibility_auroc: the env cannot label feasibility: it needs finite state_low/state_high, "
            "inverse_dynamics and a reset(options={'start': s}) (the point envs: particle, maze)."
        )
    rng = np.random.default_rng(seed)
    radius = measure_reach(env, rng) if move_radius is None else _as_dims(move_radius, _state_dim(env), "move_radius")
    if near is not None:
        near = np.asarray(near, dtype=np.float32)
        near_radius = radius if near_radius is None else near_radius
    states = sample_valid_states(env, n_moves, rng, near=near, near_radius=near_radius)  # [N, D]
    moves = rng.uniform(-1.0, 1.0, size=states.shape) * radius  # [N, D]
    next_states = (states + moves).astype(np.float32)  # [N, D]
    feasible = label_moves(env, states, next_states)  # [N]
    energies = transition_energies(agent, states, next_states)  # [N]
    infeasible = ~feasible
    return FeasibilityResult(
        auroc=auroc(energies, infeasible),
        num_feasible=int(feasible.sum()),
        num_infeasible=int(infeasible.sum()),
        mean_energy_feasible=float(energies[feasible].mean()) if feasible.any() else float("nan"),
        mean_energy_infeasible=float(energies[infeasible].mean()) if infeasible.any() else float("nan"),
        move_radius=radius,
    )


def next_state_rank(
    agent: Any,
    transitions: TransitionDataset | tuple[np.ndarray, np.ndarray],
    n_candidates: int = 64,
    scale: float = 1.0,
    seed: int = 0,
) -> NextStateRankResult:
    """How often the real next state has the lowest energy among perturbed candidates, on held-out transitions.

    Candidates are s' + N(0, sigma^2) per dim with sigma = ``scale`` * std(s' - s) over the given transitions
    (periodic dims of the energy wrapped first). Tying the noise to the size of a real step makes the measure
    comparable across envs; a dim that never moves (a target the energy masks) gets no noise. Note that where the
    env can reach a whole neighbourhood of s (the point envs) some candidates are themselves reachable, and an
    energy fitted to a random policy rightly gives them the same low energy: there even a perfect model's top-1
    stays below 1 unless ``scale`` is large.

    :param agent: an agent with an ``energy_model``, or an energy module / callable (as :func:`feasibility_auroc`).
    :param transitions: held-out real transitions, a :class:`TransitionDataset` or (states [N, D], next_states [N, D]).
    :param n_candidates: K perturbed candidates per transition (64).
    :param scale: noise standard deviation as a multiple of the per-dim std of s' - s (1.0).
    :param seed: seeds the noise.
    :return: top-1 rate, mean normalised rank and chance level.
    :raises ValueError: for bad shapes, fewer than two transitions or a non-positive scale.
    """
    if isinstance(transitions, TransitionDataset):
        states, next_states = transitions.states, transitions.next_states
    else:
        states, next_states = (np.asarray(array, dtype=np.float32) for array in transitions)
    if states.ndim != 2 or next_states.shape != states.shape or len(states) < 2:
        raise ValueError(
            f"next_state_rank: expected states and next_states of the same shape [N >= 2, D], got {states.shape} and "
            f"{next_states.shape}."
        )
    _check_positive_int(n_candidates, "n_candidates")
    if not scale > 0:
        raise ValueError(f"next_state_rank: scale must be > 0, got {scale!r}.")
    steps = next_states.astype(np.float64) - states  # [N, D]
    features = getattr(energy_function(agent), "features", None)
    if features is not None:  # periodic dims: the step across the wrap is the short way round
        dims, period = list(features.dims), features.period
        steps[:, dims] = wrap_array(steps[:, dims], period)
    noise_std = scale * steps.std(axis=0)  # [D]
    rng = np.random.default_rng(seed)
    num, dim = states.shape
    candidates = next_states[:, None, :] + rng.standard_normal((num, n_candidates, dim)) * noise_std  # [N, K, D]
    pairs_next = np.concatenate([next_states[:, None, :], candidates.astype(np.float32)], axis=1)  # [N, 1 + K, D]
    pairs_states = np.broadcast_to(states[:, None, :], pairs_next.shape)  # [N, 1 + K, D]
    energies = transition_energies(agent, pairs_states.reshape(-1, dim), pairs_next.reshape(-1, dim)).reshape(
        num, -1
    )  # [N, 1+K]
    real, others = energies[:, :1], energies[:, 1:]  # [N, 1], [N, K]
    lower = (others < real).sum(axis=1)  # [N]
    ties = (others == real).sum(axis=1)  # [N]
    top1 = np.where(lower == 0, 1.0 / (1.0 + ties), 0.0)  # [N]
    return NextStateRankResult(
        top1=float(top1.mean()),
        mean_rank=float(((lower + 0.5 * ties) / n_candidates).mean()),
        chance=1.0 / (n_candidates + 1),
        num_transitions=num,
        num_candidates=n_candidates,
        noise_std=noise_std,
    )


def model_quality(
    agent: Any,
    env: gym.Env,
    held_out: TransitionDataset,
    n_moves: int = 2000,
    n_candidates: int = 64,
    scale: float = 1.0,
    seed: int = 0,
) -> tuple[dict[str, float], FeasibilityResult | None, NextStateRankResult]:
    """Both measures at once, as :class:`~ebm_agent.callbacks.ModelProbeCallback` logs them and the harness records
    them at the end of a run.

    The feasibility AUROC is taken near the states of the agent's real-transition buffer (``pos_buffer``) when it
    holds data (an online agent: the states it visited), else over uniform valid states; the uniform one always.

    :param agent: an agent with an ``energy_model``.
    :param env: a gymnasium env of the agent's task that nothing else steps.
    :param held_out: held-out real transitions of the next-state rank.
    :param n_moves: (state, move) samples of each feasibility AUROC.
    :param n_candidates: perturbed candidates per transition of the rank.
    :param scale: candidate noise, in std(s' - s).
    :param seed: seeds the probe.
    :return: (values by key: ``next_state_rank``, ``next_state_mean_rank`` and, where the env labels moves,
        ``feasibility_auroc`` and ``feasibility_auroc_uniform``; the feasibility result or None; the rank result).
    """
    rank = next_state_rank(agent, held_out, n_candidates, scale, seed=seed)
    values = {"next_state_rank": rank.top1, "next_state_mean_rank": rank.mean_rank}
    if not can_label_feasibility(env):
        return values, None, rank
    uniform = feasibility_auroc(agent, env, n_moves, seed=seed)
    near = buffer_states(agent, n_moves, np.random.default_rng(seed))
    feasibility = uniform if near is None else feasibility_auroc(agent, env, n_moves, near=near, seed=seed)
    values.update({"feasibility_auroc": feasibility.auroc, "feasibility_auroc_uniform": uniform.auroc})
    return values, feasibility, rank


def buffer_states(agent: Any, count: int, rng: np.random.Generator) -> np.ndarray | None:
    """Up to ``count`` states of the agent's real-transition buffer, read by index (its own generator is untouched).

    :param agent: an agent, with or without a ``pos_buffer``.
    :param count: the most states returned.
    :param rng: draws which.
    :return: [M, D] states, or None when the agent has no buffer or it is empty.
    """
    buffer = getattr(agent, "pos_buffer", None)
    if buffer is None or len(buffer) == 0:
        return None
    indices = rng.choice(len(buffer), size=min(len(buffer), count), replace=False)  # [M]
    return np.asarray(buffer.get(indices).states)


def can_label_feasibility(env: gym.Env) -> bool:
    """Whether :func:`label_moves` works on this env: finite ``state_low``/``state_high`` (the env contract),
    ``inverse_dynamics``, and a ``reset`` that accepts ``options={"start": s}``.

    Tried with a reset at the env's own start (so the env is reset once).

    :param env: a gymnasium env (not a VecEnv).
    :return: True for the point envs (particle, maze), False e.g. for Reacher.
    """
    unwrapped = getattr(env, "unwrapped", None)
    low, high = getattr(unwrapped, "state_low", None), getattr(unwrapped, "state_high", None)
    if low is None or high is None or not callable(getattr(unwrapped, "inverse_dynamics", None)):
        return False
    if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
        return False
    try:
        observation, _ = env.reset()
        env.reset(options={"start": _state_of(observation)})
    except (ValueError, TypeError, KeyError):
        return False
    return True


def sample_valid_states(
    env: gym.Env,
    num: int,
    rng: np.random.Generator,
    near: np.ndarray | None = None,
    near_radius: float | np.ndarray | None = None,
    max_tries: int = 100,
) -> np.ndarray:
    """States the env accepts as a start: uniform over its valid states, or uniform in boxes around ``near`` states.

    Candidates are drawn uniformly in ``[state_low, state_high]`` (or ``near[i] + U(-near_radius, near_radius)``
    clipped to it) and kept when ``env.reset(options={"start": s})`` accepts them, so validity is the env's own.

    :param env: an env that can label feasibility.
    :param num: N states wanted.
    :param rng: the generator of the candidates.
    :param near: [M, D] states to draw around, or None for uniform states.
    :param near_radius: half-width (scalar or [D]) of the box around a ``near`` state; required with ``near``.
    :param max_tries: rounds of N candidates before giving up.
    :return: [N, D] float32 valid states.
    :raises RuntimeError: when too few candidates are valid.
    """
    unwrapped = env.unwrapped
    low = np.asarray(unwrapped.state_low, dtype=np.float64)  # type: ignore[attr-defined]
    high = np.asarray(unwrapped.state_high, dtype=np.float64)  # type: ignore[attr-defined]
    if near is not None and (near_radius is None or len(near) == 0):
        raise ValueError("sample_valid_states: near needs a non-empty [M, D] array and a near_radius.")
    half_width = np.zeros(low.size) if near_radius is None else np.broadcast_to(np.asarray(near_radius, np.float64), low.shape)
    kept: list[np.ndarray] = []
    for _ in range(max_tries):
        if near is None:
            candidates = rng.uniform(low, high, size=(num, low.size))  # [N, D]
        else:
            centres = near[rng.integers(0, len(near), size=num)]  # [N, D]
            candidates = np.clip(centres + rng.uniform(-1.0, 1.0, size=centres.shape) * half_width, low, high)
        for state in candidates.astype(np.float32):
            if _accepts_start(env, state):
                kept.append(state)
                if len(kept) == num:
                    return np.stack(kept)
    raise RuntimeError(f"sample_valid_states: only {len(kept)} of {num} candidate states were valid after {max_tries} rounds.")


def label_moves(env: gym.Env, states: np.ndarray, next_states: np.ndarray) -> np.ndarray:
    """Which moves the env makes: set to s, step with its ``inverse_dynamics(s, s')``, compare where it lands with s'.

    A move the env rejects (into a wall, across the obstacle) leaves it at s; one out of the state box is clipped:
    both are infeasible. Uses only the env's public API (``reset(options={"start": s})``, ``step``).

    :param env: an env that can label feasibility.
    :param states: [N, D] valid states.
    :param next_states: [N, D] proposed next states.
    :return: [N] bool, True where the env landed within ``LABEL_TOLERANCE`` of s' in every dim.
    """
    actions = np.asarray(env.unwrapped.inverse_dynamics(states, next_states), dtype=np.float32)  # type: ignore[attr-defined]
    feasible = np.empty(len(states), dtype=bool)
    for index, (state, action) in enumerate(zip(states, actions, strict=True)):
        env.reset(options={"start": state})
        observation, *_ = env.step(action)
        feasible[index] = bool(np.all(np.abs(_state_of(observation) - next_states[index]) <= LABEL_TOLERANCE))
    return feasible


def measure_reach(env: gym.Env, rng: np.random.Generator, num_states: int = 32) -> np.ndarray:
    """The env's one-step reach per dim: the largest |s' - s| of the action box's two extreme actions.

    :param env: an env that can label feasibility.
    :param rng: the generator of the valid states stepped from.
    :param num_states: states to step from (rejected moves give 0, so several are needed).
    :return: [D] float64 reach (0.05 per dim for the point envs).
    """
    space = env.action_space
    assert isinstance(space, gym.spaces.Box)
    reach = np.zeros(_state_dim(env))
    for state in sample_valid_states(env, num_states, rng):
        for action in (space.low, space.high):
            env.reset(options={"start": state})
            observation, *_ = env.step(np.asarray(action, dtype=np.float32))
            reach = np.maximum(reach, np.abs(_state_of(observation) - state))
    if not np.all(reach > 0):
        raise RuntimeError(f"measure_reach: the extreme actions did not move every dim ({reach}); pass move_radius.")
    return reach


# ------------------------------------------------------------------------------------------------------------ helpers
def _accepts_start(env: gym.Env, state: np.ndarray) -> bool:
    try:
        env.reset(options={"start": state})
    except ValueError:
        return False
    return True


def _state_of(observation: Any) -> np.ndarray:
    if isinstance(observation, dict):
        observation = observation["observation"]
    return np.asarray(observation, dtype=np.float32).reshape(-1)


def _state_dim(env: gym.Env) -> int:
    return int(np.asarray(env.unwrapped.state_low).size)  # type: ignore[attr-defined]


def _as_dims(value: float | np.ndarray, dim: int, name: str) -> np.ndarray:
    array = np.broadcast_to(np.asarray(value, dtype=np.float64), (dim,)).copy()
    if not np.all(array > 0):
        raise ValueError(f"{name} must be > 0 in every dim, got {value!r}.")
    return array


def _check_positive_int(value: Any, name: str) -> None:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"{name} must be a positive int, got {value!r}.")


def _draw_maps(agent: Any, env: gym.Env, held_out: TransitionDataset, path: str) -> None:
    """Write :func:`~ebm_agent.visualize.energy_maps_figure` of the agent's energy over the env's 2-D state box.

    :param agent: the agent.
    :param env: its env (``state_low`` / ``state_high`` give the box).
    :param held_out: real transitions (their largest per-dim change is the one-step move probed).
    :param path: the PNG to write.
    :raises ValueError: for an env whose states are not 2-D or have no finite box.
    """
    from ebm_agent.visualize import energy_maps_figure  # matplotlib only for the map

    base = env.unwrapped
    low, high = getattr(base, "state_low", None), getattr(base, "state_high", None)
    if low is None or high is None or np.asarray(low).shape != (2,) or not np.all(np.isfinite([low, high])):
        raise ValueError("--map draws 2-D state spaces with a finite state_low/state_high box (the particle, the maze).")
    step = np.abs(held_out.next_states - held_out.states).max(axis=0)  # [2]
    figure = energy_maps_figure(agent.energy_model, np.asarray(low), np.asarray(high), step)
    figure.savefig(path, dpi=100)
    import matplotlib.pyplot as plt

    plt.close(figure)
    print(f"energy maps written to {path}")


def main(argv: list[str] | None = None) -> tuple[FeasibilityResult | None, NextStateRankResult]:
    """Probe a saved :class:`~ebm_agent.agent.EBMPlannerAgent`: ``python -m ebm_agent.probe model.zip ENV_ID``.

    :param argv: the arguments (default: the command line's).
    :return: the feasibility result (None where the env cannot label moves) and the next-state rank.
    """
    parser = argparse.ArgumentParser(description="Model-quality probe of a saved EBMPlannerAgent (issue #34).")
    parser.add_argument("model", help="the saved agent (.zip)")
    parser.add_argument("env", help="a Gymnasium id, e.g. envs:ebm/Maze-v0 (the envs: prefix registers the project's)")
    parser.add_argument("--moves", type=int, default=4000, help="(state, move) samples of the feasibility AUROC")
    parser.add_argument("--transitions", type=int, default=2000, help="held-out random transitions of the rank")
    parser.add_argument("--candidates", type=int, default=64, help="perturbed candidates per transition")
    parser.add_argument("--scale", type=float, default=1.0, help="candidate noise, in std(s' - s)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--map",
        metavar="PNG",
        help="also draw the energy over a 2-D state space to this file: a small move centred at each state, and the "
        "highest energy of a one-step move from each state (the walls' edges, where moves are refused)",
    )
    args = parser.parse_args(argv)
    torch.set_num_threads(1)

    env = gym.make(args.env)
    agent = EBMPlannerAgent.load(args.model, env=env, device="cpu")
    feasibility = feasibility_auroc(agent, env, args.moves, seed=args.seed) if can_label_feasibility(env) else None
    if feasibility is not None:
        print(
            f"feasibility AUROC {feasibility.auroc:.4f} over {args.moves} moves "
            f"({feasibility.num_infeasible} infeasible, {feasibility.num_feasible} feasible)"
        )
    held_out = collect_random_transitions(env, args.transitions, seed=args.seed + 10_000)
    if args.map is not None:
        _draw_maps(agent, env, held_out, args.map)
    rank = next_state_rank(agent, held_out, args.candidates, args.scale, seed=args.seed)
    print(
        f"next-state top-1 {rank.top1:.4f} (chance {rank.chance:.4f}), mean rank {rank.mean_rank:.4f} "
        f"over {rank.num_transitions} held-out transitions x {rank.num_candidates} candidates"
    )
    return feasibility, rank


if __name__ == "__main__":
    main()
