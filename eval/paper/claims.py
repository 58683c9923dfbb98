"""The reproduction's claims (issue 6), judged from the measured numbers: "holds", "inconclusive", "does not hold" or
"not measured".

Nothing here knows a verdict in advance: each claim names the numbers it compares (table cells by id; exploration
figures by part and metric keys) and ``evaluate_claims`` reads them through the lookups it is given.

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
  from 3 seeds on. Otherwise the means alone decide, and the evidence says no interval was computed. A figure
  whose metrics lack the keys is "not measured".

The claims themselves, with the cells and figures each compares, are data: ``paper.yaml``, ``claims``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from eval import stats
from eval.paper.data import note, paper_data
from eval.paper.parts import AGENT_LABELS

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

Retired = Callable[[CellKey], int]
"""Runs of a cell made with earlier library defaults."""


@dataclass(frozen=True)
class Comparison:
    """One measured comparison behind a claim.

    :param label: what it compares on (an env).
    :param verdict: ``HOLDS``, ``INCONCLUSIVE``, ``FAILS`` or ``MISSING``.
    :param evidence: the numbers, in words.
    :param why: the ``notes.md`` id of what we know of why it does not hold, or None.
    """

    label: str
    verdict: str
    evidence: str
    why: str | None = None


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
class ComparisonSpec:
    """One comparison of a claim, as ``paper.yaml`` states it.

    :param label: what it compares on (an env).
    :param cells: the cells compared: ``score``: (better, worse); ``no_loss``: (new, reference); ``change``: (first
        agent before, after, other agent before, after); ``exploration``: none.
    :param why: the ``notes.md`` id shown while the comparison does not hold, or None.
    :param figure: ``exploration`` only: the figure part.
    :param ebm_key: ``exploration`` only: the EBM's number, a slash-joined path into the figure's metrics.
    :param random_keys: ``exploration`` only: the random explorers' numbers at the EBM's budget; the highest is
        compared.
    """

    label: str
    cells: tuple[CellKey, ...] = ()
    why: str | None = None
    figure: str = ""
    ebm_key: str = ""
    random_keys: tuple[str, ...] = ()


@dataclass(frozen=True)
class ClaimSpec:
    """A claim as ``paper.yaml`` states it.

    :param kind: ``score`` (one cell beats another), ``change`` (a change of setting costs the first agent less),
        ``no_loss`` (a configuration loses no score against a reference) or ``exploration``.
    :param text: the claim.
    :param comparisons: one per env.
    """

    kind: str
    text: str
    comparisons: tuple[ComparisonSpec, ...]


CLAIM_CELLS = {"score": ("better", "worse"), "no_loss": ("new", "reference"), "change": ("first", "other")}
"""The ``paper.yaml`` fields naming a comparison's cells, by kind (``change``: two [before, after] pairs)."""


def cell_keys() -> dict[str, CellKey]:
    """Every table cell of ``paper.yaml`` by id (``<part>:<agent>[:<key>]``, ``eval.paper.parts.Cell.id``).

    :return: id -> (part, agent, setting).
    """
    keys = {}
    for experiment in paper_data()["experiments"]:
        for part in experiment["parts"]:
            for cell in part.get("cells", ()):
                suffix = f":{cell['key']}" if cell.get("key") else ""
                keys[f"{part['name']}:{cell['agent']}{suffix}"] = (part["name"], cell["agent"], cell["setting"])
    return keys


def _comparison(kind: str, entry: dict[str, Any], keys: dict[str, CellKey]) -> ComparisonSpec:
    if kind == "exploration":
        return ComparisonSpec(
            entry["label"],
            why=entry.get("why"),
            figure=entry["figure"],
            ebm_key=entry["ebm"],
            random_keys=tuple(entry["random"]),
        )
    names: list[str] = []
    for field in CLAIM_CELLS[kind]:
        value = entry[field]
        names += value if isinstance(value, list) else [value]
    unknown = [name for name in names if name not in keys]
    if unknown:
        raise ValueError(f"paper.yaml: a claim names cells that do not exist: {unknown}")
    return ComparisonSpec(entry["label"], tuple(keys[name] for name in names), entry.get("why"))


def load_claims() -> tuple[ClaimSpec, ...]:
    """The claims of ``paper.yaml``, in the order they are judged and reported.

    :return: the specs, cells resolved to (part, agent, setting).
    :raises ValueError: for an unknown kind or cell.
    """
    keys, specs = cell_keys(), []
    for claim in paper_data()["claims"]:
        kind = claim["kind"]
        if kind not in (*CLAIM_CELLS, "exploration"):
            raise ValueError(f"paper.yaml: unknown claim kind {kind!r}; known: {[*CLAIM_CELLS, 'exploration']}")
        comparisons = tuple(_comparison(kind, entry, keys) for entry in claim["compare"])
        specs.append(ClaimSpec(kind, claim["text"], comparisons))
    return tuple(specs)


CLAIMS = load_claims()
"""Every claim, in ``paper.yaml``'s order."""


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
    if len(second) >= stats.MIN_SEEDS_FOR_CI:
        low, high = stats.bootstrap_ci(second, stats.mean)
        reference = f"{other_name} {stats.mean(second):.2f} [95% CI {low:.2f}, {high:.2f}]"
    else:
        low = float(second.min())
        reference = f"{other_name} {stats.mean(second):.2f} (lowest seed {low:.2f}; fewer than {stats.MIN_SEEDS_FOR_CI} seeds)"
    mean = stats.mean(first)
    verdict = HOLDS if mean >= low else FAILS
    where = (
        "above the interval"
        if len(second) >= stats.MIN_SEEDS_FOR_CI and mean > high
        else "within"
        if verdict == HOLDS
        else "below"
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
    if len(first) >= stats.MIN_SEEDS_FOR_CI and len(second) >= stats.MIN_SEEDS_FOR_CI:
        low_a, high_a = stats.bootstrap_ci(first, stats.mean)
        low_b, high_b = stats.bootstrap_ci(second, stats.mean)
        separate = low_a > high_b or low_b > high_a
        evidence += "; the 95% intervals separate" if separate else "; the 95% intervals overlap"
        if verdict == HOLDS and not separate:
            verdict = INCONCLUSIVE
    else:
        evidence += f"; fewer than {stats.MIN_SEEDS_FOR_CI} seeds on a side, no interval"
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
        interval = stats.bootstrap_difference_ci(first, second) if seeds >= stats.MIN_SEEDS_FOR_CI else None
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
        evidence += f"; fewer than {stats.MIN_SEEDS_FOR_CI} seeds in a cell, no interval"
    return Comparison(label, verdict, evidence)


def _with_interval(values: np.ndarray, digits: str = ".2f") -> str:
    text = f"{stats.mean(values):{digits}}"
    if len(values) >= stats.MIN_SEEDS_FOR_CI:
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


def exploration_numbers(metrics: Mapping[str, Any], spec: ComparisonSpec) -> tuple[str, float, str, float] | None:
    """The EBM's number and the strongest random explorer's number of an exploration figure.

    :param metrics: the figure's metrics.
    :param spec: where the numbers are (an ``exploration`` comparison).
    :return: (EBM key, its value, random key, its value), or None when the metrics lack them.
    """
    flat = _flatten(metrics)
    ours = _average(flat.get(spec.ebm_key))
    known = [(key, value) for key in spec.random_keys if (value := _average(flat.get(key))) is not None]
    if ours is None or not known:
        return None
    key, value = max(known, key=lambda pair: pair[1])
    return spec.ebm_key, ours, key, value


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
    """Judge every claim (``CLAIMS``) from the numbers the lookups return.

    :param scores: per-seed scores of a table cell.
    :param figures: metrics of a figure part.
    :param retired: runs of a table cell made with earlier library defaults (default: none), named in the evidence
        of a comparison that lacks today's runs.
    :return: the claims with their verdicts and evidence, in ``CLAIMS``' order.
    """
    count = retired or (lambda _key: 0)
    judge = {"score": _score, "change": _change, "no_loss": _no_loss, "exploration": _exploration}
    claims = []
    for spec in CLAIMS:
        comparisons = [replace(judge[spec.kind](item, scores, figures, count), why=item.why) for item in spec.comparisons]
        claims.append(Claim(spec.text, combine(comparisons), tuple(comparisons)))
    return claims


def _exploration(item: ComparisonSpec, scores: ScoreLookup, figures: FigureLookup, count: Retired) -> Comparison:
    metrics = figures(item.figure)
    if metrics is None:
        return Comparison(item.label, MISSING, f"figure {item.figure} not run yet")
    numbers = exploration_numbers(metrics, item)
    if numbers is None:
        keys = ", ".join((item.ebm_key, *item.random_keys))
        return Comparison(item.label, MISSING, f"figure {item.figure} reports none of {keys}")
    return _exploration_comparison(item.label, item.figure, metrics, *numbers)


def _no_loss(item: ComparisonSpec, scores: ScoreLookup, figures: FigureLookup, count: Retired) -> Comparison:
    new, old = item.cells
    names = f"{_name(new)} ({new[2]})", f"{_name(old)} ({old[2]})"  # the cells' settings tell the two apart
    return compare_no_loss(item.label, names[0], scores(new), names[1], scores(old))


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


def _score(item: ComparisonSpec, scores: ScoreLookup, figures: FigureLookup, count: Retired) -> Comparison:
    better, worse = item.cells
    names = _name(better), _name(worse)
    if names[0] == names[1]:  # the same agent in two settings: name the settings
        names = f"{names[0]} ({better[2]})", f"{names[1]} ({worse[2]})"
    return compare_scores(item.label, names[0], scores(better), names[1], scores(worse), (count(better), count(worse)))


def _change(item: ComparisonSpec, scores: ScoreLookup, figures: FigureLookup, count: Retired) -> Comparison:
    before, after, other_before, other_after = item.cells
    missing = [(f"{_name(cell)} {cell[2]}", count(cell)) for cell in item.cells if not len(scores(cell))]
    if missing:
        return Comparison(item.label, MISSING, _not_measured(missing))
    return compare_changes(
        item.label,
        _name(before),
        (scores(before), scores(after)),
        _name(other_before),
        (scores(other_before), scores(other_after)),
        (before[2], after[2]),
    )


def _name(key: CellKey) -> str:
    name = AGENT_LABELS.get(key[1], key[1])
    return f"untrained {name}" if key[2].startswith("untrained") else name


def render_claims(claims: Sequence[Claim]) -> str:
    """The claims as a markdown list, each comparison under its claim, with the note of why (``notes.md``) after
    each comparison that does not hold or is inconclusive and names one.

    :param claims: from ``evaluate_claims``.
    :return: markdown.
    """
    lines = []
    for claim in claims:
        lines.append(f"- **{claim.text}**: {claim.verdict}")
        for comparison in claim.comparisons:
            line = f"  - {comparison.label}: {comparison.verdict} ({comparison.evidence})"
            why = note(comparison.why) if comparison.why and comparison.verdict in (FAILS, INCONCLUSIVE) else None
            lines.append(f"{line}. Why: {why}" if why else line)
    return "\n".join(lines)


__all__ = [
    "CLAIMS",
    "FAILS",
    "HOLDS",
    "INCONCLUSIVE",
    "MISSING",
    "Claim",
    "ClaimSpec",
    "Comparison",
    "ComparisonSpec",
    "cell_keys",
    "combine",
    "compare_changes",
    "compare_no_loss",
    "compare_scores",
    "compare_seeds",
    "evaluate_claims",
    "exploration_numbers",
    "load_claims",
    "per_seed_values",
    "render_claims",
]
