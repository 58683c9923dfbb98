"""``python -m eval.paper.probe``: one cell of a paper experiment with some of the agent's settings changed, scored as
the experiment scores it.

Usage:
    python -m eval.paper.probe table1/particle/pretrained action-ff residual=true --seeds 0 1 2
    python -m eval.paper.probe table1/reacher/online ebm "cost={goal_weight: 0.1}" --seeds 0
    python -m eval.paper.probe table1/reacher/pretrained ebm --env inverse_angle_weight=30 --seeds 0
    python -m eval.paper.probe table2/sawyer/pretrained_directed action-ff standardize_outputs=false --seeds 0 \
        --datasets runs/results/datasets

Runs the jobs of the cell (``ebm-eval --experiment <experiment> --part <part>``, agent ``AGENT``) with the given
keyword arguments of the agent replaced (values in YAML, as ``ebm-eval --hyperparams``) and ``--env KEY=VALUE``
keyword arguments of the training and evaluation envs replaced, into its own results folder
(``runs/probe/<part>/<agent>/<changes>``; nothing is mixed with ``runs/results``), and prints each seed's score of its
deterministic evaluation episodes, their mean and std, and the wall time. A finished probe run is not rerun.
"""

from __future__ import annotations

import argparse
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml

from eval.jobs import Job
from eval.paper.experiments import build_parts, make_context, select_parts
from eval.provenance import completed_result
from eval.run import run_job


def parse_change(text: str) -> tuple[str, object]:
    """``key=value`` with a YAML value.

    :param text: the change.
    :return: (key, value).
    :raises argparse.ArgumentTypeError: without ``=``.
    """
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    return key, yaml.safe_load(value)


def with_env_changes(job: Job, env_changes: dict[str, object]) -> Job:
    """The job with ``env_changes`` merged into its training env's and evaluation envs' keyword arguments.

    :param job: the cell's job.
    :param env_changes: env keyword arguments to set.
    :return: the changed job (``job`` itself when there are none).
    """
    if not env_changes:
        return job
    eval_env_kwargs = None if job.eval_env_kwargs is None else {**job.eval_env_kwargs, **env_changes}
    return replace(job, env_kwargs={**job.env_kwargs, **env_changes}, eval_env_kwargs=eval_env_kwargs)


def main(argv: list[str] | None = None) -> list[float]:
    """Run the probe.

    :param argv: the arguments (default: the command line's).
    :return: each seed's mean score.
    """
    parser = argparse.ArgumentParser(prog="python -m eval.paper.probe", description=__doc__.splitlines()[0])
    parser.add_argument("part", help="a part of a paper experiment, e.g. table1/particle/pretrained")
    parser.add_argument("agent", help="the cell's agent: ebm or action-ff")
    parser.add_argument("changes", nargs="*", type=parse_change, help="KEY=VALUE agent keyword arguments")
    parser.add_argument(
        "--env", action="append", default=[], type=parse_change, metavar="KEY=VALUE", help="an env keyword argument"
    )
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--episodes", type=int, help="deterministic evaluation episodes (default: the part's)")
    parser.add_argument("--out", default="runs/probe", help="root of the probe's results folders")
    parser.add_argument("--scale", default="paper", help="the experiment's scale: paper (default) or smoke")
    parser.add_argument(
        "--datasets",
        help="a results folder's datasets/ to pretrain from (e.g. runs/results/datasets), linked into the probe's "
        "folder so that a directed dataset is reused rather than collected again (hours on the Sawyer)",
    )
    args = parser.parse_args(argv)
    changes = dict(args.changes)
    env_changes = dict(args.env)
    labels = [f"{key}-{value}" for key, value in changes.items()]
    labels += [f"env.{key}-{value}" for key, value in env_changes.items()]
    label = "_".join(labels) or "unchanged"
    out = f"{args.out}/{args.part}/{args.agent}/{re.sub(r'[^A-Za-z0-9_.-]+', '', label)}"
    if args.datasets:
        link_datasets(Path(args.datasets), Path(out))
    experiment = args.part.split("/")[0]
    try:
        part = select_parts(build_parts([experiment], make_context(args.scale, out)), [args.part])[0]
    except (KeyError, ValueError) as error:  # an unknown experiment, part or scale
        parser.error(f"{args.part!r} at scale {args.scale!r}: {error}")
    cell = next((cell for cell in part.cells if cell.agent == args.agent), None)
    if cell is None:
        parser.error(f"{args.part} has no cell of agent {args.agent!r}; its agents: {[c.agent for c in part.cells]}")
    scores = []
    for seed in args.seeds:
        job = with_env_changes(
            replace(cell.jobs[0], seed=seed, hyperparams={**cell.jobs[0].hyperparams, **changes}), env_changes
        )
        job = replace(job, eval_episodes=args.episodes) if args.episodes else job
        result = completed_result(job) or run_job(job)
        if not result.ok:
            raise SystemExit(f"seed {seed} failed: {result.error}")
        scores.append(result.score_mean)
        settings = f"{changes} env {env_changes}" if env_changes else f"{changes}"
        print(f"{args.part} {args.agent} {settings} seed {seed}: {result.score_mean:.2f} ({result.wall_time_s:.0f} s)")
    print(f"mean {np.mean(scores):.2f} ± {np.std(scores):.2f} over {len(scores)} seed(s); results in {out}/")
    return scores


def link_datasets(source: Path, out: Path) -> None:
    """Make ``<out>/datasets`` a link to ``source``, the cached datasets of another results folder.

    :param source: an existing ``datasets`` folder.
    :param out: the probe's results folder.
    :raises SystemExit: when ``source`` is not a folder, or ``<out>/datasets`` exists and is something else.
    """
    if not source.is_dir():
        raise SystemExit(f"--datasets {source}: no such folder (give a results folder's datasets/).")
    link = out / "datasets"
    if link.is_symlink() and link.resolve() == source.resolve():
        return
    if link.exists() or link.is_symlink():
        raise SystemExit(f"{link} already exists and is not a link to {source}; remove it or drop --datasets.")
    out.mkdir(parents=True, exist_ok=True)
    link.symlink_to(source.resolve(), target_is_directory=True)


if __name__ == "__main__":
    main()
