"""Maximum-entropy planning figures (paper Sec. 4.3): plan diversity vs horizon, and Reacher plans going both ways.

Both sample many plans from one start to one goal with an EBM pretrained on random transitions (the paper's
"pretrained" setting: 100k transitions at paper scale): ``count`` copies of the start are planned in one MPPI batch,
each copy with its own noise, so each is an independent draw from the planner.

- ``plan_diversity`` (Fig. "effects of varying number of planning steps"): particle, (0, 0) to (0.5, 0.5), the goal
  as paper Eq. 6's Gaussian on the final state (the reward-form goal would pull every state to the goal and hide the
  freedom a longer horizon gives). The envelope is measured as the area of grid cells the plans pass through, the
  largest sideways deviation from the start-goal line, and the mean distance between plans.
- ``reacher_directions`` (Fig. "two different planned trajectories"): Reacher, the agent's own goal energy; each plan
  is classified by the sign of the total change of the shoulder angle (counter-clockwise = increasing angle, seen
  from above), then executed closed-loop with ground-truth inverse dynamics to check the real arm turns the same way.
  Main case: a goal half a turn away at the shoulder, so both ways are equally long; second case: the env's goal.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import matplotlib.pyplot as plt
import numpy as np
import torch

from ebm_agent import EBMPlannerAgent, GaussianGoalEnergy, MPPIConfig, MPPIPlanner, PlanCost
from ebm_agent.agent import GOAL_ENERGIES
from ebm_agent.costs import AccelerationPrior, GoalEnergy
from envs.reacher import fingertip_position, wrap_difference, wrapped_l1_distance
from eval.paper.figures.common import (
    FigureResult,
    finish,
    markdown_table,
    prepare,
    pretrained_ebm,
    save_png,
    summary,
)

DIVERSITY_START = (0.0, 0.0)
DIVERSITY_GOAL = (0.5, 0.5)
ENVELOPE_CELL = 0.02
"""Side of the grid cells whose union measures the plans' envelope."""

DIVERSITY_METRICS = ("envelope_area", "lateral_deviation", "pairwise_distance", "goal_distance", "feasible_fraction")


def sample_plans(
    agent: EBMPlannerAgent,
    start: np.ndarray,
    goal: np.ndarray,
    horizon: int,
    count: int,
    seed: int,
    goal_energy: GoalEnergy | None = None,
) -> np.ndarray:
    """Draw ``count`` independent MPPI plans from one start to one goal under the agent's energy.

    :param agent: a trained EBM agent (its planner settings, acceleration prior and state bounds are used).
    :param start: [D] start state.
    :param goal: [G] goal.
    :param horizon: T, planned transitions.
    :param count: P, plans drawn (one batch: each row gets its own noise).
    :param seed: seed of the planner's noise.
    :param goal_energy: the goal term; None uses the agent's own (``CostConfig``).
    :return: plans [P, T+1, D].
    """
    spec, config = agent.goal_spec, agent.planner_config
    assert spec is not None
    if not isinstance(config, MPPIConfig):
        raise TypeError(f"sample_plans needs an MPPI agent, got planner config {type(config).__name__}")
    planner = MPPIPlanner(
        dataclasses.replace(config, horizon=horizon), spec.state_dim, spec.state_low, spec.state_high, device=agent.device
    )
    costs = agent.cost_config
    if goal_energy is None:
        goal_energy = GOAL_ENERGIES[costs.goal_energy](
            spec.goal_indices.tolist(), weight=costs.goal_weight, period=spec.goal_period
        )
    priors = [AccelerationPrior(costs.acceleration_weight, dims=spec.model_dims.tolist())] if costs.acceleration_weight else []
    cost = PlanCost(agent.energy_model, goal_energy, priors)
    as_batch = lambda x: torch.as_tensor(np.tile(np.asarray(x, np.float32), (count, 1)), device=agent.device)  # noqa: E731
    generator = torch.Generator(device=agent.device)
    generator.manual_seed(seed)
    result = planner.plan(as_batch(start), as_batch(goal), cost, generator=generator)
    return result.plans.cpu().numpy().astype(np.float64)  # [P, T+1, D]


def plan_diversity(out_dir: Path, *, seeds: Sequence[int], scale: str = "paper", goal_weight: float = 100.0) -> FigureResult:
    """The spread of sampled particle plans for several planning horizons.

    :param out_dir: folder of the PNGs and ``figure.json``.
    :param seeds: one pretrained EBM per seed.
    :param scale: ``"paper"`` or ``"smoke"``.
    :param goal_weight: weight of the Gaussian final-state goal (paper Eq. 6).
    :return: the result; ``metrics["horizons"][str(T)][metric]`` holds mean/std over seeds of each envelope measure.
    """
    out_dir, seeds, budget = prepare(out_dir, seeds, scale)
    start, goal = np.asarray(DIVERSITY_START), np.asarray(DIVERSITY_GOAL)
    per_seed: dict[int, dict[str, list[float]]] = {h: {m: [] for m in DIVERSITY_METRICS} for h in budget.diversity_horizons}
    drawn: dict[int, np.ndarray] = {}
    for seed in seeds:
        agent = pretrained_ebm("ebm/Particle-v0", seed, budget)
        for horizon in budget.diversity_horizons:
            energy = GaussianGoalEnergy([0, 1], weight=goal_weight)
            plans = sample_plans(agent, start, goal, horizon, budget.plan_samples, seed, goal_energy=energy)
            for name, value in envelope_measures(plans, start, goal).items():
                per_seed[horizon][name].append(value)
            drawn.setdefault(horizon, plans)
    metrics: dict[str, Any] = {
        "start": list(DIVERSITY_START),
        "goal": list(DIVERSITY_GOAL),
        "seeds": seeds,
        "goal_energy": f"gaussian (paper Eq. 6), weight {goal_weight}",
        "pretrain_transitions": budget.pretrain_transitions,
        "plans_per_horizon": budget.plan_samples,
        "horizons": {str(h): {m: {**summary(v), "per_seed": v} for m, v in values.items()} for h, values in per_seed.items()},
    }
    pngs = [
        _plot_plans(drawn, out_dir / "plan_diversity_plans.png"),
        _plot_envelope(metrics, out_dir / "plan_diversity_envelope.png"),
    ]
    rows = [
        [
            h,
            *(
                f"{metrics['horizons'][str(h)][m]['mean']:.3f} ± {metrics['horizons'][str(h)][m]['std']:.3f}"
                for m in DIVERSITY_METRICS
            ),
        ]
        for h in budget.diversity_horizons
    ]
    table = markdown_table(["horizon T", *DIVERSITY_METRICS], rows)
    return finish("plan_diversity", out_dir, seeds, scale, pngs=pngs, metrics=metrics, table_md=table)


def envelope_measures(plans: np.ndarray, start: np.ndarray, goal: np.ndarray) -> dict[str, float]:
    """How spread out a set of 2-D plans from ``start`` to ``goal`` is.

    :param plans: [P, T+1, 2] plans.
    :param start: [2].
    :param goal: [2].
    :return: ``envelope_area`` (area of the ``ENVELOPE_CELL`` grid cells any plan passes through), ``lateral_deviation``
        (mean over plans of the largest distance from the start-goal line), ``pairwise_distance`` (mean over plan
        pairs and steps of the distance between them), ``goal_distance`` (mean L1 of the last state to the goal),
        ``feasible_fraction`` (planned moves within the particle's 0.05 per axis).
    """
    fractions = np.linspace(0.0, 1.0, 9)[:-1, None]  # [S, 1] points along each segment
    segments = plans[:, :-1, None, :] + fractions * (plans[:, 1:, None, :] - plans[:, :-1, None, :])  # [P, T, S, 2]
    points = np.concatenate([segments.reshape(-1, 2), plans[:, -1]])
    cells = np.unique(np.floor(points / ENVELOPE_CELL).astype(np.int64), axis=0)
    direction = (goal - start) / np.linalg.norm(goal - start)
    offsets = plans - start  # [P, T+1, 2]
    lateral = np.abs(offsets[..., 0] * direction[1] - offsets[..., 1] * direction[0])  # [P, T+1]
    count = len(plans)
    gaps = np.linalg.norm(plans[:, None] - plans[None, :], axis=-1).mean(-1)  # [P, P]
    pairwise = gaps.sum() / max(count * (count - 1), 1)
    steps = np.abs(np.diff(plans, axis=1)).max(-1)  # [P, T]
    return {
        "envelope_area": float(len(cells) * ENVELOPE_CELL**2),
        "lateral_deviation": float(lateral.max(1).mean()),
        "pairwise_distance": float(pairwise),
        "goal_distance": float(np.abs(plans[:, -1] - goal).sum(-1).mean()),
        "feasible_fraction": float((steps <= 0.05 + 1e-3).mean()),
    }


def reacher_directions(
    out_dir: Path, *, seeds: Sequence[int], scale: str = "paper", reach_tolerance: float = 0.2
) -> FigureResult:
    """Sample Reacher plans to a goal and count how many turn the shoulder each way; execute them to confirm.

    :param out_dir: folder of the PNGs and ``figure.json``.
    :param seeds: one pretrained EBM (and one start state) per seed.
    :param scale: ``"paper"`` or ``"smoke"``.
    :param reach_tolerance: wrapped L1 distance of the last planned angles to the goal under which a plan reaches it.
    :return: the result; ``metrics["cases"][case]`` holds the direction fractions and the execution agreement.
    """
    out_dir, seeds, budget = prepare(out_dir, seeds, scale)
    cases: dict[str, dict[str, list[float]]] = {}
    pictures: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = {}
    for seed in seeds:
        agent = pretrained_ebm("ebm/Reacher-v0", seed, budget)
        env = gym.make("ebm/Reacher-v0")
        observation, _ = env.reset(seed=seed)
        start = np.asarray(observation["observation"], dtype=np.float64)  # [4]
        goals = {
            "opposite": wrap_difference(start[:2] + np.array([1.0, 0.0])),  # half a turn at the shoulder
            "env_goal": np.asarray(observation["desired_goal"], dtype=np.float64),
        }
        for case, goal in goals.items():
            plans = sample_plans(agent, start, goal, budget.reacher_horizon, budget.plan_samples, seed)
            turns = shoulder_turn(plans[..., 0])  # [P]
            reached = wrapped_l1_distance(plans[:, -1, :2], goal) < reach_tolerance
            real_turns = np.array([shoulder_turn(_execute(env, seed, plan)[None, :, 0])[0] for plan in plans])
            record = cases.setdefault(case, {})
            for name, value in {
                "ccw_fraction": float((turns > 0).mean()),
                "cw_fraction": float((turns < 0).mean()),
                "reached_fraction": float(reached.mean()),
                "ccw_fraction_of_reached": float((turns[reached] > 0).mean()) if reached.any() else float("nan"),
                "executed_agreement": float((np.sign(real_turns) == np.sign(turns)).mean()),
                "mean_abs_turn": float(np.abs(turns).mean()),
            }.items():
                record.setdefault(name, []).append(value)
            if seed == seeds[0]:
                pictures[case] = (plans, turns, goal, start)
        env.close()
    metrics: dict[str, Any] = {
        "seeds": seeds,
        "horizon": budget.reacher_horizon,
        "plans_per_case": budget.plan_samples,
        "pretrain_transitions": budget.pretrain_transitions,
        "reach_tolerance": reach_tolerance,
        "direction": "sign of the total change of the shoulder angle (normalised, 1.0 = half a turn); + = counter-clockwise",
        "cases": {case: {name: _nan_summary(values) for name, values in record.items()} for case, record in cases.items()},
    }
    for record in metrics["cases"].values():
        record["both_directions"] = record["ccw_fraction"]["mean"] > 0 and record["cw_fraction"]["mean"] > 0
    pngs = [_plot_reacher(*pictures[case], out_dir / f"reacher_plans_{case}.png", case) for case in pictures]
    names = ["ccw_fraction", "cw_fraction", "reached_fraction", "executed_agreement", "mean_abs_turn"]
    rows = [[case, *(metrics["cases"][case][n]["mean"] for n in names)] for case in metrics["cases"]]
    table = markdown_table(["goal", *names], rows)
    return finish("reacher_directions", out_dir, seeds, scale, pngs=pngs, metrics=metrics, table_md=table)


def shoulder_turn(angles: np.ndarray) -> np.ndarray:
    """Total signed change of normalised angles along each trajectory, the short way round at each step.

    :param angles: [P, T+1] normalised angles (period 2).
    :return: [P] total change (+ = counter-clockwise).
    """
    return wrap_difference(np.diff(angles, axis=1)).sum(axis=1)


def _execute(env: gym.Env, seed: int, plan: np.ndarray) -> np.ndarray:
    """Follow a plan closed-loop (action from the real state to the next planned one) from the seed's start.

    :return: the real states [k+1, D].
    """
    observation, _ = env.reset(seed=seed)
    states = [np.asarray(observation["observation"], dtype=np.float64)]
    for target in plan[1:]:
        action = env.unwrapped.inverse_dynamics(states[-1], target)  # type: ignore[attr-defined]
        observation, _, terminated, truncated, _ = env.step(action)
        states.append(np.asarray(observation["observation"], dtype=np.float64))
        if terminated or truncated:
            break
    return np.stack(states)


def _nan_summary(values: list[float]) -> dict[str, Any]:
    finite = [v for v in values if np.isfinite(v)]
    return {**(summary(finite) if finite else {"mean": None, "std": None}), "per_seed": values}


def _plot_plans(drawn: dict[int, np.ndarray], path: Path) -> Path:
    figure, axes = plt.subplots(1, len(drawn), figsize=(4 * len(drawn), 4), squeeze=False)
    for axis, (horizon, plans) in zip(axes[0], sorted(drawn.items())):
        for plan in plans:
            axis.plot(plan[:, 0], plan[:, 1], "-", linewidth=0.8, alpha=0.6)
        axis.plot(*DIVERSITY_START, "ks", markersize=6)
        axis.plot(*DIVERSITY_GOAL, "*", color="gold", markeredgecolor="k", markersize=14)
        axis.set_xlim(-1, 1)
        axis.set_ylim(-1, 1)
        axis.set_aspect("equal")
        axis.grid(alpha=0.3)
        axis.set_title(f"T = {horizon}: {len(plans)} sampled plans")
    return save_png(figure, path)


def _plot_envelope(metrics: dict[str, Any], path: Path) -> Path:
    horizons = sorted(int(h) for h in metrics["horizons"])
    figure, axes = plt.subplots(1, 2, figsize=(8, 3.5))
    for axis, name in zip(axes, ("envelope_area", "lateral_deviation")):
        values = [metrics["horizons"][str(h)][name] for h in horizons]
        axis.errorbar(horizons, [v["mean"] for v in values], yerr=[v["std"] for v in values], marker="o", capsize=3)
        axis.set_xlabel("planning horizon T")
        axis.set_ylabel(name.replace("_", " "))
        axis.grid(alpha=0.3)
    figure.suptitle(f"Envelope of sampled plans ({len(metrics['seeds'])} seeds, mean ± std)")
    return save_png(figure, path)


def _plot_reacher(plans: np.ndarray, turns: np.ndarray, goal: np.ndarray, start: np.ndarray, path: Path, case: str) -> Path:
    figure, (angle_axis, tip_axis) = plt.subplots(1, 2, figsize=(9, 4))
    steps = np.arange(plans.shape[1])
    cumulative = np.concatenate([np.zeros((len(plans), 1)), np.cumsum(wrap_difference(np.diff(plans[..., 0], axis=1)), 1)], 1)
    tips = fingertip_position(plans[..., :2])  # [P, T+1, 2]
    for plan_turn, path_angles, tip in zip(turns, cumulative, tips):
        color = "tab:blue" if plan_turn > 0 else "tab:orange"
        angle_axis.plot(steps, path_angles, color=color, alpha=0.5, linewidth=0.8)
        tip_axis.plot(tip[:, 0], tip[:, 1], color=color, alpha=0.5, linewidth=0.8)
    goal_turn = float(wrap_difference(goal[0] - start[0]))
    for level in {goal_turn, goal_turn - 2.0 if goal_turn > 0 else goal_turn + 2.0}:
        angle_axis.axhline(level, color="k", linestyle="--", linewidth=0.8)
    angle_axis.set_xlabel("plan step")
    angle_axis.set_ylabel("shoulder angle change (1.0 = half a turn)")
    angle_axis.set_title(f"blue: counter-clockwise ({(turns > 0).mean():.0%}), orange: clockwise")
    tip_axis.add_patch(plt.Circle((0, 0), 0.21, fill=False, color="0.7"))
    tip_axis.plot(*fingertip_position(start[:2]), "ks", markersize=6)
    tip_axis.plot(*fingertip_position(goal), "*", color="gold", markeredgecolor="k", markersize=14)
    tip_axis.set_aspect("equal")
    tip_axis.set_xlim(-0.25, 0.25)
    tip_axis.set_ylim(-0.25, 0.25)
    tip_axis.set_title(f"fingertip paths of the plans (goal: {case})")
    return save_png(figure, path)


__all__ = ["envelope_measures", "plan_diversity", "reacher_directions", "sample_plans", "shoulder_turn"]
