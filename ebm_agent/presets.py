"""Named agent configurations: the original code's settings ("paper") beside the library's measured defaults.

The library's defaults may depart from the original code where a change was measured to keep or improve the scores
(docs/agent.md, "Defaults and the paper preset"). The original's settings stay one named configuration: pass
``PAPER_EBM`` to :class:`~ebm_agent.agent.EBMPlannerAgent` (and ``PAPER_ACTION_FF`` to the Action FF baseline) to run
exactly what the reproduction's paper tables were made with::

    from ebm_agent import EBMPlannerAgent
    from ebm_agent.presets import PAPER_EBM, merge_settings

    agent = EBMPlannerAgent("MultiInputPolicy", env, **merge_settings(PAPER_EBM, {"seed": 0}))

A preset names only the settings that differ from the defaults; everything else is the default of both.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

__all__ = ["PAPER_ACTION_FF", "PAPER_EBM", "PRESETS", "merge_settings", "preset_settings"]

PAPER_EBM: dict[str, Any] = {
    # The original planned every plan, fresh or warm-started, with the full 80 MPPI iterations of K = 80 samples.
    "planner_config": {
        "iterations": 80,
        "warm_iterations": None,
        "train_iterations": None,
        "keep_warm_start": False,
        "stop_tolerance": None,
    },
}
"""Constructor arguments of ``EBMPlannerAgent`` that give the original code's configuration (docs/agent.md)."""

PAPER_ACTION_FF: dict[str, Any] = {
    "planner_config": {"iterations": 80, "warm_iterations": None, "train_iterations": None, "keep_warm_start": False},
}
"""Constructor arguments of ``ActionFFAgent`` for the same planning budget as ``PAPER_EBM``."""

PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "paper": {"EBMPlannerAgent": PAPER_EBM, "ActionFFAgent": PAPER_ACTION_FF},
}
"""Preset name -> agent class name -> constructor arguments. The library's defaults are the preset ``""``."""


def merge_settings(base: Mapping[str, Any], overrides: Mapping[str, Any]) -> dict[str, Any]:
    """``base`` updated by ``overrides``, recursively for nested dicts (a config given as a dict of its fields).

    :param base: keyword arguments (not modified).
    :param overrides: keyword arguments that win; a dict value is merged into a dict value of ``base``.
    :return: a new dict.
    """
    merged = copy.deepcopy(dict(base))
    for key, value in overrides.items():
        if isinstance(value, Mapping) and isinstance(merged.get(key), Mapping):
            merged[key] = merge_settings(merged[key], value)
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def preset_settings(preset: str, agent_class: str | type) -> dict[str, Any]:
    """The constructor arguments a preset gives an agent class.

    :param preset: ``""`` (the library's defaults: no arguments) or a key of :data:`PRESETS`.
    :param agent_class: the class or its name; a class the preset does not name gets no arguments.
    :return: a fresh dict of keyword arguments.
    :raises ValueError: for an unknown preset, naming the known ones.
    """
    if preset == "":
        return {}
    if preset not in PRESETS:
        raise ValueError(f"unknown agent preset {preset!r}; use '' (the library's defaults) or one of {sorted(PRESETS)}.")
    name = agent_class if isinstance(agent_class, str) else agent_class.__name__
    return copy.deepcopy(PRESETS[preset].get(name, {}))
