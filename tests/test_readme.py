"""The README's usage example runs as written."""

from __future__ import annotations

import os
import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_example_runs(tmp_path, monkeypatch):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    assert blocks, "README has no python example"
    monkeypatch.chdir(tmp_path)  # it writes runs/ and a zip
    namespace: dict = {}
    exec(compile(blocks[0], "README.md", "exec"), namespace)
    assert namespace["agent"].num_timesteps == 2_000
    assert namespace["mean_score"] > -10.0  # the paper's particle evaluation (optimum -4.5, standing still -100)
    assert os.path.isfile("ebm_particle.zip")
