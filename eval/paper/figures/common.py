"""What every paper-figure experiment shares: its result record, its budgets per scale, and small helpers.

The experiments themselves live in ``eval/figures_*.py``; ``eval.paper.figures`` gathers them in ``FIGURES``. Each one
trains what it needs (seeded), measures, writes PNGs and a ``figure.json`` (a :class:`FigureResult`) under its
output folder. Two scales: ``"paper"`` (the paper's budgets: 50k online transitions, 100k random transitions for
pretraining) and ``"smoke"`` (tens of transitions and a tiny planner, so that tests run in seconds).
"""

from __future__ import annotations

import hashlib
import json
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib
import matplotlib.pyplot as plt

from ebm_agent.checkpoint_files import atomic_path
from eval import report
from eval.paper.data import figure_entry, paper_data
from eval.paper.parts import Part
from eval.provenance import agent_defaults_digest, read_json_dict, read_provenance

matplotlib.use("Agg")  # files only: experiments run headless

import gymnasium as gym
import numpy as np
from matplotlib.figure import Figure

import envs  # noqa: F401  registers the ebm/ ids
from ebm_agent import EBMPlannerAgent, collect_random_transitions
from ebm_agent.presets import PAPER_EBM, merge_settings
from eval.paper.records import SEED_FOLDER


@dataclass
class FigureResult:
    """What one figure experiment produced.

    :param name: the experiment's name, a key of ``eval.paper.figures.FIGURES`` (e.g. ``"plan_diversity"``).
    :param pngs: the PNG files written (under the output folder).
    :param metrics: the numbers behind the figure, JSON-serialisable.
    :param table_md: a markdown table for docs/results.md, or None.
    :param command: the command that reproduces it.
    """

    name: str
    pngs: list[Path]
    metrics: dict[str, Any]
    table_md: str | None
    command: str

    def save(self, out_dir: Path) -> Path:
        """Write ``out_dir/figure.json``; PNG paths under ``out_dir`` are stored relative to it.

        :param out_dir: the experiment's folder.
        :return: the JSON file.
        """
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        pngs = [_relative_to(Path(png), out_dir) for png in self.pngs]
        record = {
            "name": self.name,
            "pngs": pngs,
            "metrics": to_jsonable(self.metrics),
            "table_md": self.table_md,
            "command": self.command,
        }
        path = out_dir / "figure.json"
        path.write_text(json.dumps(record, indent=2, allow_nan=False) + "\n")
        return path

    @classmethod
    def load(cls, path: Path) -> FigureResult:
        """Read a ``figure.json`` written by :meth:`save`; relative PNG paths are resolved against its folder.

        :param path: the JSON file.
        :return: the result.
        """
        path = Path(path)
        record = json.loads(path.read_text())
        missing = {"name", "pngs", "metrics", "table_md", "command"} - set(record)
        if missing:
            raise ValueError(f"{path} is not a figure.json: missing keys {sorted(missing)}")
        pngs = [Path(p) if Path(p).is_absolute() else path.parent / p for p in record["pngs"]]
        return cls(record["name"], pngs, record["metrics"], record["table_md"], record["command"])


@dataclass(frozen=True)
class FigureBudget:
    """How much each figure experiment trains and samples.

    :param online_timesteps: online transitions of each trained agent (the paper's 50,000).
    :param pretrain_transitions: random transitions of a pretraining dataset (the paper's 100,000).
    :param pretrain_epochs: passes over it (10 as the original).
    :param eval_episodes: deterministic evaluation episodes per trained seed.
    :param maze_timesteps: transitions of each maze exploration run (EBM and random alike).
    :param sawyer_ebm_timesteps: transitions of each EBM Sawyer exploration run.
    :param sawyer_random_timesteps: transitions of each random Sawyer exploration run (the paper: random needs over
        200,000 to reach maximum occupancy).
    :param curve_points: checkpoints of the exploration curves.
    :param energy_snapshots: energy maps taken during training.
    :param energy_resolution: cells per axis of a drawn energy map (the original: 300).
    :param plan_samples: plans drawn per configuration in the planning figures.
    :param diversity_horizons: the planning horizons compared by ``plan_diversity``.
    :param reacher_horizon: planning horizon of ``reacher_directions`` (a half turn takes more than 10 steps).
    :param planner: ``MPPIConfig`` fields overriding the EBM planner's defaults (empty: the defaults).
    :param ff_planner: ``ActionPlannerConfig`` fields overriding the Action FF planner's defaults.
    """

    online_timesteps: int
    pretrain_transitions: int
    pretrain_epochs: int
    eval_episodes: int
    maze_timesteps: int
    sawyer_ebm_timesteps: int
    sawyer_random_timesteps: int
    curve_points: int
    energy_snapshots: int
    energy_resolution: int
    plan_samples: int
    diversity_horizons: tuple[int, ...]
    reacher_horizon: int
    planner: dict[str, Any] = field(default_factory=dict)
    ff_planner: dict[str, Any] = field(default_factory=dict)


def _budget(fields: dict[str, Any]) -> FigureBudget:
    values: dict[str, Any] = {key: tuple(value) if isinstance(value, list) else value for key, value in fields.items()}
    return FigureBudget(**values)


SCALES: dict[str, FigureBudget] = {name: _budget(fields) for name, fields in paper_data()["figure_budgets"].items()}
"""Budgets by scale (``paper.yaml``, ``figure_budgets``): ``"paper"`` reproduces the paper's, ``"smoke"`` runs in
seconds."""


def budget_for(scale: str) -> FigureBudget:
    """The budget of a scale.

    :param scale: a key of ``SCALES``.
    :return: its budget.
    """
    if scale not in SCALES:
        raise ValueError(f"unknown scale {scale!r}; choose one of {sorted(SCALES)}")
    return SCALES[scale]


def check_seeds(seeds: Sequence[int]) -> list[int]:
    """Validate the training seeds of an experiment.

    :param seeds: one or more distinct ints.
    :return: them as a list.
    """
    values = list(seeds)
    if not values or not all(isinstance(s, (int, np.integer)) and not isinstance(s, bool) for s in values):
        raise ValueError(f"seeds must be a non-empty sequence of ints, got {seeds!r}")
    if len(set(values)) != len(values):
        raise ValueError(f"seeds must be distinct, got {values}")
    return [int(s) for s in values]


def prepare(out_dir: Path, seeds: Sequence[int], scale: str) -> tuple[Path, list[int], FigureBudget]:
    """Check a figure experiment's seeds and scale and make its folder.

    :param out_dir: the figure's folder (created).
    :param seeds: its training seeds (:func:`check_seeds`).
    :param scale: a key of ``SCALES``.
    :return: (the folder, the seeds as a list, the scale's budget).
    """
    seeds, budget = check_seeds(seeds), budget_for(scale)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    return out_dir, seeds, budget


def finish(name: str, out_dir: Path, seeds: Sequence[int], scale: str, **drawn: Any) -> FigureResult:
    """Save what a figure experiment produced as its ``figure.json``, with the command that reproduces it.

    :param name: the figure, a key of ``eval.paper.figures.FIGURES``.
    :param out_dir: its folder.
    :param seeds: its seeds.
    :param scale: its scale.
    :param drawn: ``pngs``, ``metrics`` (made JSON-able here) and ``table_md`` of :class:`FigureResult`.
    :return: the saved result.
    """
    metrics = to_jsonable(drawn["metrics"])
    result = FigureResult(name, drawn["pngs"], metrics, drawn["table_md"], reproduce_command(name, scale, seeds))
    result.save(out_dir)
    return result


def reproduce_command(name: str, scale: str, seeds: Sequence[int]) -> str:
    """The ``ebm-eval`` command line that reruns one figure experiment.

    :param name: the figure (a key of ``eval.paper.figures.FIGURES``).
    :param scale: its scale.
    :param seeds: its seeds.
    :return: the command.
    """
    experiment = figure_entry(name)[0]
    command = f"ebm-eval --experiment {experiment} --seeds {' '.join(str(s) for s in seeds)}"
    return command if scale == "paper" else f"{command} --scale {scale}"


FIGURE_PRESET = "paper"
"""The agent preset every figure trains with (``ebm_agent.presets``): the figures reproduce the paper."""


def figure_defaults_digest(agents: Sequence[str] = ("ebm", "action-ff"), env_id: str = "ebm/Particle-v0") -> str:
    """A short hash of the library defaults of the agents a figure trains (``eval.provenance``'s digests).

    :param agents: agent names of ``eval.registry.AGENTS``.
    :param env_id: the env the defaults are read for.
    :return: 16 hex digits.
    """

    parts = "/".join(str(agent_defaults_digest(agent, env_id, FIGURE_PRESET)) for agent in agents)
    return hashlib.sha256(parts.encode()).hexdigest()[:16]


def paper_numbers(figure: str) -> dict[str, float]:
    """The paper's numbers a figure shows beside ours (``paper.yaml``), never used in a computation.

    :param figure: a key of ``eval.paper.figures.FIGURES``.
    :return: label -> number (empty where the paper gives none).
    """
    return dict(figure_entry(figure)[1].get("paper") or {})


def figure_digest(figure: str) -> str | None:
    """The defaults digest a figure's results are valid for (:func:`figure_defaults_digest` of its agents).

    A finished figure records it (``provenance.json``); ``eval.paper.runner.figure_complete`` takes a figure made
    under other defaults as not finished, so that ``ebm-eval --experiment`` reruns it and the report says so.

    :param figure: a key of ``eval.paper.figures.FIGURES``.
    :return: 16 hex digits, or None for a figure ``paper.yaml`` does not list with its agents (its results are
        taken as they are).
    """
    try:
        part = figure_entry(figure)[1]
    except KeyError:
        return None
    if not part.get("agents"):
        return None
    return figure_defaults_digest(tuple(part["agents"]), part["env"])


def seed_result_path(out_dir: Path, figure: str, seed: int) -> Path:
    """Where :func:`seed_result` keeps one seed's result: ``<out_dir>/seeds/<figure>_seed<k>.json``."""
    return Path(out_dir) / SEED_FOLDER / f"{figure}_seed{seed}.json"


def seed_result(
    out_dir: Path, figure: str, seed: int, compute: Callable[[], dict[str, Any]], digest: str | None = None
) -> dict[str, Any]:
    """One seed's share of a figure (its agents trained and measured), computed once per figure folder.

    A figure trains its own agents, up to an hour per seed on 2 cores at the paper's scale, and is finished only
    when all its seeds are. A figure cut short (a session's end, a killed process) keeps each seed it finished as
    ``<out_dir>/seeds/<figure>_seed<k>.json`` (written atomically); the next run of the figure in the same folder
    reads those back and trains only the missing seeds. A seed saved with other library defaults (``digest``) or
    that cannot be read is computed again.

    :param out_dir: the figure's folder.
    :param figure: the figure's name.
    :param seed: the training seed.
    :param compute: trains and measures the seed; returns a JSON-able dict (numpy arrays come back as lists).
    :param digest: the defaults' digest the result is valid for (default: :func:`figure_defaults_digest`).
    :return: the seed's result, as JSON types.
    """

    digest = figure_defaults_digest() if digest is None else digest
    path = seed_result_path(out_dir, figure, seed)
    record = read_json_dict(path)
    if record is not None and record.get("seed") == seed and record.get("defaults_digest") == digest:
        return dict(record["result"])
    start = time.perf_counter()
    result = to_jsonable(compute())
    record = {"figure": figure, "seed": seed, "defaults_digest": digest, "result": result}
    record["wall_time_s"] = time.perf_counter() - start  # a resumed figure adds it to its own time
    with atomic_path(path) as temporary:
        temporary.write_text(json.dumps(record))
    # One line per seed says that a long figure is alive (a Sawyer exploration seed takes about an hour).
    print(f"figure {figure}: seed {seed} finished in {record['wall_time_s'] / 60:.1f} min, kept in {path}", file=sys.stderr)
    return dict(result)


def build_ebm(env: gym.Env, seed: int, budget: FigureBudget, **kwargs: Any) -> EBMPlannerAgent:
    """An EBM agent of the paper preset (``ebm_agent.presets.PAPER_EBM``: figures reproduce the paper) with the
    budget's planner settings and no TensorBoard images.

    :param env: its env.
    :param seed: its seed.
    :param budget: the scale's budget.
    :param kwargs: further ``EBMPlannerAgent`` arguments (e.g. ``cost``).
    :return: the untrained agent.
    """
    settings = merge_settings(PAPER_EBM, {"planner_config": budget.planner})
    settings = merge_settings(settings, kwargs)
    return EBMPlannerAgent("MultiInputPolicy", env, seed=seed, image_log_interval=0, **settings)


def pretrained_ebm(env_id: str, seed: int, budget: FigureBudget, **kwargs: Any) -> EBMPlannerAgent:
    """An EBM pretrained on random transitions of the env (the paper's "pretrained" setting).

    :param env_id: registered id.
    :param seed: seed of the agent and of the dataset.
    :param budget: the scale's budget (dataset size and epochs).
    :param kwargs: further ``EBMPlannerAgent`` arguments.
    :return: the trained agent.
    """
    dataset = collect_random_transitions(env_id, num_transitions=budget.pretrain_transitions, seed=seed)
    agent = build_ebm(gym.make(env_id), seed, budget, **kwargs)
    agent.learn_offline(dataset, epochs=budget.pretrain_epochs, log_interval=0)
    return agent


def run_episode(agent: Any, env: gym.Env, seed: int) -> tuple[float, np.ndarray, bool]:
    """One deterministic episode, as SB3's ``evaluate_policy`` plays it (plan carried in ``state``).

    :param agent: anything with SB3's ``predict``.
    :param env: the env (with its ``TimeLimit``).
    :param seed: seed of ``reset``.
    :return: (score: the undiscounted sum of rewards, achieved goals visited [L+1, G], success at the end).
    """
    observation, _ = env.reset(seed=seed)
    positions = [np.asarray(observation["achieved_goal"], dtype=np.float64)]
    state, episode_start = None, np.ones(1, dtype=bool)
    score, done = 0.0, False
    info: dict[str, Any] = {}
    while not done:
        action, state = agent.predict(observation, state=state, episode_start=episode_start, deterministic=True)
        episode_start = np.zeros(1, dtype=bool)
        observation, reward, terminated, truncated, info = env.step(action)
        positions.append(np.asarray(observation["achieved_goal"], dtype=np.float64))
        score += float(reward)
        done = bool(terminated or truncated)
    return score, np.stack(positions), bool(info.get("is_success", False))


def summary(values: Sequence[float] | np.ndarray) -> dict[str, float]:
    """Mean and population std (the harness's convention) of some numbers.

    :param values: the numbers.
    :return: ``{"mean": ..., "std": ...}``.
    """
    array = np.asarray(values, dtype=np.float64)
    return {"mean": float(array.mean()), "std": float(array.std())}


def save_png(figure: Figure, path: Path) -> Path:
    """Write a figure to a PNG and close it.

    :param figure: the figure.
    :param path: the file.
    :return: ``path``.
    """

    try:
        if figure.get_layout_engine() is None:
            figure.tight_layout()
        figure.savefig(path, dpi=120)
    finally:
        plt.close(figure)
    return path


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A figure's markdown table (``eval.report.markdown_table``; None is an em dash).

    :param header: column titles.
    :param rows: the cells.
    :return: the table.
    """
    return report.markdown_table(header, rows, missing="—")


def to_jsonable(value: Any) -> Any:
    """Turn numpy scalars/arrays, tuples and paths into JSON types, and NaN/inf into None.

    :param value: a nested structure of dicts, lists and numbers.
    :return: the same structure with JSON types only.
    """
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(float(value)) else None
    if isinstance(value, Path):
        return str(value)
    return value


def _relative_to(path: Path, folder: Path) -> str:
    try:
        return str(path.relative_to(folder))
    except ValueError:
        return str(path)


def figure_complete(part: Part) -> bool:
    """Whether the figure part's folder holds a ``figure.json`` made at the part's scale and seeds, under today's
    library defaults (:func:`figure_state` is ``"complete"``).

    :param part: a figure part.
    :return: True when complete.
    """
    return figure_state(part) == "complete"


def figure_state(part: Part) -> str:
    """What the figure part's folder holds.

    A figure is made under the defaults of the agents it trains (``eval.paper.figures.common.figure_digest``); one made
    under others is ``"retired"``, as a table's run is (``eval.provenance.is_current_run``): ``ebm-eval
    --experiment`` makes it again, and the report says that a rerun is pending. The digest is read from the figure's
    ``provenance.json`` or, for a figure finished before it recorded one, from its kept seeds (``seeds/*.json``); a
    figure with neither is taken as it is, as a run finished before runs recorded their defaults.

    :param part: a figure part.
    :return: ``"complete"``, ``"retired"`` (made under other library defaults) or ``"missing"`` (not finished, or of
        another scale or seeds).
    """

    folder = part.figure_dir
    record = read_provenance(folder)
    if not (folder / "figure.json").exists() or record is None:
        return "missing"
    if record.get("scale") != part.scale or list(record.get("seeds", [])) != list(part.seeds):
        return "missing"
    current = figure_digest(str(part.figure))
    recorded = recorded_figure_digests(folder, record)
    return "retired" if current is not None and any(digest != current for digest in recorded) else "complete"


def recorded_figure_digests(folder: Path | str, record: dict[str, Any]) -> set[str]:
    """The defaults digests a finished figure was made under: its provenance's, else its kept seeds'.

    :param folder: the figure's folder (in a results folder or the records).
    :param record: its ``provenance.json``.
    :return: the digests (empty for a figure finished before it recorded any).
    """
    folder = Path(folder)
    if isinstance(record.get("defaults_digest"), str):
        return {record["defaults_digest"]}
    seeds = [read_json_dict(path) or {} for path in sorted((folder / SEED_FOLDER).glob("*.json"))]
    return {seed["defaults_digest"] for seed in seeds if isinstance(seed.get("defaults_digest"), str)}


def figure_seeds_kept(part: Part) -> list[int]:
    """The part's seeds already made under today's defaults and kept in its folder (``seeds/*.json``), which the
    next ``ebm-eval --experiment`` reuses: the progress of a figure that is not finished, or is being made again.

    :param part: a figure part.
    :return: those seeds, sorted; only seeds the part asks for.
    """
    if part.figure is None:
        return []
    seeds = {(read_json_dict(path) or {}).get("seed") for path in _current_seed_files(part.figure_dir, str(part.figure))}
    return sorted(seed for seed in seeds if isinstance(seed, int) and seed in part.seeds)


def _current_seed_files(folder: Path, figure: str) -> list[Path]:
    """The kept seeds (``seeds/*.json``) a resumed figure reuses: those made under today's defaults (the figure
    computes the others again, ``eval.paper.figures.common.seed_result``)."""

    current = figure_digest(figure)
    kept = sorted((folder / SEED_FOLDER).glob("*.json"))
    if current is None:
        return kept
    return [path for path in kept if (read_json_dict(path) or {}).get("defaults_digest") == current]


__all__ = [
    "SCALES",
    "SEED_FOLDER",
    "FigureBudget",
    "FigureResult",
    "budget_for",
    "build_ebm",
    "check_seeds",
    "figure_complete",
    "figure_defaults_digest",
    "figure_digest",
    "figure_seeds_kept",
    "figure_state",
    "finish",
    "markdown_table",
    "paper_numbers",
    "prepare",
    "pretrained_ebm",
    "recorded_figure_digests",
    "reproduce_command",
    "run_episode",
    "save_png",
    "seed_result",
    "seed_result_path",
    "summary",
    "to_jsonable",
]
