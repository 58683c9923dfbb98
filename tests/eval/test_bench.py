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
    assert result["plans"] >= 1 and result["plan_gflop"] > 0  # at least the first plan, of K x T x I transitions
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


def test_the_network_flops_are_counted_from_the_layers() -> None:
    from ebm_agent.energy import EnergyModel
    from eval.bench import mlp_flops_per_row, plan_flops

    # [s, s'] of a 2-D state: 4 -> 128 -> 128 -> 128 -> 1, two FLOPs per multiply-add.
    assert mlp_flops_per_row(EnergyModel(2).net) == 2 * (4 * 128 + 2 * 128 * 128 + 128)
    flops = plan_flops(2, samples=8, horizon=5, iterations=3, num_envs=2)
    rows = 3 * 2 * 8 * 5  # I x N x K x T
    assert flops["ours"] == rows * 2 * (4 * 128 + 2 * 128 * 128 + 128)
    assert flops["theirs"] == rows * 2 * (4 * 128 + 2 * 128 * 128 + 128 * 2)  # the dynamics outputs D = 2 columns


def test_the_roofline_table_divides_by_the_measured_peak() -> None:
    from eval.bench import PlanTiming, _roofline_table, gaussian_draw_ms, matmul_peak_gflops, plan_flops

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


def test_the_learn_floor_counts_the_agents_plans_at_the_peak() -> None:
    from eval.bench import _learn_floor

    result = {"plans": 1000.0, "iterations": 8000.0, "plan_gflop": 4000.0, "seconds": 80.0}
    (line,) = [text for text in _learn_floor(result, peak_gflops=100.0) if text]
    assert "made 1000 plans (8000 MPPI iterations, 4000.0 network GFLOP in all)" in line
    assert "take 40.0 s, 50% of the 80.0 s" in line
    assert _learn_floor({**result, "plans": 0.0}, 100.0) == [] and _learn_floor(result, None) == []


def test_learn_ratios_are_taken_against_ppo_on_the_same_env() -> None:
    from eval.bench import learn_ratios

    def run(seconds: float, cpu: float) -> dict[str, float]:
        return {"seconds": seconds, "cpu_seconds": cpu, "timesteps": 50_000.0, "plans": 0.0}

    results = {
        ("ebm/Particle-v0", "ebm", 1): run(60.0, 55.0),
        ("ebm/Particle-v0", "action-ff", 1): run(45.0, 44.0),
        ("ebm/Particle-v0", "ppo", 1): run(30.0, 27.5),
        ("ebm/Particle-v0", "ebm", 4): run(50.0, 49.5),
        ("ebm/Reacher-v0", "ebm", 1): run(90.0, 80.0),
    }
    lines = learn_ratios(results)
    rows = {tuple(cell.strip() for cell in line.strip("|").split("|")[:2]): line for line in lines[2:]}
    assert "| 2.00x (2.00x) | 1.50x (1.60x) |" in rows[("ebm/Particle-v0", "1")]
    assert rows[("ebm/Particle-v0", "4")].endswith("| 1.67x (1.80x) | - |")
    assert rows[("ebm/Reacher-v0", "1")].endswith("| - | - |")  # no PPO run on that env: no ratio
    assert learn_ratios({}) == []
