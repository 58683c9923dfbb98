"""The roofline of the plan benchmark: network FLOPs, the matmul peak and each plan's floor."""

from __future__ import annotations

import torch

from benchmarks.planner import PlanTiming
from benchmarks.roofline import _roofline_table, gaussian_draw_ms, matmul_peak_gflops, mlp_flops_per_row, plan_flops
from ebm_agent.energy import EnergyModel


def test_the_network_flops_are_counted_from_the_layers() -> None:
    # [s, s'] of a 2-D state: 4 -> 128 -> 128 -> 128 -> 1, two FLOPs per multiply-add.
    assert mlp_flops_per_row(EnergyModel(2).net) == 2 * (4 * 128 + 2 * 128 * 128 + 128)
    flops = plan_flops(2, samples=8, horizon=5, iterations=3, num_envs=2)
    rows = 3 * 2 * 8 * 5  # I x N x K x T
    assert flops["ours"] == rows * 2 * (4 * 128 + 2 * 128 * 128 + 128)
    assert flops["theirs"] == rows * 2 * (4 * 128 + 2 * 128 * 128 + 128 * 2)  # the dynamics outputs D = 2 columns


def test_the_roofline_table_divides_by_the_measured_peak() -> None:
    peaks = matmul_peak_gflops(torch.device("cpu"), repeats=2, rows=(64, 256))
    assert set(peaks) == {64, 256} and all(value > 0 for value in peaks.values())
    assert gaussian_draw_ms(1000, torch.device("cpu"), repeats=2) > 0
    row = PlanTiming("cpu", 2, 64, 20, 10, ours_ms=10.0, ours_bf16_ms=8.0, theirs_ms=30.0)
    flops = plan_flops(2, 64, 20, 10)
    peak = flops["ours"] / 4e6  # GFLOP/s at which the plan's matmuls take exactly 4 ms
    line = _roofline_table([row], {"cpu": peak}, num_envs=1, draws_ms=[1.0])[2]
    cells = [cell.strip() for cell in line.strip("|").split("|")]
    theirs_floor = 4.0 * flops["theirs"] / flops["ours"] + 1.0
    # matmuls 4 ms + draws 1 ms = floor 5 ms: ours is at 50% of it, and 30 ms / 5 ms is the best ratio possible.
    assert cells[6:] == ["4.0", "1.0", "5.0", "50%", f"{100 * theirs_floor / 30:.0f}%", "6.00x"]
    missing = _roofline_table([PlanTiming("cpu", 2, 64, 20, 10, 10.0, 8.0, None)], {"cpu": peak}, 1, [1.0])[2]
    assert missing.rstrip(" |").endswith("n/a")
