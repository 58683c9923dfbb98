"""Plan time of the agent's MPPI planner next to pytorch-mppi: the plan, chunk, quality and compile sections.

These are the plan sections of ``python -m benchmarks`` (:mod:`benchmarks.cli`, ``make bench``).

What is timed for pytorch-mppi (0.9): ``MPPI.command(state, shift_nominal_trajectory=False)`` is one MPPI
iteration (sample K x T action noise, roll out T sequential calls of the learned dynamics on [K, D + D], add the
running costs, re-weight), so one plan is I such calls on a controller made beforehand. Its dynamics is
``s' = s + MLP(concat(s, a))`` with the same 3 x 128 LeakyReLU MLP as our energy (input 2D, output D instead of 1),
actions of dim D, the running cost a quadratic ``|s' - g|^2 + 0.1 |a|^2``; both run under ``torch.inference_mode``.
Ours scores the K x T transitions of a state plan with the energy in one batched call instead of T sequential ones.
"""

from __future__ import annotations

import importlib.metadata
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor, nn

from ebm_agent.costs import GaussianGoalEnergy, PlanCost
from ebm_agent.energy import EnergyModel
from ebm_agent.mppi import MPPIConfig, MPPIPlanner
from ebm_agent.networks import build_mlp

__all__ = [
    "COMPILE_CASE",
    "DEFAULT_CASE",
    "ENV_ID",
    "FULL_GRID",
    "QUICK_GRID",
    "PlanTiming",
    "bench_chunks",
    "bench_compile",
    "bench_plan",
    "bench_quality",
    "pytorch_mppi_version",
]

FULL_GRID = {"state_dims": (2, 4, 20), "samples": (64, 256, 1024), "horizons": (20, 80), "iterations": (10, 80)}
QUICK_GRID = {"state_dims": (2, 20), "samples": (64, 1024), "horizons": (20, 80), "iterations": (10,)}
DEFAULT_CASE = (2, 80, 10, 80)
"""The agent's own setting (D=2 particle, K=80, T=10, 80 iterations), always measured."""
COMPILE_CASE = (2, 256, 20, 10)
ENV_ID = "ebm/Particle-v0"


@dataclass
class PlanTiming:
    """
    Median milliseconds per plan of each variant for one problem size.

    :param device: where it ran.
    :param state_dim: D.
    :param num_samples: K.
    :param horizon: T.
    :param iterations: I.
    :param ours_ms: our planner in float32.
    :param ours_bf16_ms: our planner with ``autocast="bf16"``.
    :param theirs_ms: pytorch-mppi, or None when it is not installed.
    """

    device: str
    state_dim: int
    num_samples: int
    horizon: int
    iterations: int
    ours_ms: float
    ours_bf16_ms: float
    theirs_ms: float | None


def pytorch_mppi_version() -> str | None:
    """
    The installed pytorch-mppi version.

    :return: its version string, or None when the ``bench`` extra is not installed.
    """
    try:
        import pytorch_mppi  # noqa: F401
    except ImportError:
        return None
    return importlib.metadata.version("pytorch-mppi")


def _timed(fn: Callable[[], object], device: torch.device) -> float:
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    begin = time.perf_counter()
    fn()
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return 1000.0 * (time.perf_counter() - begin)


def _ours(
    state_dim: int, samples: int, horizon: int, iterations: int, device: torch.device, num_envs: int = 1, **options: object
):
    torch.manual_seed(0)
    energy = EnergyModel(state_dim).to(device)  # the paper's 3 x 128 LeakyReLU MLP
    cost = PlanCost(energy, GaussianGoalEnergy(tuple(range(state_dim))))
    config = MPPIConfig(horizon=horizon, num_samples=samples, iterations=iterations, **options)  # type: ignore[arg-type]
    planner = MPPIPlanner(config, state_dim, state_low=-torch.ones(state_dim), state_high=torch.ones(state_dim), device=device)
    start = torch.zeros(num_envs, state_dim, device=device)  # [N, D]
    goals = torch.full((num_envs, state_dim), 0.5, device=device)  # [N, D]
    generator = torch.Generator(device=device).manual_seed(0)
    return lambda: planner.plan(start, goals, cost, generator=generator)


class _Dynamics(nn.Module):
    """s' = s + MLP(concat(s, a)), the MLP the same size as our energy."""

    def __init__(self, state_dim: int) -> None:
        super().__init__()
        self.net = build_mlp(2 * state_dim, state_dim, hidden_dim=128, num_hidden_layers=3, activation="leaky_relu")

    def forward(self, states: Tensor, actions: Tensor) -> Tensor:
        return states + self.net(torch.cat([states, actions], dim=-1))


def _theirs(state_dim: int, samples: int, horizon: int, iterations: int, device: torch.device, num_envs: int = 1):
    from pytorch_mppi import MPPI

    torch.manual_seed(0)
    dynamics = _Dynamics(state_dim).to(device)
    goal = torch.full((state_dim,), 0.5, device=device)

    def running_cost(states: Tensor, actions: Tensor) -> Tensor:
        return (states - goal).square().sum(-1) + 0.1 * actions.square().sum(-1)

    common: dict[str, Any] = dict(
        nx=state_dim,
        noise_sigma=0.1 * torch.eye(state_dim, device=device),
        num_samples=samples,
        horizon=horizon,
        device=device,
        lambda_=1e-2,
        u_min=-torch.ones(state_dim, device=device),
        u_max=torch.ones(state_dim, device=device),
    )
    controller: Any
    if num_envs == 1:
        controller = MPPI(dynamics, running_cost, **common)
        state = torch.zeros(state_dim, device=device)  # [D]
    else:
        import pytorch_mppi

        if not hasattr(pytorch_mppi, "MPPI_Batched"):
            raise RuntimeError(
                f"--envs {num_envs} compares with pytorch-mppi's MPPI_Batched, which this pytorch-mppi "
                f"({pytorch_mppi_version()}) lacks: pip install 'pytorch-mppi>=0.9.1'."
            )
        # N envs in one dynamics call per step ([N*K, D] rows), pytorch-mppi's own batched controller.
        controller = pytorch_mppi.MPPI_Batched(dynamics, running_cost, num_envs=num_envs, **common)
        state = torch.zeros(num_envs, state_dim, device=device)  # [N, D]

    def plan() -> None:
        with torch.inference_mode():
            for _ in range(iterations):  # one MPPI iteration per command() without shifting the nominal plan
                controller.command(state, shift_nominal_trajectory=False)

    return plan


def _interleaved_medians(variants: dict[str, Callable[[], object]], device: torch.device, repeats: int) -> dict[str, float]:
    """Median ms of each variant over ``repeats`` rounds, one call of every variant per round, after one warm-up each."""
    times: dict[str, list[float]] = {name: [] for name in variants}
    for fn in variants.values():
        fn()  # warm-up: first-call allocations and kernel selection
    for _ in range(repeats):
        for name, fn in variants.items():
            times[name].append(_timed(fn, device))
    return {name: statistics.median(values) for name, values in times.items()}


def bench_plan(
    state_dim: int,
    samples: int,
    horizon: int,
    iterations: int,
    device: torch.device,
    repeats: int,
    compare: bool,
    num_envs: int = 1,
) -> PlanTiming:
    """
    Time one problem size: ours (float32 and bf16 autocast) and pytorch-mppi, interleaved, after one warm-up each.

    With ``num_envs`` N > 1 ours plans the N envs in one call and pytorch-mppi runs its ``MPPI_Batched``.

    :param state_dim: D.
    :param samples: K.
    :param horizon: T.
    :param iterations: I.
    :param device: the device to plan on.
    :param repeats: timed plans per variant; the median is kept.
    :param compare: also time pytorch-mppi.
    :param num_envs: N, the envs planned at once.
    :return: the median times (of one plan for all N envs).
    """
    variants = {
        "ours": _ours(state_dim, samples, horizon, iterations, device, num_envs, autocast=None),
        "bf16": _ours(state_dim, samples, horizon, iterations, device, num_envs, autocast="bf16"),
    }
    if compare:
        variants["theirs"] = _theirs(state_dim, samples, horizon, iterations, device, num_envs)
    medians = _interleaved_medians(variants, device, repeats)
    return PlanTiming(
        str(device), state_dim, samples, horizon, iterations, medians["ours"], medians["bf16"], medians.get("theirs")
    )


def bench_chunks(
    state_dim: int, samples: int, horizon: int, iterations: int, chunks: Sequence[int], repeats: int, compare: bool
) -> dict[str, float]:
    """
    Time one CPU problem size with several ``MPPIConfig.chunk_transitions``, interleaved (float32, one env).

    :param state_dim: D.
    :param samples: K.
    :param horizon: T.
    :param iterations: I.
    :param chunks: the chunk sizes (transitions per cost call; 0: no chunking).
    :param repeats: timed plans per variant; the median is kept.
    :param compare: also time pytorch-mppi (key ``"theirs"``).
    :return: median ms per plan, keyed by the chunk size as a string (and ``"theirs"``).
    """
    device = torch.device("cpu")
    variants = {str(c): _ours(state_dim, samples, horizon, iterations, device, chunk_transitions=c) for c in chunks}
    if compare:
        variants["theirs"] = _theirs(state_dim, samples, horizon, iterations, device)
    return _interleaved_medians(variants, device, repeats)


def _chunk_table(cases: Sequence[tuple[int, int, int, int]], chunks: Sequence[int], repeats: int, compare: bool) -> list[str]:
    names = [str(c) for c in chunks]
    header = "| D | K | T | iters | " + " | ".join(f"chunk {c} ms" for c in names) + " | pytorch-mppi ms | best chunk |"
    lines = [header, "|---" * (header.count("|") - 1) + "|"]
    for case in cases:
        medians = bench_chunks(*case, chunks=chunks, repeats=repeats, compare=compare)
        best = min(names, key=lambda name: medians[name])
        theirs = medians.get("theirs")
        cells = [f"{medians[name]:.1f}" + ("" if theirs is None else f" ({theirs / medians[name]:.2f}x)") for name in names]
        theirs_cell = "n/a" if theirs is None else f"{theirs:.1f}"
        lines.append(f"| {' | '.join(str(v) for v in case)} | {' | '.join(cells)} | {theirs_cell} | {best} |")
        print(lines[-1], flush=True)
    return lines


def bench_quality(problems: int) -> dict[str, float]:
    """
    How much bf16 planning changes plan quality, measured against the change from planning with another seed.

    The agent's own planner and cost on ``ebm/Particle-v0`` (untrained energy, reward goal, acceleration prior) plan
    from ``problems`` random starts to random goals three ways: float32, bf16 with the same generator seed, and float32
    with another seed; each plan is scored by the float32 cost.

    :param problems: the number of start/goal pairs.
    :return: {"bf16_mean", "bf16_std", "seed_mean", "seed_std", "bf16_worse"}: the mean and std over problems of the
        cost difference to the float32 plan, and the fraction of problems where bf16 was worse.
    """
    import copy

    import gymnasium as gym
    import numpy as np

    import envs  # noqa: F401  (registers ebm/Particle-v0)
    from ebm_agent import EBMPlannerAgent

    agent = EBMPlannerAgent("MultiInputPolicy", gym.make(ENV_ID), seed=0, device="cpu")
    base = agent.planner
    assert isinstance(base, MPPIPlanner)
    planners = {}
    for name, autocast in (("fp32", None), ("bf16", "bf16")):
        config = copy.copy(base.config)
        config.autocast = autocast
        planners[name] = MPPIPlanner(config, base.state_dim, base.state_low, base.state_high)
    rng = np.random.default_rng(0)
    costs: dict[str, list[float]] = {"fp32": [], "bf16": [], "seed": []}
    for problem in range(problems):
        start, goal = (torch.tensor(rng.uniform(-1.0, 1.0, (1, 2)), dtype=torch.float32) for _ in range(2))
        for name, planner, seed in (("fp32", "fp32", problem), ("bf16", "bf16", problem), ("seed", "fp32", problem + 10**6)):
            result = planners[planner].plan(start, goal, agent.plan_cost, generator=torch.Generator().manual_seed(seed))
            costs[name].append(float(result.costs[0]))
    fp32 = np.asarray(costs["fp32"])
    bf16, seed = np.asarray(costs["bf16"]) - fp32, np.asarray(costs["seed"]) - fp32
    return {
        "bf16_mean": float(bf16.mean()),
        "bf16_std": float(bf16.std()),
        "seed_mean": float(seed.mean()),
        "seed_std": float(seed.std()),
        "bf16_worse": float((bf16 > 0).mean()),
    }


def bench_compile(device: torch.device, repeats: int) -> dict[str, float]:
    """
    The compile option at ``COMPILE_CASE``: first plan (with compilation) and the median of later plans vs eager.

    :param device: the device to plan on.
    :param repeats: timed plans per variant.
    :return: {"first_ms", "compiled_ms", "eager_ms"}.
    """
    eager = _ours(*COMPILE_CASE, device)
    compiled = _ours(*COMPILE_CASE, device, compile=True)
    first = _timed(compiled, device)
    eager()
    times: dict[str, list[float]] = {"compiled_ms": [], "eager_ms": []}
    for _ in range(repeats):
        times["compiled_ms"].append(_timed(compiled, device))
        times["eager_ms"].append(_timed(eager, device))
    return {"first_ms": first, **{name: statistics.median(values) for name, values in times.items()}}


def _plan_table(rows: Sequence[PlanTiming], compare: bool) -> list[str]:
    header = (
        "| device | D | K | T | iters | ours fp32 ms | ours bf16 ms | pytorch-mppi ms | theirs / ours | theirs / ours bf16 |"
    )
    lines = [header, "|---" * (header.count("|") - 1) + "|"]
    for row in rows:
        theirs = "n/a" if row.theirs_ms is None else f"{row.theirs_ms:.1f}"
        ratio = "n/a" if row.theirs_ms is None else f"{row.theirs_ms / row.ours_ms:.2f}x"
        ratio_bf16 = "n/a" if row.theirs_ms is None else f"{row.theirs_ms / row.ours_bf16_ms:.2f}x"
        lines.append(
            f"| {row.device} | {row.state_dim} | {row.num_samples} | {row.horizon} | {row.iterations} | "
            f"{row.ours_ms:.1f} | {row.ours_bf16_ms:.1f} | {theirs} | {ratio} | {ratio_bf16} |"
        )
    if not compare:
        lines.append("")
        lines.append("pytorch-mppi is not installed (`pip install -e .[bench]`), so its columns are n/a.")
    return lines
