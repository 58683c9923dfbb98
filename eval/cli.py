"""``ebm-eval``: train the EBM agent and its baselines under equal budgets and report the comparison.

    ebm-eval --baseline ppo                       # EBM vs PPO on the particle env, small budget
    ebm-eval --config particle_online --jobs 2    # a bundled preset, two runs at a time
    ebm-eval --env maze --baseline ppo --baseline action-ff --seeds 0 1 2 --timesteps 50000
    ebm-eval --config ray_sweep_example --executor ray --address auto   # on a Ray cluster (docs/ray.md)

Settings come from three layers, the later winning: built-in defaults, the ``--config`` preset, explicit flags.

The paper's experiments (``eval.paper.experiments``) run by name, resumably, and regenerate docs/results.md:

    ebm-eval --experiment list                                   # experiments, parts, estimated cost
    ebm-eval --experiment table1 --part 'table1/particle/*' -f runs/results --jobs 2
    ebm-eval --experiment all -f runs/results                    # everything (days of CPU time)
    ebm-eval --report-only -f runs/results                       # only docs/results.md
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import shlex
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import gymnasium as gym
import yaml

from envs import ENV_IDS, PAPER_EVAL_KWARGS, PROTOCOL_ENV_KWARGS, THIRD_PARTY_ENV_IDS, resolve_env_id
from eval.anchors import compute_anchors
from eval.executors import executor_from_name
from eval.flags import (
    DEFAULTS,
    EXPERIMENT_ONLY,
    RESULTS_DIR,
    SUBJECT,
    SWEEP_ONLY,
    SWEEP_ONLY_MORE,
    build_parser,
)
from eval.jobs import Job, library_versions, to_plain
from eval.paper.experiments import EXPERIMENTS
from eval.paper.parts import SCALES
from eval.paper.records import default_docs, default_records
from eval.paper.runner import run_experiments, selected_parts
from eval.plots import plot_learning_curves  # matplotlib and scipy load only for a real sweep
from eval.presets import load_preset
from eval.registry import AGENTS
from eval.report import write_csv, write_markdown


def _hyperparams_by_agent(pairs: Sequence[tuple[str, Any]], known: Sequence[str]) -> dict[str, dict[str, Any]]:
    """``[("horizon", 20), ("ppo:n_steps", 256)]`` -> ``{"ebm": {"horizon": 20}, "ppo": {"n_steps": 256}}``."""
    grouped: dict[str, dict[str, Any]] = {}
    for key, value in pairs:
        agent, sep, name = key.rpartition(":")
        agent = agent if sep else SUBJECT
        if agent not in known:
            raise ValueError(f"--hyperparams {key}: unknown agent {agent!r}; prefix a key with one of {', '.join(known)}")
        grouped.setdefault(agent, {})[name] = value
    return grouped


def resolve_settings(args: argparse.Namespace) -> dict[str, Any]:
    """Merge defaults, the preset and explicit flags, and check the result.

    :param args: parsed flags (unset ones are None).
    :return: the settings of the sweep (env ids resolved, agents listed, eval_freq filled in).
    """
    preset = load_preset(args.config) if args.config else {}
    settings: dict[str, Any] = {}
    for key, default in DEFAULTS.items():
        explicit = getattr(args, key, None)
        settings[key] = explicit if explicit is not None else preset.get(key, default)
    for key in ("env", "baseline", "seeds"):
        if not isinstance(settings[key], list):
            settings[key] = [settings[key]]
    settings["agents"] = _agents(args, preset, settings.pop("baseline"))
    settings["env_ids"] = [resolve_env(name) for name in settings["env"]]
    settings["hyperparams"] = _hyperparams(args, preset)
    settings["env_kwargs"] = {**(preset.get("env_kwargs") or {}), **dict(args.env_kwargs or [])}
    # The evaluation env starts from the training env's kwargs; --eval-env-kwargs changes some of them.
    settings["eval_env_kwargs"] = {
        **settings["env_kwargs"],
        **(preset.get("eval_env_kwargs") or {}),
        **dict(args.eval_env_kwargs or []),
    }
    if settings["eval_freq"] is None and _is_positive_int(settings["timesteps"]):
        settings["eval_freq"] = max(settings["timesteps"] // 5, 1)
    for key in ("timesteps", "eval_episodes", "eval_freq", "jobs"):
        if not _is_positive_int(settings[key]):
            raise ValueError(f"{key} must be a positive integer, got {settings[key]!r}")
    if settings["threads"] is not None and not _is_positive_int(settings["threads"]):
        raise ValueError(f"threads must be a positive integer, got {settings['threads']!r}")
    if any(isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in settings["seeds"]):
        raise ValueError(f"seeds must be non-negative integers, got {settings['seeds']!r}")
    _check_ray_settings(settings)
    if settings["out"] is None:
        settings["out"] = str(Path("runs") / time.strftime("ebm-eval-%Y%m%d-%H%M%S"))
    return settings


RAY_ONLY = ("address", "cpus_per_job", "gpus_per_job")
"""Settings that only the Ray executor reads."""


def _check_ray_settings(settings: dict[str, Any]) -> None:
    """Reject Ray-only settings without ``--executor ray`` and fill in their defaults with it."""
    if settings["executor"] == "ray" and settings.get("threads") is not None:
        raise ValueError("--threads applies to the local executor; with --executor ray, --cpus-per-job sets them")
    if settings["executor"] != "ray":
        given = [key for key in RAY_ONLY if settings[key] is not None]
        if given:
            flags = ", ".join("--" + key.replace("_", "-") for key in given)
            raise ValueError(f"{flags} only apply to --executor ray (the executor is {settings['executor']!r})")
        return
    if settings["cpus_per_job"] is None:
        settings["cpus_per_job"] = 1
    if settings["gpus_per_job"] is None:
        settings["gpus_per_job"] = 1 if str(settings["device"]).startswith("cuda") else 0
    if settings["cpus_per_job"] <= 0:
        raise ValueError(f"--cpus-per-job must be more than 0, got {settings['cpus_per_job']}")
    if str(settings["device"]).startswith("cuda") and settings["gpus_per_job"] == 0:
        raise ValueError(
            f"--device {settings['device']} needs --gpus-per-job above 0 with --executor ray: a Ray task that reserves "
            "no GPU sees none (use --device cpu or auto to train on CPUs)"
        )


def executor_options(settings: dict[str, Any]) -> dict[str, Any]:
    """Constructor arguments of the settings' executor.

    :param settings: from ``resolve_settings``.
    :return: ``jobs`` and ``threads_per_job`` for the local executor; address and per-run resources for Ray, whose
        local instance gets CPUs for ``jobs`` runs at once.
    """
    if settings["executor"] != "ray":
        return {"jobs": settings["jobs"], "threads_per_job": settings["threads"]}
    cpus = settings["cpus_per_job"]
    return {
        "address": settings["address"],
        "num_cpus_per_job": cpus,
        "num_gpus_per_job": settings["gpus_per_job"],
        "local_num_cpus": None if settings["address"] is not None else max(math.ceil(settings["jobs"] * cpus), 1),
    }


def _is_positive_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 1


def _agents(args: argparse.Namespace, preset: dict[str, Any], baselines: list[str]) -> list[str]:
    """--agents > --baseline > preset agents > preset baseline > default; EBM always leads unless --agents."""
    if args.agents:
        agents = list(args.agents)
    elif args.baseline is None and "agents" in preset:
        agents = list(preset["agents"]) if isinstance(preset["agents"], list) else [preset["agents"]]
    else:
        agents = [SUBJECT, *baselines]
    unknown = [name for name in agents if name not in AGENTS]
    if unknown:
        raise ValueError(f"unknown agent(s) {unknown}; choose from {', '.join(AGENTS)}")
    return list(dict.fromkeys(agents))


def _hyperparams(args: argparse.Namespace, preset: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The preset's per-agent hyperparameters, updated key by key by ``--hyperparams``."""
    hyperparams: dict[str, dict[str, Any]] = {}
    for agent, values in (preset.get("hyperparams") or {}).items():
        if agent not in AGENTS or not isinstance(values, dict):
            raise ValueError(
                f"preset hyperparams must map agent names ({', '.join(AGENTS)}) to keyword arguments, "
                f"got {agent!r}: {values!r}"
            )
        hyperparams[agent] = dict(values)
    for agent, values in _hyperparams_by_agent(args.hyperparams or [], list(AGENTS)).items():
        hyperparams.setdefault(agent, {}).update(values)
    return hyperparams


def resolve_env(name: str) -> str:
    """A short name or a registered id (optionally ``module:id``) -> the registered id.

    :param name: the ``--env`` value.
    :return: the Gymnasium id.
    """
    env_id = resolve_env_id(name)
    module, sep, bare_id = env_id.rpartition(":")
    if sep:
        try:
            importlib.import_module(module)
        except ImportError as error:
            raise ValueError(f"--env {name}: cannot import {module!r} to register the env ({error})") from None
        env_id = bare_id
    if env_id not in gym.registry:
        raise ValueError(
            f"unknown env {name!r}: use a short name ({', '.join([*ENV_IDS, *THIRD_PARTY_ENV_IDS])}) or a registered "
            "Gymnasium id "
            "(e.g. Pendulum-v1, or module:EnvId to import the module that registers it)"
        )
    return env_id


def build_jobs(settings: dict[str, Any], progress: bool = True, verbose: int = 0) -> list[Job]:
    """One job per env, agent and seed.

    :param settings: from ``resolve_settings``.
    :param progress: show SB3's progress bar inside runs (only when they run in this process).
    :param verbose: SB3 verbosity.
    :return: the jobs, env-major then agent then seed.
    """
    return [
        Job(
            env_id=env_id,
            agent=agent,
            seed=seed,
            timesteps=settings["timesteps"],
            eval_freq=settings["eval_freq"],
            eval_episodes=settings["eval_episodes"],
            hyperparams=dict(settings["hyperparams"].get(agent, {})),
            preset=settings.get("preset") or "",
            env_kwargs={**PROTOCOL_ENV_KWARGS.get(env_id, {}), **settings["env_kwargs"]},
            eval_env_kwargs=evaluation_kwargs(env_id, settings),
            device=settings["device"],
            out_dir=settings["out"],
            verbose=verbose,
            progress_bar=progress and settings["jobs"] == 1 and settings.get("executor", "local") == "local",
        )
        for env_id in settings["env_ids"]
        for agent in settings["agents"]
        for seed in settings["seeds"]
    ]


def evaluation_kwargs(env_id: str, settings: dict[str, Any]) -> dict[str, Any]:
    """Keyword arguments of the evaluation env: the harness's protocol for ``env_id`` (``envs.PROTOCOL_ENV_KWARGS``),
    the paper's evaluation configuration (``envs.PAPER_EVAL_KWARGS``), then ``--env-kwargs``, then
    ``--eval-env-kwargs`` (later ones win).

    :param env_id: the registered id.
    :param settings: the merged CLI settings.
    :return: the kwargs.
    """

    return {
        **PROTOCOL_ENV_KWARGS.get(env_id, {}),
        **PAPER_EVAL_KWARGS.get(env_id, {}),
        **settings["env_kwargs"],
        **settings["eval_env_kwargs"],
    }


def _anchors_for(jobs: Sequence[Job]) -> dict[str, Any]:

    anchors: dict[str, Any] = {}
    for job in jobs:
        if job.env_short in anchors:
            continue
        try:
            anchors[job.env_short] = compute_anchors(job.env_id, job.eval_env_kwargs)
        except Exception as error:  # the anchors are context; their failure must not cost the sweep
            print(f"ebm-eval: no anchors for {job.env_id}: {error}", file=sys.stderr)
            anchors[job.env_short] = None
    return anchors


def resolve_experiment_settings(args: argparse.Namespace) -> dict[str, Any]:
    """Check the flags of ``--experiment`` / ``--report-only`` and fill in their defaults.

    :param args: parsed flags.
    :return: experiments, parts, scale, seeds, out, docs, device and the executor's settings.
    :raises ValueError: for a flag that does not apply, an unknown experiment or scale.
    """

    given = [key for key in (*SWEEP_ONLY, *SWEEP_ONLY_MORE) if getattr(args, key, None) is not None]
    if given:
        flags = ", ".join("--" + key.replace("_", "-") for key in given)
        raise ValueError(
            f"{flags}: not with --experiment, whose experiments fix their envs, agents and budgets "
            "(choose --scale, --seeds, --part and --agents instead)"
        )
    names = list(args.experiment or ["all"])
    known = [*EXPERIMENTS, "all", "list"]
    unknown = [name for name in names if name not in known]
    if unknown:
        raise ValueError(f"unknown experiment(s) {', '.join(map(repr, unknown))}; choose from: {', '.join(known)}")
    if "list" in names and len(names) > 1:
        raise ValueError("--experiment list prints the experiments; give it alone")
    scale = args.scale or "paper"
    if scale not in SCALES:
        raise ValueError(f"unknown scale {scale!r}; choose one of: {', '.join(SCALES)}")
    out = args.out or RESULTS_DIR
    settings: dict[str, Any] = {
        "experiments": names,
        "parts": list(args.part) if args.part else None,
        "agents": list(args.agents) if args.agents else None,
        "scale": scale,
        "seeds": list(args.seeds) if args.seeds else None,
        "out": out,
        "docs": default_docs(args.docs, scale, out),
        "records": default_records(args.records, default_docs(args.docs, scale, out), out),
        "report_only": bool(args.report_only),
        "device": args.device or "auto",
        "jobs": args.jobs or 1,
        "threads": args.threads,
        "executor": args.executor or "local",
        "address": args.address,
        "cpus_per_job": args.cpus_per_job,
        "gpus_per_job": args.gpus_per_job,
    }
    _check_ray_settings(settings)
    return settings


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``ebm-eval``.

    :param argv: the arguments (default: ``sys.argv[1:]``).
    :return: 0 when every run finished, 1 when some failed (their error is in the report); bad flags exit 2.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.experiment is not None or args.report_only:
        try:
            experiment_settings = resolve_experiment_settings(args)
            parts = selected_parts(experiment_settings)
            executor = executor_from_name(experiment_settings["executor"], **executor_options(experiment_settings))
        except (ValueError, TypeError) as error:
            parser.error(str(error))  # exits 2, like any bad flag
        command_line = shlex.join(["ebm-eval", *(sys.argv[1:] if argv is None else argv)])
        return run_experiments(experiment_settings, parts, executor, command_line, progress=not args.no_progress)
    given = [key for key in (*EXPERIMENT_ONLY,) if getattr(args, key, None) is not None]
    if given:
        flags = ", ".join("--" + key.replace("_", "-") for key in given)
        parser.error(f"{flags}: only with --experiment (or --report-only)")
    try:
        settings = resolve_settings(args)
        executor = executor_from_name(settings["executor"], **executor_options(settings))
    except (ValueError, TypeError) as error:
        parser.error(str(error))  # exits 2, like any bad flag

    progress = not args.no_progress
    out = Path(settings["out"])
    out.mkdir(parents=True, exist_ok=True)
    command = ["ebm-eval", *(sys.argv[1:] if argv is None else argv)]
    (out / "config.yaml").write_text(
        yaml.safe_dump(to_plain({**settings, "command": command, "versions": library_versions()}), sort_keys=False)
    )
    jobs = build_jobs(settings, progress=progress, verbose=args.verbose)
    print(
        f"ebm-eval: {len(jobs)} run(s) = {len(settings['env_ids'])} env(s) x agents {settings['agents']} x seeds "
        f"{settings['seeds']}, {settings['timesteps']} transitions each, into {out}/",
        file=sys.stderr,
    )
    anchors = _anchors_for(jobs)  # anchors of the env the scores come from
    (out / "anchors.json").write_text(json.dumps({env: a and asdict(a) for env, a in anchors.items()}, indent=2))

    results = executor.map(jobs, progress=progress)

    write_csv(results, out / "results.csv")
    text = write_markdown(results, out / "results.md", anchors, command)
    plot_learning_curves(results, out, anchors)
    print(text)
    print(f"Results in {out}/ (results.md, results.csv, learning_curves_*.png); curves: tensorboard --logdir {out}")
    return 0 if all(result.ok for result in results) else 1


if __name__ == "__main__":
    sys.exit(main())
