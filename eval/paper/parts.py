"""The units of the reproduction: scales (budgets), cells (one table number over seeds), parts (what runs, resumes
and is reported on its own) and experiments, with a rough cost estimate of each part.

``eval.paper.experiments`` builds the paper's experiments from these; ``eval.paper.runner`` runs parts and
``eval.paper.results_doc`` reports them.
"""

from __future__ import annotations

import shlex
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

from envs import ENV_IDS, PAPER_EVAL_KWARGS, PROTOCOL_ENV_KWARGS, THIRD_PARTY_ENV_IDS
from eval.jobs import Job
from eval.paper.data import paper_data
from eval.presets import PRESET_DIR, load_preset

AGENT_LABELS = {"ebm": "EBM", "action-ff": "Action FF", "ppo": "PPO", "random": "Random", "sac-her": "SAC + HER"}
"""How agents are named in tables."""


@dataclass(frozen=True)
class Scale:
    """Budgets of one scale.

    :param name: ``paper`` or ``smoke``.
    :param online: transitions of an online run.
    :param pretrain: transitions of a pretraining dataset.
    :param eval_episodes: deterministic episodes per evaluation.
    :param evaluations: evaluations per online run (points of its learning curve, the last at the budget).
    :param seeds: default training seeds.
    :param figure_seeds: default seeds of a figure, by figure (others: ``seeds``).
    :param env_kwargs: added to every env's kwargs (smoke: short episodes).
    :param hyperparams: agent name -> keyword arguments added to every run of that agent (smoke: tiny planners).
    :param offline_kwargs: ``learn_offline`` settings of pretrained runs (empty: ``eval.pretraining``'s defaults).
    :param sequential_kwargs: the same for the sequential dataset.
    :param folder: subfolder of the output folder holding this scale's runs ("" for the paper's scale), so a smoke
        run never replaces a paper run.
    """

    name: str
    online: int
    pretrain: int
    eval_episodes: int
    evaluations: int
    seeds: tuple[int, ...]
    figure_seeds: dict[str, tuple[int, ...]] = field(default_factory=dict)
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    hyperparams: dict[str, dict[str, Any]] = field(default_factory=dict)
    offline_kwargs: dict[str, Any] = field(default_factory=dict)
    sequential_kwargs: dict[str, Any] = field(default_factory=dict)
    folder: str = ""


def _scale(name: str, fields: dict[str, Any]) -> Scale:
    """A scale from its ``paper.yaml`` entry (lists become tuples)."""
    values: dict[str, Any] = {key: tuple(value) if isinstance(value, list) else value for key, value in fields.items()}
    if "figure_seeds" in fields:
        values["figure_seeds"] = {figure: tuple(seeds) for figure, seeds in fields["figure_seeds"].items()}
    return Scale(name=name, **values)


SCALES: dict[str, Scale] = {name: _scale(name, fields) for name, fields in paper_data()["scales"].items()}
"""The scales ``--scale`` accepts (``paper.yaml``, ``scales``)."""


@dataclass(frozen=True)
class Cell:
    """One number of a table: the runs of one configuration over seeds, and the paper's number beside it.

    :param setting: the row's label (``pretrained``, ``online``, ``PPO 5x``, ``RLS`` ...).
    :param env: env short name.
    :param agent: agent name (a key of ``eval.registry.AGENTS``).
    :param jobs: one job per seed.
    :param paper: the paper's number, None where it gives none.
    :param paper_note: what the paper says instead of (or beside) a number.
    :param evaluation: the name of an extra evaluation (``Job.extra_evaluations``) whose score stands for the cell,
        None for the run's main evaluation.
    :param key: what tells the cell from the part's other cells of the same agent (its id's last part), or None.
    :param why: the ``notes.md`` id of why the cell differs from the paper, or None (not investigated).
    :param part: the name of the part it belongs to.
    """

    setting: str
    env: str
    agent: str
    jobs: tuple[Job, ...]
    paper: float | None = None
    paper_note: str = ""
    evaluation: str | None = None
    key: str | None = None
    why: str | None = None
    part: str = ""

    @property
    def id(self) -> str:
        """``<part>:<agent>[:<key>]``, by which ``paper.yaml``'s claims name the cell."""
        return f"{self.part}:{self.agent}" + (f":{self.key}" if self.key else "")

    @property
    def label(self) -> str:
        """The agent's name in tables."""
        return AGENT_LABELS.get(self.agent, self.agent)


@dataclass(frozen=True)
class Part:
    """A unit of work that runs, resumes and is reported on its own: table cells, or one figure.

    :param name: ``<experiment>/<...>``, matched by ``--part`` globs.
    :param experiment: the experiment's name.
    :param scale: the scale it was built for.
    :param out_dir: the results folder.
    :param seeds: its training seeds.
    :param cells: the table cells (empty for a figure part).
    :param figure: the ``eval.paper.figures`` function it calls, None for a table part.
    :param paper: a figure part's paper numbers, label -> number.
    """

    name: str
    experiment: str
    scale: str
    out_dir: str
    seeds: tuple[int, ...]
    cells: tuple[Cell, ...] = ()
    figure: str | None = None
    paper: dict[str, float] = field(default_factory=dict)

    @property
    def jobs(self) -> list[Job]:
        """Its jobs, each once (cells may share runs), in cell order."""
        unique: dict[Path, Job] = {}
        for cell in self.cells:
            for job in cell.jobs:
                unique.setdefault(job.run_dir, job)
        return list(unique.values())

    @property
    def figure_dir(self) -> Path:
        """``<out>[/<scale folder>]/figures/<figure>``: where a figure part writes."""
        folder = SCALES[self.scale].folder
        root = Path(self.out_dir) / folder if folder else Path(self.out_dir)
        return root / "figures" / str(self.figure)

    def command(self) -> str:
        """The command that runs exactly this part into its results folder."""
        argv = ["ebm-eval", "--experiment", self.experiment, "--part", self.name, "-f", self.out_dir]
        if self.scale != "paper":
            argv += ["--scale", self.scale]
        if self.seeds != default_seeds(SCALES[self.scale], self.figure):
            argv += ["--seeds", *map(str, self.seeds)]
        return shlex.join(argv)


@dataclass(frozen=True)
class Context:
    """What parts are built for.

    :param scale: the budgets.
    :param out_dir: the results folder.
    :param seeds: training seeds (None: the scale's defaults).
    :param device: torch device of the runs.
    """

    scale: Scale
    out_dir: str
    seeds: tuple[int, ...] | None = None
    device: str = "auto"

    def seeds_for(self, figure: str | None = None) -> tuple[int, ...]:
        """The seeds of a table part (``figure`` None) or of a figure."""
        return self.seeds if self.seeds is not None else default_seeds(self.scale, figure)


@dataclass(frozen=True)
class Experiment:
    """A named experiment of the paper.

    :param name: its ``--experiment`` name.
    :param title: a heading for the results document.
    :param source: where it is in the paper.
    :param description: what it measures and how, for the results document.
    :param build: ``build(context) -> parts``.
    """

    name: str
    title: str
    source: str
    description: str
    build: Callable[[Context], list[Part]]


def default_seeds(scale: Scale, figure: str | None = None) -> tuple[int, ...]:
    """The scale's seeds of a table part or a figure.

    :param scale: the scale.
    :param figure: a figure name, or None.
    :return: the seeds.
    """
    return scale.figure_seeds.get(figure, scale.seeds) if figure else scale.seeds


@cache
def preset_hyperparams(env: str) -> dict[str, dict[str, Any]]:
    """Agent settings of an env: the ``hyperparams`` of its bundled online preset, if it has one.

    :param env: env short name.
    :return: agent name -> keyword arguments.
    """

    path = PRESET_DIR / f"{env}_online.yaml"
    return dict(load_preset(str(path)).get("hyperparams") or {}) if path.is_file() else {}


def make_cell(
    context: Context,
    setting: str,
    env: str,
    agent: str,
    variant: str,
    paper: float | None = None,
    *,
    mode: str = "online",
    dataset: str = "random",
    budget_multiple: float = 1,
    env_kwargs: dict[str, Any] | None = None,
    eval_env_kwargs: dict[str, Any] | None = None,
    offline_kwargs: dict[str, Any] | None = None,
    hyperparams: dict[str, Any] | None = None,
    extra_evaluations: dict[str, dict[str, Any]] | None = None,
    evaluation: str | None = None,
    paper_note: str = "",
    preset: str = "paper",
    key: str | None = None,
    why: str | None = None,
    part: str = "",
    seeds: dict[str, list[int]] | None = None,
) -> Cell:
    """A cell with one job per seed, at the context's scale.

    :param context: scale, folder, seeds, device.
    :param setting: the row label.
    :param env: env short name, of the project's envs (``envs.ENV_IDS``) or the third-party ones
        (``envs.THIRD_PARTY_ENV_IDS``, which train and evaluate with ``envs.PROTOCOL_ENV_KWARGS``).
    :param agent: agent name.
    :param variant: the configuration's folder name (runs of equal configurations must share it).
    :param paper: the paper's number.
    :param mode: ``online``, ``pretrained`` or ``untrained`` (budget 0).
    :param dataset: pretrained only: the dataset.
    :param budget_multiple: online only: the budget as a multiple of the scale's online budget (0.2: 10,000 of the
        paper scale's 50,000), rounded to whole transitions.
    :param env_kwargs: kwargs of the training and evaluation envs, over the scale's.
    :param eval_env_kwargs: kwargs of the evaluation env only, over those (e.g. the paper's start for an agent
        trained from random starts).
    :param offline_kwargs: pretrained only: ``learn_offline`` settings over the scale's (``{epochs: 0}``: the
        dataset without training, for a control).
    :param hyperparams: agent keyword arguments, over the preset's and the scale's.
    :param extra_evaluations: extra evaluations of every run.
    :param evaluation: the extra evaluation whose score stands for the cell.
    :param paper_note: text beside the paper's number.
    :param preset: the agents' preset (``ebm_agent.presets``): ``"paper"`` (the original code's settings, what the
        reproduction reports the paper's tables with) or ``""`` (the library's defaults, the rows beside them).
    :param key: see :class:`Cell`.
    :param why: see :class:`Cell`.
    :param part: see :class:`Cell`.
    :param seeds: the cell's own training seeds by scale name (``{paper: [0, 1, 2, 3, 4]}``: more seeds where a
        comparison needs them); a scale it does not name uses the scale's seeds, and ``--seeds`` (the context's
        seeds) overrides both.
    :return: the cell.
    """
    scale = context.scale
    unknown_scales = sorted(set(seeds or {}) - set(SCALES))
    if unknown_scales:
        raise ValueError(
            f"paper.yaml: cell {setting!r} ({part}) names seeds of unknown scales {unknown_scales}; known: {sorted(SCALES)}"
        )
    cell_seeds = context.seeds_for()
    if context.seeds is None and seeds and scale.name in seeds:
        cell_seeds = _seed_tuple(seeds[scale.name], f"the seeds of cell {setting!r} ({part}) at scale {scale.name}")
    env_id = ENV_IDS.get(env) or THIRD_PARTY_ENV_IDS[env]
    train_kwargs = {**PROTOCOL_ENV_KWARGS.get(env_id, {}), **scale.env_kwargs, **(env_kwargs or {})}
    agent_kwargs = {
        **preset_hyperparams(env).get(agent, {}),
        **scale.hyperparams.get(agent, {}),
        **(hyperparams or {}),
    }
    pretrained = mode == "pretrained"
    budget = 0 if mode == "untrained" else scale.pretrain if pretrained else max(round(scale.online * budget_multiple), 1)
    offline = {}
    collector: dict[str, Any] = {}
    if pretrained:
        offline = dict(scale.sequential_kwargs if dataset == "directed+sequential" else scale.offline_kwargs)
        offline.update(offline_kwargs or {})
        if dataset != "random":
            collector = {**preset_hyperparams(env).get("ebm", {}), **scale.hyperparams.get("ebm", {})}
    jobs = tuple(
        Job(
            env_id=env_id,
            agent=agent,
            seed=seed,
            timesteps=budget,
            eval_freq=max(budget if pretrained else budget // scale.evaluations, 1),
            eval_episodes=scale.eval_episodes,
            hyperparams=agent_kwargs,
            env_kwargs=train_kwargs,
            eval_env_kwargs={**PAPER_EVAL_KWARGS.get(env_id, {}), **train_kwargs, **(eval_env_kwargs or {})},
            device=context.device,
            out_dir=context.out_dir,
            mode=mode,
            dataset=dataset,
            offline_kwargs=offline,
            dataset_kwargs=collector,
            extra_evaluations=dict(extra_evaluations or {}),
            variant=str(Path(scale.folder) / variant) if scale.folder else variant,
            preset=preset,
        )
        for seed in cell_seeds
    )
    return Cell(setting, env, agent, jobs, paper, paper_note, evaluation, key, why, part)


def _seed_tuple(values: Any, what: str) -> tuple[int, ...]:
    """``values`` as distinct non-negative integer seeds, or a ``ValueError`` naming ``what``."""
    if not isinstance(values, list | tuple) or not values:
        raise ValueError(f"paper.yaml: {what} must be a non-empty list of seeds, got {values!r}")
    if any(isinstance(v, bool) or not isinstance(v, int) or v < 0 for v in values) or len(set(values)) != len(values):
        raise ValueError(f"paper.yaml: {what} must be distinct non-negative integers, got {values!r}")
    return tuple(values)


def table_part(context: Context, experiment: str, name: str, cells: Sequence[Cell]) -> Part:
    """A part made of table cells."""
    return Part(name, experiment, context.scale.name, context.out_dir, context.seeds_for(), tuple(cells))


def figure_part(context: Context, experiment: str, name: str, figure: str, paper: dict[str, float] | None = None) -> Part:
    """A part that calls one ``eval.paper.figures`` function."""
    seeds = context.seeds_for(figure)
    return Part(name, experiment, context.scale.name, context.out_dir, seeds, figure=figure, paper=dict(paper or {}))


__all__ = [
    "AGENT_LABELS",
    "SCALES",
    "Cell",
    "Context",
    "Experiment",
    "Part",
    "Scale",
    "default_seeds",
    "figure_part",
    "make_cell",
    "preset_hyperparams",
    "table_part",
]
