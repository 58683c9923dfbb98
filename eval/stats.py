"""Summary statistics of evaluation scores: mean, std, interquartile mean and stratified bootstrap intervals.

Conventions (one for the whole harness, so that every table agrees with TensorBoard):

- ``std`` is the *population* standard deviation (``ddof=0``), the one SB3's ``evaluate_policy`` and
  ``EvalCallback`` report as ``std_reward`` and the one rl-zoo3 and CleanRL print over seeds. With 3 seeds
  it is smaller than the sample std by a factor sqrt(2/3); pass ``ddof=1`` where the sample std is wanted.
- ``iqm`` is rliable's interquartile mean, ``scipy.stats.trim_mean(x, 0.25)``: 25 % of the values are cut
  from each end (rounded down), then the rest is averaged. With fewer than 4 values nothing is cut.
- ``bootstrap_ci`` follows rliable's stratified bootstrap: scores form a [runs x tasks] matrix, each task's
  column is resampled with replacement on its own (runs are never moved across tasks), the statistic is
  applied to each resampled matrix, and the percentile interval is returned. The harness treats one seed
  as one run and one environment as one task.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy import stats as scipy_stats

ArrayLike = Sequence[float] | np.ndarray

MIN_SEEDS_FOR_CI = 3
"""The fewest seeds from which the harness computes a 95% interval (and an IQM) and judges by it."""


def _as_array(values: ArrayLike, name: str = "values") -> np.ndarray:
    array = np.asarray(values, dtype=np.float64)
    if array.size == 0:
        raise ValueError(f"{name} is empty: at least one score is needed to compute a statistic")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} contains NaN or infinite scores: drop failed runs before aggregating")
    return array


def mean(values: ArrayLike) -> float:
    """Arithmetic mean of all values.

    :param values: scores (any shape; all entries are pooled).
    :return: the mean.
    """
    return float(np.mean(_as_array(values)))


def std(values: ArrayLike, ddof: int = 0) -> float:
    """Standard deviation of all values, population (``ddof=0``) by default like SB3's ``evaluate_policy``.

    :param values: scores (any shape; all entries are pooled).
    :param ddof: delta degrees of freedom (0: population std, 1: sample std).
    :return: the standard deviation; 0.0 for a single value whatever ``ddof``.
    """
    array = _as_array(values)
    if array.size <= ddof:
        return 0.0
    return float(np.std(array, ddof=ddof))


def standard_error(values: ArrayLike) -> float:
    """Standard error of the mean, ``std(ddof=1) / sqrt(n)`` (rl-zoo3's band on learning curves).

    :param values: scores (all entries are pooled).
    :return: the standard error; 0.0 for a single value.
    """
    array = _as_array(values)
    if array.size < 2:
        return 0.0
    return float(np.std(array, ddof=1) / np.sqrt(array.size))


def iqm(values: ArrayLike) -> float:
    """Interquartile mean: the mean of the middle 50 % of the values (rliable's ``aggregate_iqm``).

    :param values: scores (all entries are pooled).
    :return: ``scipy.stats.trim_mean(values, 0.25)``.
    """
    return float(scipy_stats.trim_mean(_as_array(values).ravel(), proportiontocut=0.25))


def _check_resampling(reps: int, confidence: float) -> None:
    """A clear error for a resampling count below 1 or a confidence outside (0, 1)."""
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence}; e.g. 0.95 for a 95% interval")
    if reps < 1:
        raise ValueError(f"reps must be a positive number of resamples, got {reps}")


def bootstrap_ci(
    scores: ArrayLike,
    statistic: Callable[[np.ndarray], float] = iqm,
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile confidence interval of ``statistic`` by stratified bootstrap over runs.

    :param scores: a [runs] vector (one task) or a [runs x tasks] matrix; each column is resampled on its own.
    :param statistic: maps a resampled [runs x tasks] matrix to a number (default: IQM of all entries).
    :param reps: number of bootstrap resamples (rliable and rl-zoo3 use 2000).
    :param confidence: coverage of the interval, in (0, 1).
    :param seed: seed of the resampling generator, so that a report is reproducible.
    :return: (lower, upper) bounds of the interval.
    """
    matrix = _as_array(scores, "scores")
    if matrix.ndim == 1:
        matrix = matrix[:, None]  # [runs, 1] a single task
    if matrix.ndim != 2:
        raise ValueError(f"scores must be [runs] or [runs x tasks], got shape {matrix.shape}")
    _check_resampling(reps, confidence)
    n_runs, n_tasks = matrix.shape
    rng = np.random.default_rng(seed)
    # [reps, runs, tasks] row indices drawn per task: the stratification keeps every run inside its own task.
    run_indices = rng.integers(0, n_runs, size=(reps, n_runs, n_tasks))
    task_indices = np.broadcast_to(np.arange(n_tasks), run_indices.shape)
    resampled = matrix[run_indices, task_indices]  # [reps, runs, tasks]
    flat = resampled.reshape(reps, -1)  # [reps, runs * tasks]
    if statistic is iqm:  # vectorised fast paths of the two usual statistics, same numbers
        estimates = scipy_stats.trim_mean(flat, proportiontocut=0.25, axis=1)  # [reps]
    elif statistic is mean:
        estimates = flat.mean(axis=1)
    else:
        estimates = np.array([statistic(sample) for sample in resampled])
    alpha = (1.0 - confidence) / 2.0
    lower, upper = np.percentile(estimates, [100.0 * alpha, 100.0 * (1.0 - alpha)])
    return float(lower), float(upper)


def bootstrap_difference_ci(
    before: ArrayLike,
    after: ArrayLike,
    reps: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile confidence interval of ``mean(after) - mean(before)``, each side's runs resampled on their own.

    For the change of one agent's score between two settings whose runs are independent (other runs, not the same
    run measured twice), so the two sides may have different numbers of runs.

    :param before: the first setting's [runs] scores.
    :param after: the second setting's [runs] scores.
    :param reps: number of bootstrap resamples.
    :param confidence: coverage of the interval, in (0, 1).
    :param seed: seed of the resampling generator, so that a report is reproducible.
    :return: (lower, upper) bounds of the interval of the difference of means.
    """
    first, second = _as_array(before, "before"), _as_array(after, "after")
    if first.ndim != 1 or second.ndim != 1:
        raise ValueError(f"before and after must be [runs] vectors, got shapes {first.shape} and {second.shape}")
    _check_resampling(reps, confidence)
    rng = np.random.default_rng(seed)
    first_means = first[rng.integers(0, len(first), size=(reps, len(first)))].mean(axis=1)  # [reps]
    second_means = second[rng.integers(0, len(second), size=(reps, len(second)))].mean(axis=1)  # [reps]
    alpha = (1.0 - confidence) / 2.0
    lower, upper = np.percentile(second_means - first_means, [100.0 * alpha, 100.0 * (1.0 - alpha)])
    return float(lower), float(upper)


__all__ = ["MIN_SEEDS_FOR_CI", "bootstrap_ci", "bootstrap_difference_ci", "iqm", "mean", "standard_error", "std"]
