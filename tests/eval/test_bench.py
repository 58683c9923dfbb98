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
