"""Planner and training speed: ``python -m eval.bench`` (``make bench``).

Prints markdown tables, all measured in the same run so that the ratios compare like with like on a loaded machine:

1. **Plan time**: ms per ``MPPIPlanner.plan`` (one env, or N in one plan with ``--envs N``) over a grid of state dims
   D, candidates K, horizons T and iterations I, in float32 and with ``autocast="bf16"``, next to ``pytorch_mppi.MPPI``
   (``MPPI_Batched`` for N > 1) on the equivalent problem and the ratio. The variants are timed interleaved, repeat
   by repeat, and the table shows medians. The agent's default precision is float32 (``autocast=None``), the
   first of the two.
2. **Plan quality in bf16** (``--quality N``): the float32 cost of N particle plans made in bf16 and in float32 with
   the same noise, next to float32 plans made with other noise: bf16 should move the cost less than a new seed does.
3. **torch.compile**: the first plan (compilation included) and the median of later plans for one configuration.
4. **learn throughput**: transitions per second and peak memory of ``EBMPlannerAgent.learn`` and SB3 ``PPO.learn``
   on ``ebm/Particle-v0``, each in its own subprocess.
5. **Roofline**: this host's float32 matmul peak, measured in the same run (``torch.mm`` of [M, 128] x [128, 128],
   the energy's hidden layer), the time of drawing each plan's I x N x K x T x D Gaussian numbers, the network FLOPs
   of each plan, and from them each plan's floor (matmuls at the peak + the draws: no planner that evaluates the same
   network on the same rows and draws the same noise is faster) and the best ``theirs / ours`` ratio a planner at that
   floor could reach against the pytorch-mppi time of this run. The learn section uses the peak too: the matmul time
   of the agent's plans at that peak.
6. **Chunk size** (``--chunks 1024 4096 ...``): ms per float32 plan with each ``MPPIConfig.chunk_transitions`` on
   the grid's problems larger than the smallest chunk, interleaved, next to pytorch-mppi (how
   ``ebm_agent.mppi.CPU_CHUNK_TRANSITIONS`` was chosen).

What is timed for pytorch-mppi (0.9): ``MPPI.command(state, shift_nominal_trajectory=False)`` is one MPPI
iteration (sample K x T action noise, roll out T sequential calls of the learned dynamics on [K, D + D], add the
running costs, re-weight), so one plan is I such calls on a controller made beforehand. Its dynamics is
``s' = s + MLP(concat(s, a))`` with the same 3 x 128 LeakyReLU MLP as our energy (input 2D, output D instead of 1),
actions of dim D, the running cost a quadratic ``|s' - g|^2 + 0.1 |a|^2``; both run under ``torch.inference_mode``.
Ours scores the K x T transitions of a state plan with the energy in one batched call instead of T sequential ones.
"""

from __future__ import annotations

import argparse
import datetime
import functools
import importlib.metadata
import json
import os
import platform
import resource
import shlex
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor, nn

from ebm_agent.costs import GaussianGoalEnergy, PlanCost
from ebm_agent.energy import EnergyModel
from ebm_agent.mppi import CPU_CHUNK_TRANSITIONS, MPPIConfig, MPPIPlanner, native_bf16
from ebm_agent.networks import build_mlp

__all__ = [
    "PlanTiming",
    "bench_chunks",
    "bench_learn",
    "bench_plan",
    "gaussian_draw_ms",
    "main",
    "matmul_peak_gflops",
    "mlp_flops_per_row",
    "plan_flops",
    "pytorch_mppi_version",
]

FULL_GRID = {"state_dims": (2, 4, 20), "samples": (64, 256, 1024), "horizons": (20, 80), "iterations": (10, 80)}
QUICK_GRID = {"state_dims": (2, 20), "samples": (64, 1024), "horizons": (20, 80), "iterations": (10,)}
DEFAULT_CASE = (2, 80, 10, 80)
"""The agent's own setting (D=2 particle, K=80, T=10, 80 iterations), always measured."""
COMPILE_CASE = (2, 256, 20, 10)
PEAK_ROWS = (1024, 4096, 16384)
"""Batch sizes of the matmul-peak probe; the best of them is the host's peak (a lower bound on any plan's time)."""
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


def mlp_flops_per_row(net: nn.Module) -> int:
    """
    Floating-point operations of one row through the ``nn.Linear`` layers of ``net`` (2 per multiply-add).

    Biases and activations are not counted: they are elementwise and far cheaper than the matmuls.

    :param net: a network, e.g. ``EnergyModel(D).net`` (in 2D -> 128 -> 128 -> 128 -> 1).
    :return: 2 x sum of in x out over its Linear layers.
    """
    return sum(2 * layer.in_features * layer.out_features for layer in net.modules() if isinstance(layer, nn.Linear))


def plan_flops(state_dim: int, samples: int, horizon: int, iterations: int, num_envs: int = 1) -> dict[str, int]:
    """
    Network FLOPs of one plan of each benchmarked planner (the networks are built here, as the benchmark builds them).

    Ours evaluates the energy on the N x K x T transitions of the candidates each iteration; pytorch-mppi evaluates
    its dynamics on the N x K rows of each of the T rolled-out steps. Both are the same 3 x 128 MLP, whose output layer
    has 1 column for ours and D for theirs.

    :param state_dim: D.
    :param samples: K.
    :param horizon: T.
    :param iterations: I.
    :param num_envs: N.
    :return: {"ours": FLOPs, "theirs": FLOPs} of the networks' matmuls in one plan.
    """
    rows = iterations * num_envs * samples * horizon
    with torch.device("meta"):  # shapes only: no weights allocated or initialised, torch's global RNG untouched
        energy, dynamics = EnergyModel(state_dim), _Dynamics(state_dim)
    return {"ours": rows * mlp_flops_per_row(energy.net), "theirs": rows * mlp_flops_per_row(dynamics.net)}


def matmul_peak_gflops(
    device: torch.device, repeats: int = 20, rows: Sequence[int] = PEAK_ROWS, width: int = 128
) -> dict[int, float]:
    """
    Float32 GFLOP/s of ``torch.mm`` on [M, width] x [width, width], the energy's hidden layer, for each M.

    The best of them is the host's matmul peak for this network: no plan that evaluates the network on the same rows
    can spend less than (its network FLOPs / that peak), since the thin first and last layers and every other op only
    add time. Timed after a warm-up, median of ``repeats`` calls per size.

    :param device: where to measure.
    :param repeats: timed calls per size.
    :param rows: the batch sizes M.
    :param width: the hidden width.
    :return: {M: GFLOP/s}.
    """
    generator = torch.Generator(device=device).manual_seed(0)
    weight = torch.randn(width, width, device=device, generator=generator)  # [h, h]
    peaks = {}
    with torch.inference_mode():
        for size in rows:
            inputs = torch.randn(size, width, device=device, generator=generator)  # [M, h]
            out = torch.empty(size, width, device=device)  # [M, h]
            for _ in range(3):
                torch.mm(inputs, weight, out=out)
            multiply = functools.partial(torch.mm, inputs, weight, out=out)
            ms = statistics.median(_timed(multiply, device) for _ in range(repeats))
            peaks[size] = 2 * size * width * width / (ms * 1e6)
    return peaks


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


LEARN_ENVS = ("ebm/Particle-v0", "ebm/Reacher-v0", "ebm/SawyerReach-v0")
"""The envs of the learn section's ratio table (the issue's targets: EBM and Action FF learn against PPO's)."""

LEARN_AGENTS = ("ebm", "action-ff", "ppo")
"""The agents of the learn section, by their ``eval.registry`` names."""


def learn_worker(
    agent: str, steps: int, threads: int, device: str = "cpu", env_id: str = ENV_ID, preset: str = "", n_envs: int = 1
) -> dict[str, float]:
    """
    Run one ``learn`` in this process and measure it (called in a subprocess by :func:`bench_learn`).

    :param agent: ``"ebm"``, ``"action-ff"`` or ``"ppo"`` (``baselines.ppo.make_ppo``: the tuned settings of the
        env, its own number of envs).
    :param steps: total_timesteps passed to ``learn``.
    :param threads: torch CPU threads.
    :param device: the torch device the agent trains on (``"cpu"`` or ``"cuda"``).
    :param env_id: the env.
    :param preset: the planning agents' preset (``ebm_agent.presets``; ``""``: the library's defaults).
    :param n_envs: envs of the planning agents' VecEnv (all planned in one batched call per step).
    :return: {"seconds", "cpu_seconds", "timesteps", "rss_before_mb", "rss_peak_mb", "gpu_peak_mb", "plans",
        "plan_gflop", "iterations"}; ``cpu_seconds`` is the process's CPU time during ``learn`` (with one torch thread,
        its wall time on an idle core, and much less sensitive than wall time to other processes on the machine);
        ``gpu_peak_mb`` is ``torch.cuda.max_memory_allocated`` on CUDA and 0 on the CPU; ``plans`` is
        the planning agent's number of plans, ``iterations`` the MPPI iterations they ran in all and ``plan_gflop``
        the EBM's network GFLOP of all of them (0 for PPO and Action FF).
    """
    from stable_baselines3.common.env_util import make_vec_env

    import envs  # noqa: F401  (registers the ebm/ ids)
    from ebm_agent.presets import preset_settings

    torch.set_num_threads(threads)
    model: Any
    if agent == "ppo":
        from baselines.ppo import make_ppo

        model = make_ppo(env_id, seed=0, device=device)
    elif agent in ("ebm", "action-ff"):
        from baselines.action_ff import ActionFFAgent
        from ebm_agent import EBMPlannerAgent

        agent_class = EBMPlannerAgent if agent == "ebm" else ActionFFAgent
        env = make_vec_env(env_id, n_envs=n_envs, seed=0)
        model = agent_class("MultiInputPolicy", env, seed=0, device=device, **preset_settings(preset, agent_class))
    else:
        raise ValueError(f"agent must be one of {LEARN_AGENTS}, got {agent!r}.")
    iterations: list[int] = []
    if agent != "ppo":
        plan = model.planner.plan

        def counted_plan(*args: Any, **kwargs: Any) -> Any:
            result = plan(*args, **kwargs)
            planned = getattr(result, "iterations", kwargs.get("iterations"))  # Action FF returns a tuple
            if planned is None:  # Action FF: its warm or its full budget
                config = model.planner.config
                warm = kwargs.get("init_actions") is not None and config.warm_iterations is not None
                planned = min(config.warm_iterations, config.iterations) if warm else config.iterations
            iterations.append(int(planned))
            return result

        model.planner.plan = counted_plan
    rss_before = _peak_rss_mb()
    begin, cpu_begin = time.perf_counter(), time.process_time()
    if agent == "ppo":
        from baselines.ppo import exact_budget_callback

        model.learn(steps, callback=exact_budget_callback(steps))  # whole rollouts would overshoot the budget
    else:
        model.learn(steps)
    seconds, cpu_seconds = time.perf_counter() - begin, time.process_time() - cpu_begin
    rss_peak = _peak_rss_mb()
    gpu_peak = torch.cuda.max_memory_allocated() / 2**20 if torch.device(device).type == "cuda" else 0.0
    plan_gflop = 0.0
    if agent == "ebm":
        config = model.planner_config
        rows = config.num_samples * config.horizon * n_envs * sum(iterations)  # K x T x N x I transitions (upper bound)
        plan_gflop = rows * mlp_flops_per_row(model.energy_model.net) / 1e9
    return {
        "plans": float(getattr(model, "num_plans", 0)),
        "iterations": float(sum(iterations)),
        "plan_gflop": plan_gflop,
        "seconds": seconds,
        "cpu_seconds": cpu_seconds,
        "timesteps": float(model.num_timesteps),
        "rss_before_mb": rss_before,
        "rss_peak_mb": rss_peak,
        "gpu_peak_mb": gpu_peak,
    }


def _peak_rss_mb() -> float:
    # VmHWM is this process's own high-water mark; ru_maxrss of a forked-and-exec'd child starts at the parent's
    # peak on Linux, which would hide the worker's own.
    try:
        with open("/proc/self/status") as status:
            return next(float(line.split()[1]) / 1024.0 for line in status if line.startswith("VmHWM:"))
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux


def bench_learn(
    steps: int,
    threads: int,
    device: str = "cpu",
    env_ids: Sequence[str] = LEARN_ENVS,
    agents: Sequence[str] = LEARN_AGENTS,
    preset: str = "",
    n_envs: Sequence[int] = (1,),
) -> dict[tuple[str, str, int], dict[str, float]]:
    """
    ``learn(steps)`` of each agent on each env, each in a fresh subprocess so that peak memory is its own.

    :param steps: total_timesteps of each.
    :param threads: torch CPU threads of each.
    :param device: the torch device they train on.
    :param env_ids: the envs.
    :param agents: agent names of :data:`LEARN_AGENTS`.
    :param preset: the planning agents' preset.
    :param n_envs: VecEnv sizes of the planning agents (PPO always runs its tuned number of envs once).
    :return: (env, agent, n_envs) -> what :func:`learn_worker` measured.
    """
    results = {}
    for env_id in env_ids:
        for agent in agents:
            for count in (1,) if agent == "ppo" else n_envs:
                command = [sys.executable, "-m", "eval.bench", "--learn-worker", agent, "--learn-steps", str(steps)]
                command += ["--threads", str(threads), "--learn-device", device, "--learn-envs", env_id]
                command += ["--learn-preset", preset, "--learn-n-envs", str(count)]
                done = subprocess.run(command, capture_output=True, text=True, check=False)
                if done.returncode != 0:
                    raise RuntimeError(f"the {agent} learn worker on {env_id} failed:\n{done.stderr[-3000:]}")
                results[(env_id, agent, count)] = json.loads(done.stdout.strip().splitlines()[-1])
    return results


def _machine() -> str:
    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as cpuinfo:
            model = next(line.split(":", 1)[1].strip() for line in cpuinfo if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    load = ", ".join(f"{value:.1f}" for value in os.getloadavg()) if hasattr(os, "getloadavg") else "n/a"
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return f"{model}, {cores} cores available, load average {load} at the start"


def _cuda_line() -> str:
    if not torch.cuda.is_available():
        return "not available (CPU rows only)"
    cuda = torch.version.cuda or "unknown"
    return f"{torch.cuda.get_device_name(0)} (CUDA {cuda}, {torch.cuda.device_count()} device(s))"


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


def gaussian_draw_ms(count: int, device: torch.device, repeats: int = 5) -> float:
    """
    Median ms of drawing ``count`` standard normal float32 numbers with a seeded ``torch.Generator``.

    Both planners draw I x N x K x T x D of them per plan (ours as STOMP's white noise, pytorch-mppi as its action
    noise), so this time is part of either's floor whatever the implementation around it.

    :param count: how many numbers.
    :param device: where to draw them.
    :param repeats: timed draws (after one warm-up).
    :return: the median time in ms.
    """
    generator = torch.Generator(device=device).manual_seed(0)
    out = torch.empty(count, device=device)
    out.normal_(generator=generator)
    return statistics.median(_timed(functools.partial(out.normal_, generator=generator), device) for _ in range(repeats))


def _roofline_table(
    rows: Sequence[PlanTiming], peaks: dict[str, float], num_envs: int, draws_ms: Sequence[float]
) -> list[str]:
    """Per timed problem: its network GFLOP, its floor (matmuls at the device's peak + the Gaussian draws), and the
    best ratio a planner at that floor could reach against pytorch-mppi's time (``draws_ms``: one per row)."""
    header = (
        "| device | D | K | T | iters | network GFLOP per plan (ours / theirs) | matmuls at peak ms | Gaussian draws ms | "
        "floor ms | ours fp32 % of floor | pytorch-mppi % of its floor | best possible theirs / ours |"
    )
    lines = [header, "|---" * (header.count("|") - 1) + "|"]
    for row, draw_ms in zip(rows, draws_ms, strict=True):
        flops = plan_flops(row.state_dim, row.num_samples, row.horizon, row.iterations, num_envs)
        matmul_ms = flops["ours"] / (peaks[row.device] * 1e6)  # the plan's matmuls at the peak
        floor_ms = matmul_ms + draw_ms
        theirs_floor_ms = flops["theirs"] / (peaks[row.device] * 1e6) + draw_ms
        theirs_share = "n/a" if row.theirs_ms is None else f"{100 * theirs_floor_ms / row.theirs_ms:.0f}%"
        best = "n/a" if row.theirs_ms is None else f"{row.theirs_ms / floor_ms:.2f}x"
        lines.append(
            f"| {row.device} | {row.state_dim} | {row.num_samples} | {row.horizon} | {row.iterations} | "
            f"{flops['ours'] / 1e9:.2f} / {flops['theirs'] / 1e9:.2f} | {matmul_ms:.1f} | {draw_ms:.1f} | {floor_ms:.1f} | "
            f"{100 * floor_ms / row.ours_ms:.0f}% | {theirs_share} | {best} |"
        )
    return lines


def _learn_table(results: dict[tuple[str, str, int], dict[str, float]], steps: int, gpu: bool = False) -> list[str]:
    header = (
        "| env | agent | envs | learn(total_timesteps) | transitions run | seconds | transitions / s | plans | "
        "MPPI iterations | peak RSS before learn (MB) | peak RSS (MB) |" + (" peak CUDA memory (MB) |" if gpu else "")
    )
    lines = [header, "|---" * (header.count("|") - 1) + "|"]
    for (env_id, agent, count), result in results.items():
        rate = result["timesteps"] / result["seconds"]
        lines.append(
            f"| {env_id} | {agent} | {count} | {steps} | {int(result['timesteps'])} | {result['seconds']:.1f} | "
            f"{rate:.1f} | {result['plans']:.0f} | {result.get('iterations', 0.0):.0f} | {result['rss_before_mb']:.0f} | "
            f"{result['rss_peak_mb']:.0f} |" + (f" {result.get('gpu_peak_mb', 0.0):.0f} |" if gpu else "")
        )
    return lines


def _ratio(result: dict[str, float], ppo: dict[str, float]) -> str:
    """``wall ratio (CPU ratio)`` of one learn over PPO's."""
    nan = float("nan")
    cpu = result.get("cpu_seconds", nan) / ppo.get("cpu_seconds", nan)
    return f"{result['seconds'] / ppo['seconds']:.2f}x ({cpu:.2f}x)"


def learn_ratios(results: dict[tuple[str, str, int], dict[str, float]]) -> list[str]:
    """The summary of the learn section: per env, each planning agent's learn time over PPO's (same run).

    Wall time and the process's CPU time are both given; with one torch thread per process the CPU time is what
    each learn would take alone on a core, so its ratio holds on a machine that other work shares.

    :param results: what :func:`bench_learn` measured (with PPO on every env).
    :return: markdown lines (none when no env has PPO and a planning agent).
    """
    header = (
        "| env | envs | EBM learn s (CPU s) | Action FF learn s (CPU s) | PPO learn s (CPU s) | EBM / PPO wall (CPU) | "
        "Action FF / PPO wall (CPU) |"
    )
    lines = [header, "|---" * 7 + "|"]
    for env_id in dict.fromkeys(env for env, _, _ in results):
        ppo = results.get((env_id, "ppo", 1))
        counts = sorted({count for env, agent, count in results if env == env_id and agent != "ppo"})
        for count in counts:
            ebm, ff = results.get((env_id, "ebm", count)), results.get((env_id, "action-ff", count))
            cells = [f"{r['seconds']:.1f} ({r.get('cpu_seconds', float('nan')):.1f})" if r else "-" for r in (ebm, ff, ppo)]
            ratios = [_ratio(r, ppo) if (r and ppo) else "-" for r in (ebm, ff)]
            lines.append(f"| {env_id} | {count} | " + " | ".join(cells + ratios) + " |")
    return lines if len(lines) > 2 else []


def _learn_floor(result: dict[str, float], peak_gflops: float | None) -> list[str]:
    """The EBM agent's plans in a learn run and the seconds their network matmuls alone take at the matmul peak."""
    if not result.get("plans") or peak_gflops is None:
        return []
    floor_s = result["plan_gflop"] / peak_gflops
    return [
        "",
        f"The EBM agent made {result['plans']:.0f} plans ({result.get('iterations', 0.0):.0f} MPPI iterations, "
        f"{result['plan_gflop']:.1f} network GFLOP in all): at this host's matmul peak ({peak_gflops:.0f} GFLOP/s) their "
        f"matmuls alone take {floor_s:.1f} s, {100 * floor_s / result['seconds']:.0f}% of the "
        f"{result['seconds']:.1f} s it ran.",
    ]


def main(argv: Sequence[str] | None = None) -> None:
    """
    Run the benchmark and print (and optionally write) the markdown report.

    :param argv: command-line arguments (``--help`` lists them); None for ``sys.argv``.
    """
    parser = argparse.ArgumentParser(prog="python -m eval.bench", description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a small grid: D {2, 20}, K {64, 1024}, T {20, 80}, I {10}")
    parser.add_argument("--out", default=None, help="also write the report to this markdown file")
    parser.add_argument("--repeats", type=int, default=5, help="timed plans per variant (median reported)")
    parser.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    parser.add_argument("--learn-steps", type=int, default=1000, help="total_timesteps of each learn() (0 skips)")
    parser.add_argument("--no-compile", action="store_true", help="skip the torch.compile section")
    parser.add_argument("--quality", type=int, default=30, help="plans of the bf16 quality check (0 skips)")
    parser.add_argument("--note", action="append", default=[], help="a line to add to the report's header")
    parser.add_argument(
        "--chunks",
        type=int,
        nargs="+",
        default=None,
        help="also time these MPPIConfig.chunk_transitions on the grid's CPU cases larger than one chunk (e.g. 1024 4096)",
    )
    parser.add_argument(
        "--devices",
        nargs="+",
        choices=("cpu", "cuda"),
        default=None,
        help="where to time the plans (default: the CPU, and CUDA when available)",
    )
    parser.add_argument(
        "--learn-device", choices=("cpu", "cuda"), default="cpu", help="the device both agents train on in the learn section"
    )
    parser.add_argument("--envs", type=int, default=1, help="N, the envs of each timed plan (one batched plan)")
    parser.add_argument("--learn-envs", nargs="+", default=list(LEARN_ENVS), help="envs of the learn section")
    parser.add_argument(
        "--learn-agents", nargs="+", choices=LEARN_AGENTS, default=list(LEARN_AGENTS), help="agents of the learn section"
    )
    parser.add_argument(
        "--learn-preset", default="", help="the planning agents' preset in the learn section ('' defaults, 'paper')"
    )
    parser.add_argument(
        "--learn-n-envs", type=int, nargs="+", default=[1], help="VecEnv sizes of the planning agents' learn (e.g. 1 4 8)"
    )
    parser.add_argument("--skip-plans", action="store_true", help="only the learn section (no plan, roofline, compile)")
    parser.add_argument("--learn-worker", choices=LEARN_AGENTS, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.learn_worker:
        measured = learn_worker(
            args.learn_worker,
            args.learn_steps,
            args.threads,
            args.learn_device,
            env_id=args.learn_envs[0],
            preset=args.learn_preset,
            n_envs=args.learn_n_envs[0],
        )
        print(json.dumps(measured))
        return
    if args.repeats < 1:
        parser.error("--repeats must be >= 1")
    if args.envs < 1:
        parser.error("--envs must be >= 1")
    cuda_asked = "cuda" in (args.devices or []) or args.learn_device == "cuda"
    if cuda_asked and not torch.cuda.is_available():
        parser.error("CUDA was asked for (--devices cuda or --learn-device cuda) but torch sees no CUDA device here")

    torch.set_num_threads(args.threads)
    theirs_version = pytorch_mppi_version()
    compare = theirs_version is not None
    if args.devices is None:
        devices = [torch.device("cpu")] + ([torch.device("cuda")] if torch.cuda.is_available() else [])
    else:
        devices = [torch.device(name) for name in dict.fromkeys(args.devices)]
    grid = QUICK_GRID if args.quick else FULL_GRID
    cases = [DEFAULT_CASE] + [
        (d, k, t, i) for d in grid["state_dims"] for k in grid["samples"] for t in grid["horizons"] for i in grid["iterations"]
    ]
    command = shlex.join(["python", "-m", "eval.bench", *(sys.argv[1:] if argv is None else argv)])
    report = [
        "# Benchmarks",
        "",
        f"- Command: `{command.strip()}`",
        f"- Date: {datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M UTC')}",
        f"- Machine: {_machine()}; torch threads: {args.threads}",
        f"- torch {torch.__version__}; pytorch-mppi {theirs_version or 'not installed'}; Python {platform.python_version()}",
        f"- CUDA: {_cuda_line()}",
        f"- Grid: {'quick' if args.quick else 'full'}; medians of {args.repeats} plans per variant after one warm-up, "
        "variants interleaved; "
        + ("one env (N=1)." if args.envs == 1 else f"N={args.envs} envs in each plan (pytorch-mppi: MPPI_Batched)."),
        *(f"- Note: {note}" for note in args.note),
        "",
        "## Plan time (ms per plan)",
        "",
    ]
    peaks: dict[str, float] = {}
    if args.skip_plans:
        report = [line for line in report[: report.index("## Plan time (ms per plan)")] if not line.startswith("- Grid:")]
    else:
        print("\n".join(report), flush=True)
        rows = []
        for device in devices:
            for case in cases:
                row = bench_plan(*case, device=device, repeats=args.repeats, compare=compare, num_envs=args.envs)
                rows.append(row)
                print(_plan_table([row], True)[-1], flush=True)
        report += _plan_table(rows, compare)
        peak_by_size = {str(device): matmul_peak_gflops(device) for device in devices}
        peaks = {name: max(by_size.values()) for name, by_size in peak_by_size.items()}
        native = "has" if native_bf16(torch.device("cpu")) else "does not have"
        report += [
            "",
            "What is timed: see the docstring of `eval/bench.py`. `theirs / ours` > 1 means our planner is faster;",
            "only ratios from the same run are comparable (timings on the shared machines vary by 30-40% between runs).",
            "The agent plans in float32 by default (`MPPIConfig.autocast=None`); bf16 is opt-in (`autocast='bf16'`), and",
            f"this machine's CPU {native} native bf16 dot products (AVX512-BF16 or AMX).",
        ]
        report += ["", "## Roofline (float32 matmul peak of this host, measured in this run)", ""]
        for name, by_size in peak_by_size.items():
            sizes = ", ".join(f"{size:,} rows {gflops:.0f}" for size, gflops in by_size.items())
            report.append(f"- {name}: `torch.mm` [M, 128] x [128, 128], GFLOP/s by M: {sizes}; peak {peaks[name]:.0f} GFLOP/s")
        draws = [
            gaussian_draw_ms(
                row.iterations * args.envs * row.num_samples * row.horizon * row.state_dim, torch.device(row.device)
            )
            for row in rows
        ]
        report += ["", *_roofline_table(rows, peaks, args.envs, draws), ""]
        report += [
            "The floor of a plan is its network's matmul FLOPs at that peak plus the time of drawing its I x N x K x T x D",
            "standard normal numbers with torch's generator (both planners draw that many: ours as STOMP's white noise,",
            "pytorch-mppi as its action noise). No planner that evaluates this network on the same K x T rows per iteration",
            "and draws the same noise can be faster: the thin first and last layers, the STOMP matmul, the costs and the",
            "softmax only add time. `best possible theirs / ours` is the pytorch-mppi time of this run over our floor: the",
            "ratio a planner doing nothing but those two things at the host's speed would reach. Where it is below 2, the",
            "issue's target (2x pytorch-mppi at equal K, T and iterations) cannot be met in float32 on this host by any",
            "implementation of the same computation; only less or cheaper arithmetic (fewer rows, bf16) could.",
        ]
        if args.chunks:
            positive = [c for c in args.chunks if c > 0]
            large = [case for case in cases if not positive or case[1] * case[2] > min(positive)]
            report += [
                "",
                "## Chunk size (ms per plan, float32, CPU; in brackets pytorch-mppi / ours)",
                "",
                f"`MPPIConfig.chunk_transitions=None` takes `CPU_CHUNK_TRANSITIONS` = {CPU_CHUNK_TRANSITIONS} on CPU.",
                "",
                *_chunk_table(large, args.chunks, args.repeats, compare),
            ]
        if args.quality > 0:
            quality = bench_quality(args.quality)
            report += [
                "",
                f"## Plan quality in bf16 ({args.quality} particle plans, float32 cost of each plan)",
                "",
                "| change from the float32 plan | mean | std |",
                "|---|---|---|",
                f"| bf16, same noise | {quality['bf16_mean']:+.4f} | {quality['bf16_std']:.4f} |",
                f"| float32, another seed | {quality['seed_mean']:+.4f} | {quality['seed_std']:.4f} |",
                "",
                f"bf16 was worse on {100 * quality['bf16_worse']:.0f}% of the problems. A bf16 change smaller than a new",
                "seed's means bf16 rounding costs less plan quality than the sampling noise of MPPI itself on these random",
                "problems; it is still not the default because a trained particle agent (the README example, 2,000",
                "transitions) scored -27 with bf16 plans against -4.6 in float32: its last centimetre to the goal is below",
                "bf16's resolution of the energies.",
            ]
        if not args.no_compile:
            timings = bench_compile(devices[0], args.repeats)
            report += [
                "",
                f"## torch.compile (D, K, T, I = {COMPILE_CASE}, {devices[0]})",
                "",
                "| first plan incl. compilation (s) | compiled median ms | eager median ms | eager / compiled |",
                "|---|---|---|---|",
                f"| {timings['first_ms'] / 1000:.1f} | {timings['compiled_ms']:.1f} | {timings['eager_ms']:.1f} | "
                f"{timings['eager_ms'] / timings['compiled_ms']:.2f}x |",
            ]
    if args.learn_steps > 0:
        results = bench_learn(
            args.learn_steps,
            args.threads,
            args.learn_device,
            env_ids=args.learn_envs,
            agents=args.learn_agents,
            preset=args.learn_preset,
            n_envs=args.learn_n_envs,
        )
        where = "CUDA" if args.learn_device == "cuda" else "CPU"
        preset = args.learn_preset or "library defaults"
        report += ["", f"## learn wall time ({where}, {args.threads} threads, {preset}, one process each)", ""]
        report += learn_ratios(results)
        report += ["", *_learn_table(results, args.learn_steps, gpu=args.learn_device == "cuda")]
        ebm_particle = results.get((ENV_ID, "ebm", 1))
        report += _learn_floor(ebm_particle, peaks.get(args.learn_device)) if ebm_particle else []
        report += [
            "",
            "PPO is baselines.ppo.make_ppo (the env's tuned settings and number of envs) and stops at exactly",
            "total_timesteps. The ratio is learn wall time over PPO's, both measured in this run on the same env and threads.",
            "Peak RSS is the worker process's VmHWM (it includes the interpreter, torch and the env), before and after learn.",
        ]
    text = "\n".join(report) + "\n"
    print("\n".join(report[report.index("## Plan time (ms per plan)") :] if not args.skip_plans else report))
    if args.out:
        os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
        with open(args.out, "w") as handle:
            handle.write(text)


if __name__ == "__main__":
    main()
