"""Per-environment PPO hyperparameters, rl-zoo3 style: the table is data, ``baselines/ppo.yaml`` (keyed by Gymnasium id,
with a ``default`` entry; the file's comments say how each entry was chosen)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

PPO_HYPERPARAMS_FILE = Path(__file__).with_name("ppo.yaml")
"""The PPO table."""

PPO_HYPERPARAMS: dict[str, dict[str, Any]] = yaml.safe_load(PPO_HYPERPARAMS_FILE.read_text())
"""PPO hyperparameters per Gymnasium id; ``default`` fills in whatever an entry leaves out."""

__all__ = ["PPO_HYPERPARAMS", "PPO_HYPERPARAMS_FILE"]
