"""The arguments of ``python -m benchmarks`` (named apart from tests/eval/test_cli.py: test modules share one namespace)."""

from __future__ import annotations

import pytest
import torch

from benchmarks import eval_goal_weight, settings
from benchmarks.cli import main


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the refusal on a machine without CUDA")
@pytest.mark.parametrize("argv", [["--devices", "cuda"], ["--learn-device", "cuda"]])
def test_asking_for_cuda_without_it_is_a_clear_error(argv, capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    assert "torch sees no CUDA device" in capsys.readouterr().err


def test_bad_env_counts_are_refused(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["--envs", "0"])
    assert "--envs must be >= 1" in capsys.readouterr().err


def test_eval_goal_weight_benchmark_prints_one_row_per_seed(capsys: pytest.CaptureFixture[str]) -> None:
    assert eval_goal_weight.main(["--timesteps", "0", "--seeds", "0", "--episodes", "1", "--weights", "1", "10"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| 0 |")]
    assert len(rows) == 1 and rows[0].count("success") == 2


def test_the_settings_count_counts_config_fields_not_config_arguments(capsys: pytest.CaptureFixture[str]) -> None:
    import dataclasses

    from ebm_agent import EBMPlannerAgent
    from ebm_agent.config import OnlineConfig

    groups, alternatives = settings.leaf_settings(EBMPlannerAgent)
    counts = dict(groups)
    assert counts["online: OnlineConfig"] == len(dataclasses.fields(OnlineConfig))
    assert "planner_config: MPPIConfig" in counts and dict(alternatives).keys() == {"planner_config: LangevinConfig"}
    assert settings.main([]) == 0
    out = capsys.readouterr().out
    assert f"| **EBMPlannerAgent** | **total** | **{sum(counts.values())}** |" in out and "| **SAC** | **total** |" in out


def test_action_inference_study_prints_one_row_per_setting_and_seed(capsys) -> None:
    from benchmarks.action_inference import main

    settings = '{"planner_config": {"iterations": 2, "num_samples": 8, "train_iterations": 2}}'
    assert main(["--env", "particle", "--steps", "60", "--episodes", "1", "--settings", settings, "--seeds", "0", "1"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| `")]
    assert len(rows) == 2 and all(0.0 <= float(row.split("|")[3]) <= 1.0 for row in rows)
