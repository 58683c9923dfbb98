"""The reproduction's claims (issue 6), judged from the measured numbers: "holds", "inconclusive", "does not hold" or
"not measured".

Nothing here knows a verdict in advance: each claim names the numbers it compares (table cells by part, agent and
evaluation; exploration figures by part) and ``evaluate_claims`` reads them through the lookups it is given.

- A score comparison does not hold when the first agent's mean over seeds is not higher (scores are sums of
  rewards: higher is better). With at least 3 seeds on each side it holds when the two means' 95%
  stratified-bootstrap intervals separate, and is "inconclusive" when the first mean is higher but the intervals
  overlap; with fewer seeds a higher mean holds and the evidence says that no interval was computed.
- A claim over several envs does not hold when any measured comparison does not, is "not measured" while a
  comparison lacks its runs, is "inconclusive" while any comparison is, and holds when every comparison holds.
- A change claim (Table 2's sequential ablation) compares how much two agents' scores change from one setting to
  another: the first agent's change of mean, ``mean(after) - mean(before)``, must be the higher (the smaller drop).
  With at least 3 seeds in each of the four cells it holds when the two changes' 95% bootstrap intervals separate
  (``eval.stats.bootstrap_difference_ci``, each cell's seeds resampled on their own) and is "inconclusive" when
  they overlap; with fewer seeds the means decide and the evidence says so.
- The exploration claim reads the exploration figures' metrics (``eval.paper.figures``) at equal transitions: maze
  coverage of the EBM vs the random agent after the same budget, Sawyer finger occupancy of the EBM at its budget
  vs each random explorer's occupancy at that same budget, against the strongest random explorer (highest mean).
  Keys are slash-joined paths into the nested metrics (``agents/ebm/coverage/mean``). Where both numbers have
  per-seed values beside them (``.../per_seed``), they are judged as scores are: the 95% intervals must separate
  from 3 seeds on. Otherwise the means alone decide, and the evidence says no interval was computed. Should the
  keys be missing, a pair of keys that differ only by ``ebm`` / ``random`` is used instead (spread statistics such
  as ``std`` excluded).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from eval import stats

LEARNING_CONTROL = (
    "Control, not a claim of the paper: the online EBM beats the same agent untrained (what its planner and the env's "
    "ground-truth inverse dynamics do with no learned energy)"
)
"""Where this fails, a win of the EBM over the other agents on that env is not a win of its learned energy."""

HOLDS = "holds"
INCONCLUSIVE = "inconclusive"
FAILS = "does not hold"
MISSING = "not measured"

CellKey = tuple[str, str, str]
"""(part name, agent, setting): one table cell (``eval.paper.parts.Cell``)."""

ScoreLookup = Callable[[CellKey], Sequence[float]]
"""Per-seed scores of a cell; empty when it has not run."""

FigureLookup = Callable[[str], Mapping[str, Any] | None]
"""A figure part's metrics; None when it has not run."""

MIN_SEEDS_FOR_CI = 3


@dataclass(frozen=True)
class Comparison:
    """One measured comparison behind a claim.

    :param label: what it compares on (an env).
    :param verdict: ``HOLDS``, ``INCONCLUSIVE``, ``FAILS`` or ``MISSING``.
    :param evidence: the numbers, in words.
    """

    label: str
    verdict: str
    evidence: str


@dataclass(frozen=True)
class Claim:
    """A claim with its verdict and the comparisons that decide it.

    :param text: the claim.
    :param verdict: ``HOLDS``, ``INCONCLUSIVE``, ``FAILS`` or ``MISSING``.
    :param comparisons: the evidence, one comparison per env.
    """

    text: str
    verdict: str
    comparisons: tuple[Comparison, ...]


@dataclass(frozen=True)
class ScoreClaim:
    """A claim that one agent scores higher than another, on each listed env.

    :param text: the claim.
    :param comparisons: (env label, the cell that should score higher, the other cell).
    """

    text: str
    comparisons: tuple[tuple[str, CellKey, CellKey], ...]


SCORE_CLAIMS = (
    ScoreClaim(
        "Online EBM beats online Action FF on particle, maze, Reacher and Sawyer",
        (
            ("particle", ("table1/particle/online", "ebm", "online"), ("table1/particle/online", "action-ff", "online")),
            ("maze", ("table1/maze/online", "ebm", "online"), ("table1/maze/online", "action-ff", "online")),
            ("reacher", ("table1/reacher/online", "ebm", "online"), ("table1/reacher/online", "action-ff", "online")),
            (
                "sawyer",
                ("table2/sawyer/online_fixed", "ebm", "online fixed"),
                ("table2/sawyer/online_fixed", "action-ff", "online fixed"),
            ),
        ),
    ),
    ScoreClaim(
        "EBM beats PPO at equal budget on Sawyer",
        (("sawyer", ("table2/sawyer/online_fixed", "ebm", "online fixed"), ("sawyer_ppo/1x", "ppo", "PPO 1x")),),
    ),
)
"""The claims decided by table cells (issue 6's "must show")."""

DIRECTED_CLAIMS = (
    ScoreClaim(
        "Pretrained on the Sawyer, the EBM learns more from directed data than from random data (paper Sec. 4.2: "
        "random interactions cover too few states; -4438 against -9569)",
        (
            (
                "sawyer",
                ("table2/sawyer/pretrained_directed", "ebm", "pretrained directed"),
                ("table2/sawyer/pretrained_random", "ebm", "pretrained random"),
            ),
        ),
    ),
    ScoreClaim(
        "Pretrained on directed data, the EBM beats Action FF on the Sawyer (paper: slightly, -4438 against -5041)",
        (
            (
                "sawyer",
                ("table2/sawyer/pretrained_directed", "ebm", "pretrained directed"),
                ("table2/sawyer/pretrained_directed", "action-ff", "pretrained directed"),
            ),
        ),
    ),
)
"""Table 2's findings on pretraining data (paper Sec. 4.2), decided as the score claims are."""


@dataclass(frozen=True)
class ChangeClaim:
    """A claim that a change of setting costs one agent less than another: its score changes by more (drops less).

    :param text: the claim.
    :param comparisons: (env label, (the first agent's cell before, after), (the other agent's cell before, after)).
    """

    text: str
    comparisons: tuple[tuple[str, tuple[CellKey, CellKey], tuple[CellKey, CellKey]], ...]


CHANGE_CLAIMS = (
    ChangeClaim(
        "Trained on the directed data in sequential, correlated batches instead of shuffled ones, the EBM's score "
        "drops less than Action FF's on the Sawyer (paper Sec. 4.2: by 676 against 7797)",
        (
            (
                "sawyer",
                (
                    ("table2/sawyer/pretrained_directed", "ebm", "pretrained directed"),
                    ("table2/sawyer/pretrained_directed_sequential", "ebm", "pretrained directed + sequential"),
                ),
                (
                    ("table2/sawyer/pretrained_directed", "action-ff", "pretrained directed"),
                    ("table2/sawyer/pretrained_directed_sequential", "action-ff", "pretrained directed + sequential"),
                ),
            ),
        ),
    ),
)
"""Table 2's sequential ablation (paper Sec. 4.2): the drop from shuffled to sequential batches, EBM vs Action FF."""

CONTROL_CLAIMS = (
    ScoreClaim(
        LEARNING_CONTROL,
        (
            ("particle", ("table1/particle/online", "ebm", "online"), ("table1/particle/untrained", "ebm", "untrained")),
            ("maze", ("table1/maze/online", "ebm", "online"), ("table1/maze/untrained", "ebm", "untrained")),
            ("reacher", ("table1/reacher/online", "ebm", "online"), ("table1/reacher/untrained", "ebm", "untrained")),
            (
                "sawyer",
                ("table2/sawyer/online_fixed", "ebm", "online fixed"),
                ("table2/sawyer/untrained_fixed", "ebm", "untrained fixed"),
            ),
        ),
    ),
)
"""Controls judged after the paper's claims, the same way: not claims of the paper, but what they rest on."""


@dataclass(frozen=True)
class NoLossClaim:
    """A claim that one configuration loses no score against another: its mean lies within or above the other's 95%
    bootstrap interval of the mean, on each listed cell pair.

    :param text: the claim.
    :param comparisons: (label, the new configuration's cell, the reference cell).
    """

    text: str
    comparisons: tuple[tuple[str, CellKey, CellKey], ...]


def _no_loss_pairs() -> tuple[tuple[str, CellKey, CellKey], ...]:
    pairs = []
    for env in ("particle", "maze", "reacher"):
        for agent in ("ebm", "action-ff"):
            label = f"{env}, {AGENT_NAMES[agent]}"
            pairs.append(
                (label, (f"table1/{env}/online_fast", agent, "fast preset"), (f"table1/{env}/online", agent, "online"))
            )
    for setting in ("online_fixed", "online_variable"):
        for agent in ("ebm", "action-ff"):
            label = f"sawyer {setting.split('_')[1]}, {AGENT_NAMES[agent]}"
            fast = (f"table2/sawyer/{setting}_fast", agent, f"{setting.replace('_', ' ')}, fast preset")
            pairs.append((label, fast, (f"table2/sawyer/{setting}", agent, setting.replace("_", " "))))
    return tuple(pairs)


@dataclass(frozen=True)
class ExplorationSpec:
    """Where an exploration figure keeps the EBM's number and the random explorers' numbers at the same budget.

    :param label: the env.
    :param part: the figure part.
    :param ebm_key: the EBM's number (a slash-joined path into the metrics).
    :param random_keys: the random explorers' numbers at the EBM's budget; the highest is compared.
    """

    label: str
    part: str
    ebm_key: str
    random_keys: tuple[str, ...]


EXPLORATION_CLAIM = "EBM explores more than random actions (maze coverage, Sawyer finger occupancy)"
EXPLORATION_FIGURES = (
    ExplorationSpec("maze", "maze_exploration/maze", "agents/ebm/coverage/mean", ("agents/random/coverage/mean",)),
    ExplorationSpec(
        "sawyer",
        "sawyer_exploration/sawyer",
        "agents/ebm/occupancy/mean",
        ("agents/random_uniform/occupancy_at_ebm_budget/mean", "agents/random_joint_targets/occupancy_at_ebm_budget/mean"),
    ),
)
"""The exploration claim's figures."""

SPREAD_STATISTICS = ("std", "min", "max", "low", "high", "ci", "sem")
"""Last path components that describe a spread, never compared."""

AGENT_NAMES = {"ebm": "EBM", "action-ff": "Action FF", "ppo": "PPO", "random": "Random"}


NO_LOSS_CLAIMS = (
    NoLossClaim(
        "Not a claim of the paper: the fast preset (warm-started training plans, ebm_agent.presets.FAST_EBM) loses no "
        "score against the paper preset online (each fast mean within or above the paper preset's 95% interval); "
        "the library's defaults could become the fast budgets only where this holds",
        _no_loss_pairs(),
    ),
)
"""The fast preset against the paper preset (issue 33), judged before the controls (which come last)."""


def compare_no_loss(label: str, name: str, values: Sequence[float], other_name: str, other: Sequence[float]) -> Comparison:
    """Whether ``values`` lose no score against ``other``: their mean is at least the low end of the 95% bootstrap
    interval of ``other``'s mean (with fewer than 3 seeds of ``other``: at least its lowest seed).

    :param label: what is compared.
    :param name: the new configuration's name.
    :param values: its per-seed scores (empty: not run).
    :param other_name: the reference's name.
    :param other: the reference's per-seed scores (empty: not run).
    :return: ``HOLDS``, ``FAILS`` or ``MISSING``.
    """
    if len(values) == 0 or len(other) == 0:
        missing = [n for n, v in ((name, values), (other_name, other)) if len(v) == 0]
        return Comparison(label, MISSING, f"{' and '.join(missing)} not run yet")
    first, second = np.asarray(values, dtype=np.float64), np.asarray(other, dtype=np.float64)
    if len(second) >= MIN_SEEDS_FOR_CI:
        low, high = stats.bootstrap_ci(second, stats.mean)
        reference = f"{other_name} {stats.mean(second):.2f} [95% CI {low:.2f}, {high:.2f}]"
    else:
        low = float(second.min())
        reference = f"{other_name} {stats.mean(second):.2f} (lowest seed {low:.2f}; fewer than {MIN_SEEDS_FOR_CI} seeds)"
    mean = stats.mean(first)
    verdict = HOLDS if mean >= low else FAILS
    where = (
        "above the interval" if len(second) >= MIN_SEEDS_FOR_CI and mean > high else "within" if verdict == HOLDS else "below"
    )
    seeds = f"{len(first)} seed{'s' if len(first) != 1 else ''}"
    return Comparison(label, verdict, f"{name} {mean:.2f} ({seeds}) vs {reference}: {where}")


def compare_scores(
    label: str,
    name: str,
    scores: Sequence[float],
    other_name: str,
    other: Sequence[float],
    retired: tuple[int, int] = (0, 0),
) -> Comparison:
    """Whether ``scores`` beat ``other`` on average (beyond the 95% intervals from 3 seeds on), with the evidence.

    :param label: what is compared (an env).
    :param name: the first side's name.
    :param scores: its per-seed scores [seeds] (empty: not run).
    :param other_name: the second side's name.
    :param other: its per-seed scores.
    :param retired: each side's runs made with earlier library defaults (``eval.paper.results_doc.CellResult.retired``):
        a side with none of today's runs but some of those reads "rerun pending", as its table cell does.
    :return: the comparison.
    """
    if len(scores) == 0 or len(other) == 0:
        sides = [(n, r) for n, s, r in ((name, scores, retired[0]), (other_name, other, retired[1])) if len(s) == 0]
        return Comparison(label, MISSING, _not_measured(sides))
    return compare_seeds(label, name, scores, other_name, other)


def _not_measured(sides: Sequence[tuple[str, int]]) -> str:
    """The evidence of a comparison that lacks runs: (name, runs made with earlier defaults) of each empty side."""
    not_run = [n for n, r in sides if r == 0]
    phrases = [f"{' and '.join(not_run)} not run yet"] if not_run else []
    phrases += [f"{n} rerun pending ({r} run(s) made with earlier library defaults)" for n, r in sides if r > 0]
    return "; ".join(phrases)


def compare_seeds(
    label: str, name: str, values: Sequence[float], other_name: str, other: Sequence[float], digits: str = ".2f"
) -> Comparison:
    """Whether ``values`` are higher than ``other`` on average, beyond the 95% intervals from 3 seeds on.

    :param label: what is compared (an env).
    :param name: the first side's name.
    :param values: its per-seed numbers [seeds], not empty (higher is better).
    :param other_name: the second side's name.
    :param other: its per-seed numbers, not empty.
    :param digits: the format of the numbers in the evidence.
    :return: the comparison: ``HOLDS`` when the intervals separate (or with fewer seeds, when the mean is higher),
        ``INCONCLUSIVE`` when the mean is higher but the intervals overlap, else ``FAILS``.
    """
    first, second = np.asarray(values, dtype=np.float64), np.asarray(other, dtype=np.float64)
    verdict = HOLDS if stats.mean(first) > stats.mean(second) else FAILS
    evidence = f"{name} {_with_interval(first, digits)} vs {other_name} {_with_interval(second, digits)}"
    if len(first) >= MIN_SEEDS_FOR_CI and len(second) >= MIN_SEEDS_FOR_CI:
        low_a, high_a = stats.bootstrap_ci(first, stats.mean)
        low_b, high_b = stats.bootstrap_ci(second, stats.mean)
        separate = low_a > high_b or low_b > high_a
        evidence += "; the 95% intervals separate" if separate else "; the 95% intervals overlap"
        if verdict == HOLDS and not separate:
            verdict = INCONCLUSIVE
    else:
        evidence += f"; fewer than {MIN_SEEDS_FOR_CI} seeds on a side, no interval"
    return Comparison(label, verdict, evidence)


def compare_changes(
    label: str,
    name: str,
    change: tuple[Sequence[float], Sequence[float]],
    other_name: str,
    other_change: tuple[Sequence[float], Sequence[float]],
    setting_names: tuple[str, str] = ("before", "after"),
) -> Comparison:
    """Whether the first agent's score changes by more (drops less) than the other's between two settings.

    :param label: what is compared (an env).
    :param name: the first agent's name.
    :param change: its per-seed scores (before [seeds], after [seeds]), none empty.
    :param other_name: the other agent's name.
    :param other_change: its per-seed scores (before, after), none empty.
    :param setting_names: the two settings, for the evidence.
    :return: ``HOLDS`` when the first change is higher and, with 3 seeds in every cell, the two changes' 95% intervals
        separate; ``INCONCLUSIVE`` when it is higher but they overlap; else ``FAILS``.
    """
    sides = []
    for agent, (before, after) in ((name, change), (other_name, other_change)):
        first, second = np.asarray(before, dtype=np.float64), np.asarray(after, dtype=np.float64)
        delta = stats.mean(second) - stats.mean(first)
        seeds = min(len(first), len(second))
        interval = stats.bootstrap_difference_ci(first, second) if seeds >= MIN_SEEDS_FOR_CI else None
        text = f"{agent} {delta:+.2f}"
        if interval is not None:
            text += f" [95% CI {interval[0]:+.2f}, {interval[1]:+.2f}]"
        counts = f"{len(first)} and {len(second)} seed{'s' if max(len(first), len(second)) > 1 else ''}"
        text += f" ({stats.mean(first):.2f} to {stats.mean(second):.2f}; {counts})"
        sides.append((delta, interval, text))
    (delta_a, interval_a, text_a), (delta_b, interval_b, text_b) = sides
    verdict = HOLDS if delta_a > delta_b else FAILS
    evidence = f"change from {setting_names[0]} to {setting_names[1]}: {text_a} vs {text_b}"
    if interval_a is not None and interval_b is not None:
        separate = interval_a[0] > interval_b[1] or interval_b[0] > interval_a[1]
        evidence += "; the 95% intervals separate" if separate else "; the 95% intervals overlap"
        if verdict == HOLDS and not separate:
            verdict = INCONCLUSIVE
    else:
        evidence += f"; fewer than {MIN_SEEDS_FOR_CI} seeds in a cell, no interval"
    return Comparison(label, verdict, evidence)


def _with_interval(values: np.ndarray, digits: str = ".2f") -> str:
    text = f"{stats.mean(values):{digits}}"
    if len(values) >= MIN_SEEDS_FOR_CI:
        low, high = stats.bootstrap_ci(values, stats.mean)
        text += f" [95% CI {low:{digits}}, {high:{digits}}]"
    return text + f" ({len(values)} seed{'s' if len(values) != 1 else ''})"


def combine(comparisons: Sequence[Comparison]) -> str:
    """The verdict of a claim made of several comparisons.

    :param comparisons: its comparisons.
    :return: ``FAILS`` if any fails, else ``MISSING`` if any lacks its runs (or there are none), else
        ``INCONCLUSIVE`` if any is, else ``HOLDS``.
    """
    verdicts = [c.verdict for c in comparisons]
    if FAILS in verdicts:
        return FAILS
    if not verdicts or MISSING in verdicts:
        return MISSING
    if INCONCLUSIVE in verdicts:
        return INCONCLUSIVE
    return HOLDS


def exploration_numbers(metrics: Mapping[str, Any], spec: ExplorationSpec) -> tuple[str, float, str, float] | None:
    """The EBM's number and the strongest random explorer's number of an exploration figure.

    :param metrics: the figure's metrics.
    :param spec: where the numbers are.
    :return: (EBM key, its value, random key, its value); ``exploration_pair``'s guess when the keys are missing.
    """
    flat = _flatten(metrics)
    ours = _average(flat.get(spec.ebm_key))
    theirs = [(key, _average(flat.get(key))) for key in spec.random_keys]
    known = [(key, value) for key, value in theirs if value is not None]
    if ours is None or not known:
        return exploration_pair(metrics)
    key, value = max(known, key=lambda pair: pair[1])
    return spec.ebm_key, ours, key, value


def exploration_pair(metrics: Mapping[str, Any]) -> tuple[str, float, str, float] | None:
    """A guess of the EBM and random exploration numbers of a figure's metrics: keys differing by ``ebm``/``random``.

    :param metrics: the figure's metrics (nested dicts allowed).
    :return: (EBM key, its value, random key, its value), or None when no such pair exists.
    """
    flat = _flatten(metrics)
    candidates = []
    for key, value in flat.items():
        if not re.search(r"ebm", key, flags=re.IGNORECASE) or re.search(r"timestep|transition|step", key, re.IGNORECASE):
            continue
        if key.rsplit("/", 1)[-1].lower() in SPREAD_STATISTICS:
            continue
        partner = re.sub(r"ebm", "random", key, flags=re.IGNORECASE)
        partner = next((k for k in flat if k.lower() == partner.lower()), "")
        ours, theirs = _average(value), _average(flat.get(partner))
        if partner and ours is not None and theirs is not None:
            rank = (
                0 if re.search("coverage|occupan", key, re.IGNORECASE) else 1,
                0 if re.search("final|mean", key, re.IGNORECASE) else 1,
                key,
            )
            candidates.append((rank, key, ours, partner, theirs))
    if not candidates:
        return None
    _, key, ours, partner, theirs = min(candidates)
    return key, ours, partner, theirs


def _flatten(metrics: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in metrics.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(_flatten(value, name + "/"))
        else:
            flat[name] = value
    return flat


def _average(value: Any) -> float | None:
    """The mean of a number or a (nested) list of numbers; None for anything else."""
    if isinstance(value, bool) or value is None:
        return None
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    if array.size == 0 or not np.all(np.isfinite(array)):
        return None
    return float(array.mean())


def evaluate_claims(
    scores: ScoreLookup, figures: FigureLookup, retired: Callable[[CellKey], int] | None = None
) -> list[Claim]:
    """Judge every claim from the numbers the lookups return.

    :param scores: per-seed scores of a table cell.
    :param figures: metrics of a figure part.
    :param retired: runs of a table cell made with earlier library defaults (default: none), named in the evidence
        of a comparison that lacks today's runs.
    :return: the claims with their verdicts and evidence.
    """
    claims = [_score_claim(spec, scores, retired) for spec in SCORE_CLAIMS]
    exploration = []
    for spec_ in EXPLORATION_FIGURES:
        label, part = spec_.label, spec_.part
        metrics = figures(part)
        pair = exploration_numbers(metrics, spec_) if metrics is not None else None
        if metrics is None:
            exploration.append(Comparison(label, MISSING, f"figure {part} not run yet"))
        elif pair is None:
            exploration.append(Comparison(label, MISSING, f"figure {part} reports no EBM / random pair of numbers"))
        else:
            exploration.append(_exploration_comparison(label, part, metrics, *pair))
    claims.append(Claim(EXPLORATION_CLAIM, combine(exploration), tuple(exploration)))
    claims += [_score_claim(spec, scores, retired) for spec in DIRECTED_CLAIMS]
    claims += [_change_claim(spec, scores, retired) for spec in CHANGE_CLAIMS]
    claims += [_no_loss_claim(spec, scores) for spec in NO_LOSS_CLAIMS]
    claims += [_score_claim(spec, scores, retired) for spec in CONTROL_CLAIMS]
    return claims


def _no_loss_claim(spec: NoLossClaim, scores: ScoreLookup) -> Claim:
    comparisons = [
        compare_no_loss(label, f"{_name(new)} (fast preset)", scores(new), f"{_name(old)} (paper preset)", scores(old))
        for label, new, old in spec.comparisons
    ]
    return Claim(spec.text, combine(comparisons), tuple(comparisons))


def per_seed_values(metrics: Mapping[str, Any], key: str) -> list[float] | None:
    """The per-seed values beside a summary number: ``a/b/mean`` -> ``a/b/per_seed``.

    :param metrics: a figure's metrics.
    :param key: the slash-joined path of a mean.
    :return: the finite per-seed values, or None when there are none.
    """
    folder, _, last = key.rpartition("/")
    if last != "mean":
        return None
    values = _flatten(metrics).get(f"{folder}/per_seed")
    if not isinstance(values, list) or not values:
        return None
    array = np.asarray(values, dtype=np.float64)
    return array.tolist() if array.ndim == 1 and np.all(np.isfinite(array)) else None


def _exploration_comparison(
    label: str, part: str, metrics: Mapping[str, Any], key: str, ours: float, partner: str, theirs: float
) -> Comparison:
    mine, other = per_seed_values(metrics, key), per_seed_values(metrics, partner)
    if mine is None or other is None:
        verdict = HOLDS if ours > theirs else FAILS
        evidence = f"{key} = {ours:.4g} vs {partner} = {theirs:.4g}; no per-seed values, no interval ({part})"
        return Comparison(label, verdict, evidence)
    comparison = compare_seeds(label, key, mine, partner, other, digits=".4g")
    return Comparison(label, comparison.verdict, f"{comparison.evidence} ({part})")


def _score_claim(spec: ScoreClaim, scores: ScoreLookup, retired: Callable[[CellKey], int] | None = None) -> Claim:
    count = retired or (lambda _key: 0)
    comparisons = []
    for label, better, worse in spec.comparisons:
        names = _name(better), _name(worse)
        if names[0] == names[1]:  # the same agent in two settings: name the settings
            names = f"{names[0]} ({better[2]})", f"{names[1]} ({worse[2]})"
        counts = count(better), count(worse)
        comparisons.append(compare_scores(label, names[0], scores(better), names[1], scores(worse), counts))
    return Claim(spec.text, combine(comparisons), tuple(comparisons))


def _change_claim(spec: ChangeClaim, scores: ScoreLookup, retired: Callable[[CellKey], int] | None = None) -> Claim:
    count = retired or (lambda _key: 0)
    comparisons = []
    for label, cells, other_cells in spec.comparisons:
        missing = [(f"{_name(cell)} {cell[2]}", count(cell)) for cell in (*cells, *other_cells) if not len(scores(cell))]
        if missing:
            comparisons.append(Comparison(label, MISSING, _not_measured(missing)))
            continue
        comparisons.append(
            compare_changes(
                label,
                _name(cells[0]),
                (scores(cells[0]), scores(cells[1])),
                _name(other_cells[0]),
                (scores(other_cells[0]), scores(other_cells[1])),
                (cells[0][2], cells[1][2]),
            )
        )
    return Claim(spec.text, combine(comparisons), tuple(comparisons))


def _name(key: CellKey) -> str:
    name = AGENT_NAMES.get(key[1], key[1])
    return f"untrained {name}" if key[2].startswith("untrained") else name


def render_claims(claims: Sequence[Claim], reason: Callable[[str, str], str | None] | None = None) -> str:
    """The claims as a markdown list, each comparison under its claim.

    :param claims: from ``evaluate_claims``.
    :param reason: ``(claim text, comparison label) -> what we know of why it does not hold`` (or None); asked only
        for comparisons that do not hold or are inconclusive (``eval.paper.differences.claim_reason``).
    :return: markdown.
    """
    lines = []
    for claim in claims:
        lines.append(f"- **{claim.text}**: {claim.verdict}")
        for comparison in claim.comparisons:
            line = f"  - {comparison.label}: {comparison.verdict} ({comparison.evidence})"
            why = reason(claim.text, comparison.label) if reason and comparison.verdict in (FAILS, INCONCLUSIVE) else None
            lines.append(f"{line}. Why: {why}" if why else line)
    return "\n".join(lines)


__all__ = [
    "CHANGE_CLAIMS",
    "CONTROL_CLAIMS",
    "DIRECTED_CLAIMS",
    "EXPLORATION_CLAIM",
    "EXPLORATION_FIGURES",
    "FAILS",
    "HOLDS",
    "LEARNING_CONTROL",
    "MISSING",
    "SCORE_CLAIMS",
    "SPREAD_STATISTICS",
    "ChangeClaim",
    "Claim",
    "Comparison",
    "ExplorationSpec",
    "ScoreClaim",
    "combine",
    "compare_changes",
    "compare_scores",
    "compare_seeds",
    "evaluate_claims",
    "exploration_numbers",
    "exploration_pair",
    "per_seed_values",
    "render_claims",
]
