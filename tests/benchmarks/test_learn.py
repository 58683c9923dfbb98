"""The learn section of the benchmark: the worker's measurements and the tables built from them."""

from __future__ import annotations

from benchmarks.learn import _learn_floor, _learn_table, learn_ratios, learn_worker


def test_the_learn_worker_measures_a_cpu_run_and_the_table_shows_cuda_memory_only_for_cuda() -> None:
    result = learn_worker("ebm", 40, threads=1, device="cpu")
    assert result["timesteps"] >= 40 and result["seconds"] > 0 and result["gpu_peak_mb"] == 0.0
    assert result["plans"] >= 1 and result["plan_gflop"] > 0  # at least the first plan, of K x T x I transitions
    results = {"ebm": result, "ppo": {**result, "timesteps": 2048.0}}
    assert "peak CUDA memory" not in "\n".join(_learn_table(results, 40))
    gpu_lines = _learn_table(results, 40, gpu=True)
    assert "peak CUDA memory (MB)" in gpu_lines[0]
    assert all(line.count("|") == gpu_lines[0].count("|") for line in gpu_lines[1:3])


def test_the_learn_floor_counts_the_agents_plans_at_the_peak() -> None:
    result = {"plans": 1000.0, "iterations": 8000.0, "plan_gflop": 4000.0, "seconds": 80.0}
    (line,) = [text for text in _learn_floor(result, peak_gflops=100.0) if text]
    assert "made 1000 plans (8000 MPPI iterations, 4000.0 network GFLOP in all)" in line
    assert "take 40.0 s, 50% of the 80.0 s" in line
    assert _learn_floor({**result, "plans": 0.0}, 100.0) == [] and _learn_floor(result, None) == []


def test_learn_ratios_are_taken_against_ppo_on_the_same_env() -> None:
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
