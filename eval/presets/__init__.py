"""Experiment presets: YAML files whose keys are ``ebm-eval`` flags (``--config <name>`` or ``--config <file>``).

A preset sets any of ``PRESET_KEYS``; flags given on the command line win over it. Example::

    env: [particle]
    agents: [ebm, ppo]
    timesteps: 20000
    seeds: [0, 1, 2]
    hyperparams:
      ppo: {n_steps: 256}
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

PRESET_DIR = Path(__file__).resolve().parent
"""The folder of the bundled presets."""

PRESET_KEYS = (
    "env",
    "agents",
    "baseline",
    "timesteps",
    "seeds",
    "eval_episodes",
    "eval_freq",
    "env_kwargs",
    "eval_env_kwargs",
    "hyperparams",
    "device",
    "jobs",
    "executor",
    "address",
    "cpus_per_job",
    "gpus_per_job",
    "out",
)
"""Keys a preset may set (dashes are read as underscores)."""


def available_presets() -> list[str]:
    """Names of the bundled presets.

    :return: sorted names, usable as ``--config <name>``.
    """
    return sorted(path.stem for path in PRESET_DIR.glob("*.yaml"))


def preset_path(name_or_path: str) -> Path:
    """Find a preset: a bundled name (``particle_online``) or a path to a YAML file.

    :param name_or_path: the ``--config`` value.
    :return: the YAML file.
    """
    candidate = Path(name_or_path)
    if candidate.suffix in (".yaml", ".yml") and candidate.is_file():
        return candidate
    bundled = PRESET_DIR / f"{candidate.stem if candidate.suffix in ('.yaml', '.yml') else name_or_path}.yaml"
    if bundled.is_file():
        return bundled
    raise ValueError(
        f"unknown preset {name_or_path!r}: give a YAML file or one of the bundled presets: {', '.join(available_presets())}"
    )


def load_preset(name_or_path: str) -> dict[str, Any]:
    """Read and check a preset.

    :param name_or_path: a bundled name or a YAML path.
    :return: the preset's settings, keys with underscores.
    """
    path = preset_path(name_or_path)
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as error:
        raise ValueError(f"preset {path} is not valid YAML: {error}") from None
    data = {} if data is None else data
    if not isinstance(data, dict):
        raise ValueError(f"preset {path} must be a mapping of flag names to values, got {type(data).__name__}")
    settings = {str(key).replace("-", "_"): value for key, value in data.items()}
    unknown = sorted(set(settings) - set(PRESET_KEYS))
    if unknown:
        raise ValueError(f"preset {path} has unknown keys {unknown}; allowed keys: {', '.join(PRESET_KEYS)}")
    for key in ("env_kwargs", "eval_env_kwargs", "hyperparams"):
        if key in settings and not isinstance(settings[key], dict):
            raise ValueError(f"preset {path}: {key} must be a mapping, got {settings[key]!r}")
    return settings


__all__ = ["PRESET_DIR", "PRESET_KEYS", "available_presets", "load_preset", "preset_path"]
