"""The roofline section of ``python -m benchmarks``: the host's matmul peak and each plan's floor.

A plan's floor is its network's matmul FLOPs at this host's float32 ``torch.mm`` peak plus the time of drawing its
Gaussian numbers: no planner that evaluates the same network on the same rows and draws the same noise is faster.
"""

from __future__ import annotations

import functools
import statistics
from collections.abc import Sequence

import torch
from torch import nn

from benchmarks.planner import PlanTiming, _Dynamics, _timed
from ebm_agent.energy import EnergyModel

__all__ = ["PEAK_ROWS", "gaussian_draw_ms", "matmul_peak_gflops", "mlp_flops_per_row", "plan_flops"]

PEAK_ROWS = (1024, 4096, 16384)
"""Batch sizes of the matmul-peak probe; the best of them is the host's peak (a lower bound on any plan's time)."""


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
