"""The main job's output carries only what it is about: no third-party release or deprecation notice."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import envs

REPO = Path(__file__).resolve().parents[2]


def _stderr_of(*args: str, cwd: Path) -> str:
    completed = subprocess.run(
        [sys.executable, "-m", "eval", *args], cwd=cwd, capture_output=True, text=True, timeout=300, check=False
    )
    assert completed.returncode == 0, completed.stderr[-3000:]
    return completed.stderr


def _assert_quiet(stderr: str) -> None:
    for notice in envs.RELEASE_NOTICES:
        assert notice not in stderr
    assert "Adroit" not in stderr and "deprecat" not in stderr.lower(), stderr[-3000:]


def test_help_prints_no_third_party_notice():
    _assert_quiet(_stderr_of("--help", cwd=REPO))


def test_a_tiny_run_prints_no_third_party_notice(tmp_path):
    stderr = _stderr_of("--config", "smoke", "-f", str(tmp_path / "out"), "--no-progress", cwd=REPO)
    _assert_quiet(stderr)
    assert "200/200 transitions" in stderr  # what the run is about still comes through


def test_other_stderr_output_passes_through(capsys):
    with envs.without_release_notices():
        print(next(iter(envs.RELEASE_NOTICES)), file=sys.stderr)
        print("something else", file=sys.stderr)
    assert capsys.readouterr().err == "something else\n"
