"""How many settings a user can set: ``python -m benchmarks.settings``.

Counts the leaf settings of each agent (issue 45's "a configuration a reader can hold"): every constructor parameter
with a default, where a parameter takes a config dataclass (``online: OnlineConfig | dict | None``) the fields of that
config instead of the parameter itself. A parameter that takes one of several configs (``planner_config``: the
MPPI or the Langevin planner's) counts the config of its default (MPPI); the table lists the others apart. SB3's SAC
and PPO are counted the same way, for scale (their ``policy_kwargs`` counts as one setting).
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import re
import sys
from collections.abc import Sequence
from typing import Any

from stable_baselines3 import PPO, SAC

from baselines.action_ff import ActionFFAgent
from ebm_agent import EBMPlannerAgent

INFRASTRUCTURE = frozenset({"_init_setup_model"})
"""Constructor parameters that are not settings (SB3's own loading flag)."""


def config_classes(agent_class: type, annotation: Any) -> list[type]:
    """The config dataclasses that a parameter annotation names, in order (resolved in the agent's module).

    :param agent_class: the agent class.
    :param annotation: the parameter's annotation (a string under ``from __future__ import annotations``).
    :return: the dataclass types.
    """
    module = vars(sys.modules[agent_class.__module__])
    found = []
    for token in re.findall(r"[A-Za-z_][A-Za-z0-9_]*", str(annotation)):
        candidate = module.get(token)
        if isinstance(candidate, type) and dataclasses.is_dataclass(candidate) and candidate not in found:
            found.append(candidate)
    return found


def leaf_settings(agent_class: type) -> tuple[list[tuple[str, int]], list[tuple[str, int]]]:
    """The leaf settings of an agent class, grouped.

    :param agent_class: the agent class.
    :return: (counted groups, alternatives): ``[(group, count)]`` where a group is ``"constructor"`` (plain
        parameters) or ``"<parameter>: <Config>"``; alternatives are the configs a parameter may take instead of its
        default one, not counted in the total.
    """
    plain = 0
    groups: list[tuple[str, int]] = []
    alternatives: list[tuple[str, int]] = []
    for name, parameter in inspect.signature(agent_class).parameters.items():
        if parameter.default is inspect.Parameter.empty or name in INFRASTRUCTURE:
            continue
        configs = config_classes(agent_class, parameter.annotation)
        if not configs:
            plain += 1
            continue
        first, *others = configs
        groups.append((f"{name}: {first.__name__}", len(dataclasses.fields(first))))
        alternatives.extend((f"{name}: {other.__name__}", len(dataclasses.fields(other))) for other in others)
    return [("constructor", plain), *groups], alternatives


def main(argv: Sequence[str] | None = None) -> int:
    """Print the table.

    :param argv: no arguments.
    :return: 0.
    """
    argparse.ArgumentParser(prog="python -m benchmarks.settings", description=__doc__).parse_args(argv)
    print("| agent | group | settings |\n|---|---|---|")
    for agent_class in (EBMPlannerAgent, ActionFFAgent, SAC, PPO):
        groups, alternatives = leaf_settings(agent_class)
        for group, count in groups:
            print(f"| {agent_class.__name__} | {group} | {count} |")
        for group, count in alternatives:
            print(f"| {agent_class.__name__} | {group} (instead of the default) | ({count}) |")
        print(f"| **{agent_class.__name__}** | **total** | **{sum(count for _, count in groups)}** |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
