"""The learn section of ``python -m benchmarks``: ``learn`` wall time and memory of each agent against PPO's.

Each ``learn`` runs in its own subprocess (``python -m benchmarks --learn-worker ...``) so that its peak memory is
its own; PPO is ``baselines.ppo.make_ppo`` with the env's tuned settings.
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import time
from collections.abc import Sequence
from typing import Any

import torch

from benchmarks.planner import ENV_ID
from benchmarks.roofline import mlp_flops_per_row

__all__ = ["LEARN_AGENTS", "LEARN_ENVS", "bench_learn", "learn_ratios", "learn_worker"]

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
                command = [sys.executable, "-m", "benchmarks", "--learn-worker", agent, "--learn-steps", str(steps)]
                command += ["--threads", str(threads), "--learn-device", device, "--learn-envs", env_id]
                command += ["--learn-preset", preset, "--learn-n-envs", str(count)]
                done = subprocess.run(command, capture_output=True, text=True, check=False)
                if done.returncode != 0:
                    raise RuntimeError(f"the {agent} learn worker on {env_id} failed:\n{done.stderr[-3000:]}")
                results[(env_id, agent, count)] = json.loads(done.stdout.strip().splitlines()[-1])
    return results


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
