"""The plan-time benchmark (the timings themselves are never asserted)."""

from __future__ import annotations

import torch

from benchmarks.planner import _ours, bench_plan, pytorch_mppi_version


def test_a_batched_plan_is_timed_for_every_env_and_checked_against_pytorch_mppi_batched() -> None:
    plan = _ours(2, 8, 5, 2, torch.device("cpu"), num_envs=3)
    assert plan().plans.shape == (3, 6, 2)  # [N, T+1, D]: all three envs in one call
    compare = pytorch_mppi_version() is not None  # the bench extra; CI runs without it
    row = bench_plan(2, 8, 5, 2, torch.device("cpu"), repeats=1, compare=compare, num_envs=3)
    assert row.ours_ms > 0 and row.ours_bf16_ms > 0
    assert (row.theirs_ms is not None and row.theirs_ms > 0) == compare
