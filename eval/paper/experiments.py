"""The paper's experiments by name, each split into parts that run, resume and merge on their own.

    ebm-eval --experiment list                                  # experiments, parts and their estimated cost
    ebm-eval --experiment table1 -f runs/results                # Table 1, every part
    ebm-eval --experiment all --part 'table2/*' -f runs/results # only Table 2's parts
    ebm-eval --experiment all -f runs/results                   # everything, then docs/results.md

An :class:`Experiment` builds its :class:`Part` s for a :class:`Scale` (``paper``: the paper's budgets;
``smoke``: tiny ones for tests). A part is either a list of :class:`Cell` s (one number of a table each: the runs
of one configuration over seeds, with the paper's number beside it) or one figure of ``eval.paper.figures``. Every run
folder is named by its configuration (``<out>/<variant>/<env>/<agent>/seed_<k>``), so experiments that need the
same runs share them (Table 2's online fixed-goal runs are also the ground-truth row of the inverse-dynamics
ablation and the runs the fixed-goal-on-variable-goals evaluation reads).

Budgets (paper Sec. 4.1 and Table 2's caption): 50,000 transitions online, datasets of 100,000 transitions for
pretraining, 3 seeds, 10 deterministic evaluation episodes, the paper's evaluation configuration of each env
(``envs.PAPER_EVAL_KWARGS``). Agent settings per env come from the env's online preset
(``eval/presets/<env>_online.yaml``, key ``hyperparams``), so that ``--config particle_online`` and
``--experiment table1`` train the same agents.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from fnmatch import fnmatchcase
from pathlib import Path

from eval.jobs import RESUME_FOLDER, STATE_FILE, Job
from eval.paper.estimates import estimate_jobs_seconds, estimate_part_seconds, format_duration, measured_part_cost
from eval.paper.parts import (
    FAST_PART_SUFFIX,
    FAST_VARIANT_SUFFIX,
    SCALES,
    Cell,
    Context,
    Experiment,
    Part,
    figure_part,
    make_cell,
    table_part,
)
from eval.pretraining import collection_checkpoint_dir
from eval.provenance import read_json_dict

PPO_MULTIPLES = (1, 5, 10)
"""PPO's Sawyer budgets as multiples of the online budget (paper Sec. 4.2: -9300 at 1x, comparable to the EBM at
5-10x)."""

TABLE1_PAPER = {
    ("pretrained", "ebm"): {"particle": -5.14, "maze": -72.07, "reacher": -19.38},
    ("pretrained", "action-ff"): {"particle": -6.11, "maze": -65.06, "reacher": -25.54},
    ("online", "ebm"): {"particle": -20.38, "maze": -162.97, "reacher": -29.87},
    ("online", "action-ff"): {"particle": -850.67, "maze": -949.99, "reacher": -42.37},
}
"""Paper Table 1: (data, agent) -> env -> score."""

TABLE2_DATASETS = {
    "pretrained_random": "random",
    "pretrained_directed": "directed",
    "pretrained_directed_sequential": "directed+sequential",
}
"""Table 2's pretrained columns (part names) and their datasets."""

TABLE2_SETTINGS = (*TABLE2_DATASETS, "online_fixed", "online_variable")
"""Table 2's columns, as part names."""

TABLE2_PAPER = {
    "ebm": dict(zip(TABLE2_SETTINGS, (-9569.0, -4438.0, -5114.0, -3782.0, -3907.0))),
    "action-ff": dict(zip(TABLE2_SETTINGS, (-10326.0, -5041.0, -12838.0, -9360.0, -11942.0))),
}
"""Paper Table 2: agent -> setting -> score."""

FAST_SETTING = "fast preset"
"""The row label of the online runs made with the fast preset (``ebm_agent.presets.FAST_EBM``: every other EBM and
Action FF row runs the paper preset, the original code's settings and the library's defaults)."""

VARIABLE_GOAL = {"goal": "variable"}
"""The Sawyer's variable-goal configuration (a new target per episode)."""

FIXED_ON_VARIABLE = {"variable_goal": VARIABLE_GOAL}
"""The extra evaluation of the fixed-goal Sawyer runs: the same model on variable goals (paper Sec. 4.2)."""


def _table1(context: Context) -> list[Part]:
    parts = []
    for env in ("particle", "maze", "reacher"):
        for data in ("pretrained", "online"):
            cells = [
                make_cell(
                    context,
                    data,
                    env,
                    agent,
                    "online" if data == "online" else "pretrained_random",
                    TABLE1_PAPER[(data, agent)][env],
                    mode=data,
                )
                for agent in ("ebm", "action-ff")
            ]
            parts.append(table_part(context, "table1", f"table1/{env}/{data}", cells))
        cells = [
            make_cell(context, FAST_SETTING, env, agent, "online" + FAST_VARIANT_SUFFIX, preset="fast")
            for agent in ("ebm", "action-ff")
        ]
        parts.append(table_part(context, "table1", f"table1/{env}/online{FAST_PART_SUFFIX}", cells))
        parts.append(untrained_part(context, "table1", f"table1/{env}/untrained", env))
    return parts


def untrained_part(context: Context, experiment: str, name: str, env: str, env_kwargs: dict | None = None) -> Part:
    """The EBM as built, evaluated without learning (no paper number): the control that says how much of a trained
    EBM's score its planner and the env's ground-truth inverse dynamics give without any learned energy."""
    setting = "untrained" + ("" if env != "sawyer" else " variable" if env_kwargs == VARIABLE_GOAL else " fixed")
    variant = "untrained" + ("_variable_goal" if env_kwargs == VARIABLE_GOAL else "")
    cell = make_cell(context, setting, env, "ebm", variant, mode="untrained", env_kwargs=env_kwargs)
    return table_part(context, experiment, name, [cell])


def sawyer_online_fixed(context: Context, agent: str, setting: str = "online fixed", paper: float | None = None) -> Cell:
    """The Sawyer online fixed-goal runs (Table 2), also evaluated on variable goals; shared by several experiments."""
    extra = FIXED_ON_VARIABLE if agent in ("ebm", "action-ff") else None
    return make_cell(context, setting, "sawyer", agent, "online", paper, extra_evaluations=extra)


def _table2(context: Context) -> list[Part]:
    parts = []
    for setting in TABLE2_SETTINGS:
        cells = []
        for agent in ("ebm", "action-ff"):
            paper = TABLE2_PAPER[agent][setting]
            label = setting.replace("_", " ").replace("directed sequential", "directed + sequential")
            if setting == "online_fixed":
                cells.append(sawyer_online_fixed(context, agent, label, paper))
            elif setting == "online_variable":
                variant = "online_variable_goal"
                cells.append(make_cell(context, label, "sawyer", agent, variant, paper, env_kwargs=VARIABLE_GOAL))
            else:
                dataset = TABLE2_DATASETS[setting]
                cells.append(make_cell(context, label, "sawyer", agent, setting, paper, mode="pretrained", dataset=dataset))
        parts.append(table_part(context, "table2", f"table2/sawyer/{setting}", cells))
    for setting, variant, env_kwargs in (
        ("online_fixed", "online", None),
        ("online_variable", "online_variable_goal", VARIABLE_GOAL),
    ):
        label = setting.replace("_", " ") + ", " + FAST_SETTING
        cells = [
            make_cell(context, label, "sawyer", agent, variant + FAST_VARIANT_SUFFIX, env_kwargs=env_kwargs, preset="fast")
            for agent in ("ebm", "action-ff")
        ]
        parts.append(table_part(context, "table2", f"table2/sawyer/{setting}{FAST_PART_SUFFIX}", cells))
    parts.append(untrained_part(context, "table2", "table2/sawyer/untrained_fixed", "sawyer"))
    parts.append(untrained_part(context, "table2", "table2/sawyer/untrained_variable", "sawyer", VARIABLE_GOAL))
    return parts


def _sawyer_ppo(context: Context) -> list[Part]:
    parts = []
    for multiple in PPO_MULTIPLES:
        paper, note = (-9300.0, "") if multiple == 1 else (None, "comparable to the online EBM (-3782) at 5-10x")
        variant = "online" if multiple == 1 else f"online_{multiple}x"
        cell = make_cell(
            context, f"PPO {multiple}x", "sawyer", "ppo", variant, paper, budget_multiple=multiple, paper_note=note
        )
        parts.append(table_part(context, "sawyer_ppo", f"sawyer_ppo/{multiple}x", [cell]))
    return parts


def _fixed_on_variable(context: Context) -> list[Part]:
    setting = "trained fixed, evaluated variable"
    cells = [
        replace(sawyer_online_fixed(context, agent, setting, paper), evaluation="variable_goal")
        for agent, paper in (("ebm", -4547.0), ("action-ff", None))
    ]
    return [table_part(context, "fixed_on_variable", "fixed_on_variable/sawyer", cells)]


INVERSE_DYNAMICS_PAPER = {"sawyer": {"ground_truth": -3782.0, "rls": -4694.0}}
"""Paper Sec. 4.2: ground truth is Table 2's online fixed-goal EBM; RLS -4694; no number for a learned network."""


def _inverse_dynamics(context: Context) -> list[Part]:
    parts = []
    for env in ("sawyer", "particle"):
        cells = []
        for kind in ("ground_truth", "mlp", "rls"):
            paper = INVERSE_DYNAMICS_PAPER.get(env, {}).get(kind)
            note = "no number; learned networks may mode-collapse" if env == "sawyer" and kind == "mlp" else ""
            label = kind.replace("_", " ") if kind == "ground_truth" else kind.upper()
            if kind == "ground_truth" and env == "sawyer":
                cells.append(sawyer_online_fixed(context, "ebm", label, paper))
            elif kind == "ground_truth":
                cells.append(make_cell(context, label, env, "ebm", "online", paper))
            else:
                hyper = {"inverse_dynamics": kind}
                cells.append(
                    make_cell(context, label, env, "ebm", f"online_invdyn_{kind}", paper, hyperparams=hyper, paper_note=note)
                )
        parts.append(table_part(context, "inverse_dynamics", f"inverse_dynamics/{env}", cells))
    return parts


def _figure(name: str, part: str, figure: str, paper: dict[str, float] | None = None) -> Callable[[Context], list[Part]]:
    return lambda context: [figure_part(context, name, part, figure, paper)]


EXPERIMENTS: dict[str, Experiment] = {
    experiment.name: experiment
    for experiment in (
        Experiment(
            "table1",
            "Table 1: particle, maze and Reacher, pretrained and online",
            "paper Table 1, Sec. 4.2",
            "EBM vs Action FF, each pretrained on 100,000 random transitions of the env (10 epochs of shuffled "
            "batches of 256) or learning online (Algorithm 1) from 50,000 transitions; evaluated from the paper's "
            "start and goal. The untrained rows (no paper number) are the EBM as built, evaluated without learning: "
            "the control for how much of the EBM's score its planner and the env's ground-truth inverse dynamics "
            "give with no learned energy.",
            _table1,
        ),
        Experiment(
            "table2",
            "Table 2: Sawyer arm",
            "paper Table 2, Sec. 4.2",
            "EBM vs Action FF on the Sawyer reach: pretrained on 100,000 random transitions (the env's exploration "
            "actions), on 100,000 directed transitions (the real transitions of an EBM learning online), on the "
            "directed transitions repeated 100 times in contiguous batches (directed + sequential), and online "
            "(50,000 transitions) with a fixed goal or a new goal per episode. Our Sawyer is a torque-driven "
            "Metaworld arm, not the original's PR2-like model: compare against the anchors, not only the paper. "
            "The untrained rows (no paper number) are the EBM as built, evaluated without learning on the fixed and "
            "the variable goals.",
            _table2,
        ),
        Experiment(
            "sawyer_ppo",
            "PPO on the Sawyer arm at 1x, 5x and 10x the online budget",
            "paper Sec. 4.2",
            "SB3 PPO with tuned per-env hyperparameters (baselines.hyperparams) on the fixed-goal Sawyer at 50,000, "
            "250,000 and 500,000 transitions, against the online EBM of Table 2.",
            _sawyer_ppo,
        ),
        Experiment(
            "fixed_on_variable",
            "A fixed-goal Sawyer model evaluated on variable goals",
            "paper Sec. 4.2",
            "Table 2's online fixed-goal runs, each evaluated again on the variable-goal env (same seeds, same "
            "episodes). The paper quotes -4547 (its Table 2 gives -3907 for a model trained on variable goals).",
            _fixed_on_variable,
        ),
        Experiment(
            "inverse_dynamics",
            "Inverse-dynamics ablation: ground truth, learned MLP, recursive least squares",
            "paper Sec. 4.2",
            "The online EBM with the env's ground-truth inverse dynamics, a learned MLP, or recursive least squares "
            "(inverse_dynamics='ground_truth' | 'mlp' | 'rls'), on the fixed-goal Sawyer (the paper's setting) and "
            "on the particle.",
            _inverse_dynamics,
        ),
        Experiment(
            "obstacle",
            "Obstacle generalisation: the particle with an unseen box",
            "paper Fig. 4, Sec. 4.3",
            "EBM and Action FF trained on the particle without obstacles, evaluated with a box obstacle.",
            _figure("obstacle", "obstacle/particle", "obstacle_generalisation", {"EBM": -61.94, "Action FF": -81.24}),
        ),
        Experiment(
            "plan_diversity",
            "Plan diversity against the planning horizon",
            "paper Fig. 5, Sec. 4.3",
            "The spread of sampled plans as the horizon grows.",
            _figure("plan_diversity", "plan_diversity/particle", "plan_diversity"),
        ),
        Experiment(
            "reacher_directions",
            "Reacher: clockwise and counter-clockwise plans",
            "paper Fig. 6, Sec. 4.3",
            "Plans to one goal going both ways round, with the fraction of each.",
            _figure("reacher_directions", "reacher_directions/reacher", "reacher_directions"),
        ),
        Experiment(
            "maze_exploration",
            "Maze exploration: EBM without a goal vs random actions",
            "paper Fig. 7, Sec. 4.4",
            "Visited cells of a 20x20 grid over the maze for the same number of transitions.",
            _figure("maze_exploration", "maze_exploration/maze", "maze_exploration"),
        ),
        Experiment(
            "sawyer_exploration",
            "Sawyer exploration: finger voxel occupancy, EBM vs random",
            "paper Fig. 8, Sec. 4.4",
            "Occupied voxels of the finger (the original's 10x10x10 grid) against transitions, over 4 seeds.",
            _figure("sawyer_exploration", "sawyer_exploration/sawyer", "sawyer_exploration"),
        ),
        Experiment(
            "energy_maps",
            "Energy maps over training",
            "paper Fig. 9, Sec. 4.4",
            "The energy of a small move centred at each state, at several points of online training.",
            _figure("energy_maps", "energy_maps/particle_maze", "energy_maps"),
        ),
    )
}
"""Every experiment by name, in the order of the paper."""


def build_parts(names: Sequence[str], context: Context) -> list[Part]:
    """The parts of the named experiments (``"all"`` for every one).

    :param names: experiment names.
    :param context: scale, folder, seeds, device.
    :return: the parts, experiment by experiment.
    :raises ValueError: for an unknown name.
    """
    selected = list(EXPERIMENTS) if "all" in names else list(dict.fromkeys(names))
    unknown = [name for name in selected if name not in EXPERIMENTS]
    if unknown:
        raise ValueError(f"unknown experiment(s) {unknown}; choose from: {', '.join(EXPERIMENTS)}, all (or list)")
    return [part for name in selected for part in EXPERIMENTS[name].build(context)]


def select_parts(parts: Sequence[Part], patterns: Sequence[str] | None) -> list[Part]:
    """The parts whose name matches any of the globs (all parts when there is none).

    :param parts: candidate parts.
    :param patterns: shell-style globs, e.g. ``table1/particle/*`` or ``*/sawyer*``.
    :return: the matching parts, in order.
    :raises ValueError: when a glob matches no part.
    """
    if not patterns:
        return list(parts)
    for pattern in patterns:
        if not any(fnmatchcase(part.name, pattern) for part in parts):
            names = ", ".join(part.name for part in parts)
            raise ValueError(f"--part {pattern!r} matches no part; the parts are: {names}")
    return [part for part in parts if any(fnmatchcase(part.name, pattern) for pattern in patterns)]


def make_context(scale: str, out_dir: str, seeds: Sequence[int] | None = None, device: str = "auto") -> Context:
    """A context for a scale by name.

    :param scale: ``paper`` or ``smoke``.
    :param out_dir: the results folder.
    :param seeds: training seeds (None: the scale's).
    :param device: torch device.
    :return: the context.
    :raises ValueError: for an unknown scale.
    """
    if scale not in SCALES:
        raise ValueError(f"unknown scale {scale!r}; choose one of: {', '.join(SCALES)}")
    return Context(SCALES[scale], str(out_dir), None if seeds is None else tuple(seeds), device)


def describe_experiments(context: Context, measured_from: Sequence[str | Path] = ()) -> str:
    """The text of ``ebm-eval --experiment list``: experiments, their parts, runs, estimated and measured cost.

    :param context: scale, folder, seeds.
    :param measured_from: results or records folders whose finished runs and figures give measured times.
    :return: the text.
    """
    lines = [
        f"Experiments at scale {context.scale.name!r} (CPU time of one process: a rough estimate, and the measured "
        "wall time of the finished runs, where there are any; --jobs N divides the wall time of runs):",
        "",
    ]
    unique_jobs: dict[Path, Job] = {}
    figures = 0.0
    for experiment in EXPERIMENTS.values():
        parts = experiment.build(context)
        runs = {job.run_dir: job for part in parts for job in part.jobs}
        cost = estimate_jobs_seconds(runs.values()) + sum(estimate_part_seconds(p) for p in parts if p.figure)
        for part in parts:
            unique_jobs.update((job.run_dir, job) for job in part.jobs)
            figures += estimate_part_seconds(part) if part.figure else 0.0
        lines.append(f"{experiment.name:<20} {experiment.title} ({experiment.source}) ~{format_duration(cost)}")
        for part in parts:
            what = f"figure {part.figure}" if part.figure else f"{len(part.jobs)} runs"
            seeds = " ".join(map(str, part.seeds))
            line = f"  {part.name:<46} {what:<32} seeds {seeds:<10} ~{format_duration(estimate_part_seconds(part)):<7}"
            measured = measured_part_cost(part, measured_from) if measured_from else None
            line = f"{line} {measured.describe()}" if measured else line.rstrip()
            lines.append(line + _in_progress(part))
    total = figures + estimate_jobs_seconds(unique_jobs.values())
    lines += [
        "",
        f"all: {len(unique_jobs)} runs and {sum(1 for _ in EXPERIMENTS)} experiments, ~{format_duration(total)} "
        "of CPU time (runs and directed collections shared by parts counted once)",
    ]
    return "\n".join(lines)


def _in_progress(part: Part) -> str:
    """``; resumes <run> at t/T, ...`` for the part's unfinished runs that kept a checkpoint (``eval.resume``) and
    the unfinished directed collections its pretrained runs wait for (``eval.pretraining``)."""

    found: list[str] = []
    collections: dict[Path, str] = {}  # the EBM and Action FF runs of a seed share one collection
    for job in part.jobs:
        state = read_json_dict(job.run_dir / RESUME_FOLDER / STATE_FILE)
        if state is not None and not (job.run_dir / "metrics.json").exists():
            found.append(f"{job.agent} seed {job.seed} at {state.get('num_timesteps')}/{job.timesteps}")
        if job.mode == "pretrained" and job.dataset != "random":
            folder = collection_checkpoint_dir(job)
            state = read_json_dict(folder / STATE_FILE)
            if state is not None:
                collections[folder] = (
                    f"the directed dataset of seed {job.seed} at {state.get('num_timesteps')}/{job.timesteps}"
                )
    found += collections.values()
    return f"; resumes {', '.join(found)}" if found else ""


__all__ = [
    "EXPERIMENTS",
    "INVERSE_DYNAMICS_PAPER",
    "PPO_MULTIPLES",
    "TABLE1_PAPER",
    "TABLE2_PAPER",
    "build_parts",
    "describe_experiments",
    "make_context",
    "select_parts",
]
