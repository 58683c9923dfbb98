"""The benchmark script's arguments and learn section (the timings themselves are never asserted)."""

from __future__ import annotations

import pytest
import torch

from eval.bench import _learn_table, learn_worker, main


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the refusal on a machine without CUDA")
@pytest.mark.parametrize("argv", [["--devices", "cuda"], ["--learn-device", "cuda"]])
def test_asking_for_cuda_without_it_is_a_clear_error(argv, capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    assert "torch sees no CUDA device" in capsys.readouterr().err


def test_the_learn_worker_measures_a_cpu_run_and_the_table_shows_cuda_memory_only_for_cuda() -> None:
    result = learn_worker("ebm", 40, threads=1, device="cpu")
    assert result["timesteps"] >= 40 and result["seconds"] > 0 and result["gpu_peak_mb"] == 0.0
    results = {"ebm": result, "ppo": {**result, "timesteps": 2048.0}}
    assert "peak CUDA memory" not in "\n".join(_learn_table(results, 40))
    gpu_lines = _learn_table(results, 40, gpu=True)
    assert "peak CUDA memory (MB)" in gpu_lines[0]
    assert all(line.count("|") == gpu_lines[0].count("|") for line in gpu_lines[1:3])


def test_a_batched_plan_is_timed_for_every_env_and_checked_against_pytorch_mppi_batched() -> None:
    from eval.bench import _ours, bench_plan, pytorch_mppi_version

    plan = _ours(2, 8, 5, 2, torch.device("cpu"), num_envs=3)
    assert plan().plans.shape == (3, 6, 2)  # [N, T+1, D]: all three envs in one call
    compare = pytorch_mppi_version() is not None  # the bench extra; CI runs without it
    row = bench_plan(2, 8, 5, 2, torch.device("cpu"), repeats=1, compare=compare, num_envs=3)
    assert row.ours_ms > 0 and row.ours_bf16_ms > 0
    assert (row.theirs_ms is not None and row.theirs_ms > 0) == compare


def test_bad_env_counts_are_refused(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["--envs", "0"])
    assert "--envs must be >= 1" in capsys.readouterr().err
