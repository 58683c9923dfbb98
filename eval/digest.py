"""The settings an agent runs with, as a digest that retires recorded runs when a library default changes.

Every finished run stores the digest of its agent's settings on its env (``AgentSpec.defaults``); a run whose digest
differs from today's is no longer current. The library knows nothing of this: which settings were added at a value
that changes nothing (and so must not retire the runs made before them) is harness data, ``neutral_settings.yaml``;
where the library moved a setting is the library's own record (``ebm_agent.config.MOVED_SETTINGS``), read here.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import inspect
import re
import sys
from pathlib import Path
from typing import Any

import gymnasium as gym
import yaml

from ebm_agent.config import MOVED_SETTINGS

NEUTRAL_FILE = Path(__file__).with_name("neutral_settings.yaml")
"""The settings added after runs were recorded, with the values at which they change nothing."""

NOT_MEASURED = frozenset({"tensorboard_log", "verbose", "seed", "device", "_init_setup_model", "stats_window_size"})
"""Constructor arguments that do not change what a run measures (left out of ``class_defaults``)."""


@functools.lru_cache(maxsize=1)
def neutral_settings() -> dict[str, dict[str, dict[str, Any]]]:
    """``neutral_settings.yaml``: ``{section: {class name: {name: value}}}`` (sections ``config_fields``,
    ``removed_fields``, ``moved_settings``, ``fixed_settings``, ``arguments``, ``recorded_as``,
    ``env_inverse_dynamics``)."""
    data = yaml.safe_load(NEUTRAL_FILE.read_text()) or {}
    # where the library moved its settings is its own record (the error an old setting gets names the same places)
    data["moved_settings"] = {"EBMPlannerAgent": dict(MOVED_SETTINGS), **(data.get("moved_settings") or {})}
    sections = (
        "config_fields",
        "removed_fields",
        "moved_settings",
        "fixed_settings",
        "arguments",
        "recorded_as",
        "env_inverse_dynamics",
    )
    return {section: dict(data.get(section) or {}) for section in sections}


def _plain(value: Any) -> Any:
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, (tuple, list)):
        return [_plain(item) for item in value]
    if isinstance(value, type):  # a class setting (subgoal_class): its name
        return f"{value.__module__}.{value.__qualname__}"
    return type(value).__name__  # an object's repr may hold its address: its type is what is stable


def class_defaults(
    agent_class: type, overrides: dict[str, Any] | None = None, neutral: dict[str, dict[str, dict[str, Any]]] | None = None
) -> dict[str, Any]:
    """The default settings of an agent class: its constructor's defaults and, for every config dataclass its
    annotations name (``MPPIConfig | dict | None``), that dataclass's default fields.

    Left out: the arguments in ``NOT_MEASURED``, and the settings ``neutral`` lists while they have their neutral
    value (constructor ``arguments`` and ``config_fields``). An argument whose default is None and which
    ``recorded_as`` lists counts as the value it stands for.

    :param agent_class: the class.
    :param overrides: constructor arguments that replace defaults (an agent preset, ``ebm_agent.presets``); a dict
        given for a config argument replaces that config's fields. The neutral rules apply after them, so a preset
        that restores the settings of earlier runs has their digest.
    :param neutral: the rules (default: ``neutral_settings()``).
    :return: ``{argument: default, "argument:ConfigName": {field: default}}``.
    """
    overrides = overrides or {}
    neutral = neutral_settings() if neutral is None else neutral
    name_of = agent_class.__name__
    neutral_arguments = neutral.get("arguments", {}).get(name_of, {})
    recorded_as = neutral.get("recorded_as", {}).get(name_of, {})
    module = vars(sys.modules[agent_class.__module__])
    moved = neutral.get("moved_settings", {}).get(name_of, {})
    sources = {path.split(".")[0] for path in moved}  # arguments whose config fields move back, neutral or not
    defaults: dict[str, Any] = {}
    for name, parameter in inspect.signature(agent_class).parameters.items():
        if parameter.default is inspect.Parameter.empty or name in NOT_MEASURED:
            continue
        override = overrides.get(name)
        value = parameter.default if (name not in overrides or isinstance(override, dict)) else override
        if name in neutral_arguments and _plain(value) == _plain(neutral_arguments[name]):
            if name not in sources:
                continue  # an argument added later, at the value that changes nothing
        else:
            if value is None and name in recorded_as:
                value = recorded_as[name]
            defaults[name] = _plain(value)
        for token in re.findall(r"[A-Za-z_][A-Za-z0-9_]*", str(parameter.annotation)):
            config = module.get(token)
            if isinstance(config, type) and dataclasses.is_dataclass(config):
                fields = override if isinstance(override, dict) else None
                key = f"{name}:{config.__name__}"
                try:
                    defaults[key] = _config_defaults(config, fields, neutral)
                except TypeError:  # a config without defaults for every field, or one the preset's fields are not for
                    try:
                        defaults[key] = _config_defaults(config, None, neutral)
                    except TypeError:
                        continue
    _recorded_layout(defaults, moved, neutral.get("fixed_settings", {}).get(name_of, {}), neutral, name_of)
    return defaults


def _recorded_layout(
    defaults: dict[str, Any], moved: dict[str, str], fixed: dict[str, Any], neutral: Rules, name_of: str
) -> None:
    """Put the settings that moved since runs were recorded back where those runs' digests hold them, in place.

    :param defaults: ``class_defaults``'s result so far.
    :param moved: ``{"argument.field": "old place"}``, the old place an argument (``"loss"``) or an ``"argument.field"``
        (``"online.hard_negatives"``) (``moved_settings``).
    :param fixed: ``{"argument.field": value}``, settings the agent no longer has, at the value its behaviour is now
        fixed at (``fixed_settings``).
    :param neutral: the rules: an old place's neutral value leaves it out, as it did then.
    :param name_of: the agent class's name.
    """

    def config_key(argument: str) -> str | None:
        return next((key for key in defaults if key.startswith(f"{argument}:")), None)

    def place(path: str, value: Any) -> None:
        argument, _, field = path.partition(".")
        if not field:
            if _plain(value) != _plain(neutral.get("arguments", {}).get(name_of, {}).get(argument, object())):
                defaults[argument] = _plain(value)
            return
        key = config_key(argument)
        assert key is not None, f"no config argument {argument!r} to put {path!r} back into"
        rules = neutral.get("config_fields", {}).get(key.split(":")[1], {})
        if not (field in rules and rules[field] == value):
            defaults[key][field] = value

    for new, old in moved.items():
        argument, _, field = new.partition(".")
        key = config_key(argument)
        if key is None or field not in defaults[key]:
            continue
        place(old, defaults[key].pop(field))
        if not defaults[key]:
            del defaults[key]
    for path, value in fixed.items():
        place(path, value)


Rules = dict[str, dict[str, dict[str, Any]]]


def _config_defaults(config: type, fields: dict[str, Any] | None, neutral: Rules) -> dict[str, Any]:
    """A config dataclass's fields (its defaults, less ``fields`` given), less those at their neutral value, plus the
    fields removed from it at the value their behaviour is now fixed at (``removed_fields``)."""
    values = {**neutral.get("removed_fields", {}).get(config.__name__, {}), **dataclasses.asdict(config(**(fields or {})))}
    for name, value in neutral.get("config_fields", {}).get(config.__name__, {}).items():
        if name in values and values[name] == value:
            del values[name]
    return values


def recorded_hyperparams(class_name: str | None, hyperparams: dict[str, Any]) -> dict[str, Any]:
    """A job's agent keyword arguments in the layout the recorded runs were fingerprinted in (``moved_settings``):
    ``{"training": {"l2_coeff": 0.1, "hard_negatives": True}}`` reads ``{"l2_coeff": 0.1, "online": {"hard_negatives":
    True}}``, so that a row written in today's layout is the run recorded before the configs were split.

    :param class_name: the agent's class name (None: an agent without such rules, returned as is).
    :param hyperparams: the job's ``hyperparams``.
    :return: a new dict.
    """
    moved = neutral_settings()["moved_settings"].get(class_name or "", {})
    result = {key: dict(value) if isinstance(value, dict) else value for key, value in hyperparams.items()}
    for new, old in moved.items():
        argument, _, field = new.partition(".")
        given = result.get(argument)
        if not isinstance(given, dict) or field not in given:
            continue
        value = given.pop(field)
        if not given:
            del result[argument]
        old_argument, _, old_field = old.partition(".")
        if old_field:
            result.setdefault(old_argument, {})[old_field] = value
        else:
            result[old_argument] = value
    return result


def env_inverse_dynamics_defaults(env_id: str) -> dict[str, Any]:
    """The env's constructor defaults that change only its ``inverse_dynamics``, where they differ from the value
    that reproduces earlier runs (``neutral_settings.yaml``, ``env_inverse_dynamics``).

    Agents that use the env's ground-truth inverse dynamics (the EBM) add these to their digest, so that changing
    such a default retires their runs on that env and leaves every other agent's runs (which never call it) valid.

    :param env_id: a registered Gymnasium id.
    :return: ``{argument: default}`` (empty for an unknown id or an env without such arguments).
    """

    try:
        entry_point = gym.spec(env_id).entry_point
    except gym.error.Error:
        return {}
    if not isinstance(entry_point, str):
        return {}
    module_name, _, attribute = entry_point.partition(":")
    arguments = neutral_settings()["env_inverse_dynamics"].get(attribute, {})
    env_class = getattr(importlib.import_module(module_name), attribute, None) if arguments else None
    if env_class is None:
        return {}
    parameters = inspect.signature(env_class).parameters
    return {
        name: _plain(parameters[name].default)
        for name, value in arguments.items()
        if name in parameters and parameters[name].default != value
    }


__all__ = [
    "NEUTRAL_FILE",
    "NOT_MEASURED",
    "class_defaults",
    "env_inverse_dynamics_defaults",
    "neutral_settings",
    "recorded_hyperparams",
]
