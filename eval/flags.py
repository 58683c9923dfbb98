"""The ``ebm-eval`` command line: its flags, their argparse types and the built-in defaults.

``eval.cli`` resolves what these flags mean (presets, experiments, executors) and runs them.
"""

from __future__ import annotations

import argparse
from typing import Any

import yaml

from envs import ENV_IDS, THIRD_PARTY_ENV_IDS
from eval.registry import AGENTS

DEFAULTS: dict[str, Any] = {
    "env": ["particle"],
    "baseline": ["ppo"],
    "timesteps": 2000,
    "seeds": [0],
    "eval_episodes": 10,
    "eval_freq": None,  # timesteps // 5
    "env_kwargs": {},
    "eval_env_kwargs": {},
    "hyperparams": {},
    "preset": "",  # the library's defaults
    "device": "auto",
    "jobs": 1,
    "threads": None,  # local only: torch's default in-process (every core), 1 per --jobs worker
    "executor": "local",
    "address": None,  # Ray only: a local Ray instance
    "cpus_per_job": None,  # Ray only: 1
    "gpus_per_job": None,  # Ray only: 1 with a cuda device, else 0
    "out": None,  # runs/ebm-eval-<timestamp>
}
"""Built-in defaults: ``ebm-eval`` alone runs EBM vs PPO on the particle env within minutes on 2 CPU cores."""

SUBJECT = "ebm"
"""The agent under test: always run, unless ``--agents`` lists the agents explicitly."""

RESULTS_DIR = "runs/results"
"""Default results folder of ``--experiment``."""

PAPER_DOC = "docs/results.md"
"""Default document of ``--experiment`` at the paper's scale (other scales write ``<out>/results.md``)."""

SWEEP_ONLY = ("env", "baseline", "timesteps", "eval_episodes", "eval_freq", "config", "env_kwargs")
SWEEP_ONLY_MORE = ("eval_env_kwargs", "hyperparams", "preset")
EXPERIMENT_ONLY = ("part", "scale", "docs", "records")


def positive_int(text: str) -> int:
    """Argparse type: an integer >= 1.

    :param text: the flag's value.
    :return: the integer.
    """
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer (at least 1), got {value}")
    return value


def seed_int(text: str) -> int:
    """Argparse type: an integer >= 0.

    :param text: the flag's value.
    :return: the integer.
    """
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"seeds are non-negative integers, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"seeds are non-negative integers, got {value}")
    return value


def parse_value(text: str) -> Any:
    """A ``key=value`` value read as YAML (``[0, 0]``, ``true``, ``64``), with ``1e-3`` read as a float.

    :param text: the value text.
    :return: the Python value.
    """
    value = yaml.safe_load(text)
    if isinstance(value, str):
        try:
            return float(value)  # YAML 1.1 reads 1e-3 as a string; rl-zoo3 users expect a number
        except ValueError:
            return value
    return value


def resource_amount(text: str) -> float:
    """Argparse type: a non-negative number of CPUs or GPUs (fractions share one).

    :param text: the flag's value.
    :return: the number.
    """
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of CPUs or GPUs such as 1 or 0.5, got {text!r}") from None
    if not value >= 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text}")
    return int(value) if value.is_integer() else value


def key_value(text: str) -> tuple[str, Any]:
    """Argparse type: ``key=value``.

    :param text: the flag's item.
    :return: (key, parsed value).
    """
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"expected key=value, got {text!r} (e.g. goal=[0.5,0.5] or ppo:n_steps=256)")
    try:
        return key.strip(), parse_value(value)
    except yaml.YAMLError as error:
        raise argparse.ArgumentTypeError(f"cannot read the value of {key!r}: {error}") from None


def build_parser() -> argparse.ArgumentParser:
    """The ``ebm-eval`` argument parser (flags in rl-zoo3's style).

    :return: the parser.
    """

    baselines = [name for name in AGENTS if name != SUBJECT]
    parser = argparse.ArgumentParser(
        prog="ebm-eval",
        description="Train the EBM planning agent and baselines on exactly the same number of transitions, "
        "evaluate them the paper's way and write a comparison table, learning curves and TensorBoard logs.",
        epilog="Examples: `ebm-eval --baseline ppo`; `ebm-eval --config particle_online --jobs 2`; "
        "`ebm-eval --env maze --baseline ppo --baseline action-ff --seeds 0 1 2`.",
    )
    parser.add_argument(
        "--env",
        nargs="+",
        action="extend",
        metavar="ENV",
        help=f"env(s): a short name ({', '.join([*ENV_IDS, *THIRD_PARTY_ENV_IDS])}) or any registered Gymnasium id "
        "(default: particle)",
    )
    parser.add_argument(
        "--baseline",
        nargs="+",
        action="extend",
        choices=baselines,
        metavar="NAME",
        help=f"baseline(s) run beside the EBM agent: {', '.join(baselines)}; repeat the flag for several (default: ppo)",
    )
    parser.add_argument(
        "--agents",
        nargs="+",
        action="extend",
        choices=list(AGENTS),
        metavar="NAME",
        help=f"the full list of agents, replacing EBM + baselines: {', '.join(AGENTS)}; with --experiment, only "
        "the runs of these agents (figures are left out)",
    )
    parser.add_argument(
        "-n",
        "--timesteps",
        type=positive_int,
        help=f"budget: transitions every agent learns from, exactly (default: {DEFAULTS['timesteps']})",
    )
    parser.add_argument("--seeds", nargs="+", type=seed_int, metavar="SEED", help="training seeds, one run each (default: 0)")
    parser.add_argument(
        "--eval-episodes",
        type=positive_int,
        help=f"deterministic episodes per evaluation (default: {DEFAULTS['eval_episodes']})",
    )
    parser.add_argument(
        "--eval-freq", type=positive_int, help="evaluate every this many transitions (default: timesteps // 5)"
    )
    parser.add_argument("-f", "--out", help="output folder (default: runs/ebm-eval-<timestamp>)")
    parser.add_argument("--device", help="torch device of the agents: auto, cpu, cuda, cuda:1 (default: auto)")
    parser.add_argument(
        "-c", "--config", help="preset: a bundled name (see eval/presets/) or a YAML file; explicit flags win over it"
    )
    parser.add_argument("-j", "--jobs", type=positive_int, help="runs executed at once, one process each (default: 1)")
    parser.add_argument(
        "--threads",
        type=positive_int,
        help="torch threads of each run, and of the figures (which run in the ebm-eval process), with the local "
        "executor (default: torch's own, every core, for --jobs 1 and figures; 1 per run otherwise); give 1 to each "
        "of several ebm-eval processes that share the cores",
    )
    parser.add_argument(
        "--executor",
        help="where runs execute: local (process pool; default) or ray (Ray tasks, needs the ray extra; see docs/ray.md)",
    )
    parser.add_argument(
        "--address",
        help="with --executor ray: the Ray cluster, auto (the one this machine belongs to), ray://<head>:10001 "
        "(Ray Client) or <head-ip>:6379 (default: a local Ray instance with --jobs x --cpus-per-job CPUs)",
    )
    parser.add_argument(
        "--cpus-per-job",
        type=resource_amount,
        metavar="N",
        help="with --executor ray: CPUs each run reserves, also its torch threads (default: 1)",
    )
    parser.add_argument(
        "--gpus-per-job",
        type=resource_amount,
        metavar="N",
        help="with --executor ray: GPUs each run reserves, 0.5 shares one between two (default: 1 with a cuda "
        "--device, else 0; with 0 Ray hides the GPUs from the run)",
    )
    parser.add_argument(
        "--env-kwargs",
        nargs="+",
        action="extend",
        type=key_value,
        metavar="KEY=VALUE",
        help="gym.make keyword arguments, values in YAML (e.g. goal=[0.5,0.5])",
    )
    parser.add_argument(
        "--eval-env-kwargs",
        nargs="+",
        action="extend",
        type=key_value,
        metavar="KEY=VALUE",
        help="changes to --env-kwargs for the evaluation env only (e.g. start=[0,0]: train from random starts, "
        "evaluate from the paper's start)",
    )
    parser.add_argument(
        "--preset",
        choices=("", "paper", "fast"),
        help="agent preset of the EBM agent and Action FF (ebm_agent.presets): paper = the original code's settings "
        "in full (80 MPPI iterations for every plan, the evaluation goal weight = the training weight), fast = 3 "
        "iterations for warm-started and 20 for fresh training plans (5-15x cheaper learning; lower scores on the "
        "Sawyer); --hyperparams apply over it (default: the library's defaults)",
    )
    parser.add_argument(
        "-params",
        "--hyperparams",
        nargs="+",
        action="extend",
        type=key_value,
        metavar="[AGENT:]KEY=VALUE",
        help="agent keyword arguments, values in YAML; a plain key goes to the EBM agent, AGENT:KEY to that agent "
        "(e.g. horizon=20 ppo:n_steps=256)",
    )
    experiments = parser.add_argument_group(
        "paper experiments",
        "run the paper's tables and figures by name (eval/paper/experiments.py), resumably, and write "
        "docs/results.md; the sweep flags above (--env, --timesteps, ...) do not apply",
    )
    experiments.add_argument(
        "--experiment",
        nargs="+",
        action="extend",
        metavar="NAME",
        help="experiment(s) to run: table1, table2, sawyer_ppo, fixed_on_variable, inverse_dynamics, obstacle, "
        "plan_diversity, reacher_directions, maze_exploration, sawyer_exploration, energy_maps; all; or list "
        "(print the experiments, their parts and estimated cost)",
    )
    experiments.add_argument(
        "--part",
        nargs="+",
        action="extend",
        metavar="GLOB",
        help="only the parts matching these globs, e.g. 'table1/particle/*' or '*/sawyer*' (default: all parts)",
    )
    experiments.add_argument(
        "--scale", help="paper (the paper's budgets; default) or smoke (tiny budgets, runs in <out>/smoke/)"
    )
    experiments.add_argument(
        "--report-only",
        action="store_true",
        help="only regenerate the results document from the results folder (no training)",
    )
    experiments.add_argument(
        "--docs",
        metavar="PATH",
        help=f"the results document (default: {PAPER_DOC} at the paper's scale from {RESULTS_DIR}, else <out>/results.md)",
    )
    experiments.add_argument(
        "--records",
        metavar="DIR",
        help="keep the small files of finished runs and figures in DIR, restored into the results folder before "
        "running or reporting and saved after (default: docs/records for docs/results.md from runs/results, else "
        "none; 'none': off)",
    )
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    parser.add_argument("-v", "--verbose", type=int, default=0, help="SB3 verbosity of the agents: 0, 1 or 2 (default: 0)")
    return parser


__all__ = [
    "DEFAULTS",
    "EXPERIMENT_ONLY",
    "PAPER_DOC",
    "RESULTS_DIR",
    "SUBJECT",
    "SWEEP_ONLY",
    "SWEEP_ONLY_MORE",
    "build_parser",
    "key_value",
    "parse_value",
    "positive_int",
    "resource_amount",
    "seed_int",
]
