"""eval.stats against values computed by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eval import stats


def test_mean_and_population_std_by_hand():
    scores = [2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0]
    assert stats.mean(scores) == 5.0
    # Squared deviations 9+1+1+1+0+0+4+16 = 32, / 8 = 4 -> population std 2.
    assert stats.std(scores) == 2.0
    # Sample std: sqrt(32 / 7).
    assert stats.std(scores, ddof=1) == pytest.approx(math.sqrt(32 / 7))


def test_std_of_one_value_is_zero_for_any_ddof():
    assert stats.std([3.5]) == 0.0
    assert stats.std([3.5], ddof=1) == 0.0


def test_standard_error_by_hand():
    # Sample std of [1, 2, 3] is 1, so the standard error is 1 / sqrt(3).
    assert stats.standard_error([1.0, 2.0, 3.0]) == pytest.approx(1 / math.sqrt(3))
    assert stats.standard_error([1.0]) == 0.0


@pytest.mark.parametrize(
    ("scores", "expected"),
    [
        # 8 values: 2 cut from each end, mean of 3, 4, 5, 6.
        ([8, 1, 7, 2, 6, 3, 5, 4], 4.5),
        # 4 values: 1 cut from each end, mean of 2 and 10; an outlier of 1000 does not count.
        ([1, 2, 10, 1000], 6.0),
        # 3 values: int(0.75) = 0 cut, so the IQM is the mean.
        ([1, 2, 6], 3.0),
        # 5 values: int(1.25) = 1 cut from each end, mean of 2, 3, 4.
        ([-100, 2, 3, 4, 100], 3.0),
    ],
)
def test_iqm_by_hand(scores, expected):
    assert stats.iqm(scores) == pytest.approx(expected)


def test_iqm_pools_a_matrix_like_rliable():
    # [runs x tasks]; rliable's aggregate_iqm trims over all entries.
    matrix = np.array([[8, 1], [7, 2], [6, 3], [5, 4]])
    assert stats.iqm(matrix) == pytest.approx(4.5)


def test_bootstrap_ci_of_two_values_spans_them():
    # Resampled means of {0, 1}: 0 (p 1/4), 0.5 (p 1/2), 1 (p 1/4): the 2.5th and 97.5th percentiles are 0 and 1.
    low, high = stats.bootstrap_ci([0.0, 1.0], statistic=stats.mean, reps=2000, seed=0)
    assert (low, high) == (0.0, 1.0)


def test_bootstrap_ci_matches_the_exact_binomial_percentiles():
    # Mean of 4 draws from {0, 0, 0, 1} = Binomial(4, 1/4) / 4: P(0) = 0.316, P(<= 0.5) = 0.949, P(<= 0.75) = 0.996,
    # so the 95% percentile interval is [0, 0.75].
    low, high = stats.bootstrap_ci([0.0, 0.0, 0.0, 1.0], statistic=stats.mean, reps=4000, seed=1)
    assert (low, high) == (0.0, 0.75)


def test_bootstrap_ci_is_stratified_by_task():
    # Task 0 all zeros, task 1 all ones: resampling within tasks keeps the pooled mean at 0.5 exactly;
    # pooling runs across tasks would move it.
    matrix = np.column_stack([np.zeros(5), np.ones(5)])  # [runs=5, tasks=2]
    assert stats.bootstrap_ci(matrix, statistic=stats.mean, reps=500) == (0.5, 0.5)


def test_bootstrap_ci_is_reproducible_and_brackets_the_estimate():
    rng = np.random.default_rng(3)
    scores = rng.normal(-10.0, 2.0, size=10)
    first = stats.bootstrap_ci(scores, seed=7)
    assert first == stats.bootstrap_ci(scores, seed=7)
    assert first != stats.bootstrap_ci(scores, seed=8)
    assert first[0] <= stats.iqm(scores) <= first[1]
    assert first[0] < first[1]


def test_fast_paths_match_the_generic_loop():
    scores = np.random.default_rng(0).normal(size=(7, 2))
    assert stats.bootstrap_ci(scores, stats.iqm, reps=300) == pytest.approx(
        stats.bootstrap_ci(scores, lambda sample: stats.iqm(sample), reps=300)
    )
    assert stats.bootstrap_ci(scores, stats.mean, reps=300) == pytest.approx(
        stats.bootstrap_ci(scores, lambda sample: float(np.mean(sample)), reps=300)
    )


def test_constant_scores_have_a_point_interval():
    assert stats.bootstrap_ci([-4.5, -4.5, -4.5]) == (-4.5, -4.5)


@pytest.mark.parametrize("bad", [[], [1.0, float("nan")], [float("inf")]])
def test_empty_or_non_finite_scores_raise(bad):
    with pytest.raises(ValueError, match=r"empty|NaN"):
        stats.mean(bad)


def test_bad_bootstrap_arguments_raise():
    with pytest.raises(ValueError, match="confidence"):
        stats.bootstrap_ci([1.0, 2.0], confidence=95)
    with pytest.raises(ValueError, match="reps"):
        stats.bootstrap_ci([1.0, 2.0], reps=0)
    with pytest.raises(ValueError, match="runs x tasks"):
        stats.bootstrap_ci(np.zeros((2, 2, 2)))


def test_bootstrap_difference_ci_brackets_the_change_and_resamples_each_side_alone():
    before, after = [-270.0, -262.0, -280.0], [-258.0, -257.0, -259.0, -256.0]  # other runs, other counts
    low, high = stats.bootstrap_difference_ci(before, after, seed=1)
    assert (low, high) == stats.bootstrap_difference_ci(before, after, seed=1)
    assert low <= stats.mean(after) - stats.mean(before) <= high and low < high
    # Constant sides: every resample has the same means, so the interval is the difference itself.
    assert stats.bootstrap_difference_ci([1.0, 1.0], [4.0, 4.0, 4.0], reps=50) == (3.0, 3.0)
    # By hand: before [0, 2] resamples to means 0, 1 or 2 (1/4, 1/2, 1/4), after is 10: the change is 8, 9 or 10.
    low, high = stats.bootstrap_difference_ci([0.0, 2.0], [10.0], reps=4000, confidence=0.5)
    assert (low, high) == (9.0, 9.0)
    with pytest.raises(ValueError, match="before is empty"):
        stats.bootstrap_difference_ci([], [1.0])
    with pytest.raises(ValueError, match="must be \\[runs\\] vectors"):
        stats.bootstrap_difference_ci(np.zeros((2, 2)), [1.0])
