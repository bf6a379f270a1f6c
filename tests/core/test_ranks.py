"""moglow_eval.core.ranks: ranks with ties averaged and the AUC they give, exactly as scipy.stats.rankdata and the
Mann-Whitney U give them (the parts rank in numpy alone, so that a short command does not import scipy.stats)."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.stats import mannwhitneyu, rankdata

from moglow_eval.core.ranks import auc, auc_of_rank_sums, average_ranks

# Few distinct values, so that ties are common; NaN now and then.
VALUES = st.lists(st.sampled_from([-2.0, -0.5, 0.0, 0.0, 1.0, 3.5, 1e9, np.nan]), max_size=30)


@given(VALUES)
def test_ranks_are_scipys_average_ranks_bit_for_bit(values):
    ours, theirs = average_ranks(values), rankdata(values)
    assert ours.dtype == np.float64 and ours.shape == theirs.shape
    assert np.array_equal(ours, theirs, equal_nan=True)


@given(st.integers(1, 6), st.integers(1, 4), st.integers(0, 2**32 - 1))
def test_ranks_along_an_axis_rank_each_slice_alone(rows, cols, seed):
    x = np.random.default_rng(seed).integers(0, 4, (rows, cols)).astype(float)
    if seed % 3 == 0:
        x[seed % rows, seed % cols] = np.nan  # its column (axis 0) or row (axis 1) all NaN, the others ranked
    assert np.array_equal(average_ranks(x, axis=0), rankdata(x, axis=0), equal_nan=True)
    assert np.array_equal(average_ranks(x, axis=1), rankdata(x, axis=1), equal_nan=True)


def test_auc_counts_ties_half():
    assert auc([1, 2], [0, 0]) == 1.0 and auc([0], [0]) == 0.5 and auc([0, 3], [1, 2]) == 0.5
    assert auc([1, 2], [3, 4]) == 0.0 and np.isnan(auc([], [1])) and np.isnan(auc([1, np.nan], [2]))


@given(st.lists(st.integers(0, 5), min_size=1, max_size=20), st.lists(st.integers(0, 5), min_size=1, max_size=20))
def test_auc_is_the_mann_whitney_u_over_the_pairs(a, b):
    u = mannwhitneyu(a, b, alternative="two-sided").statistic  # U of the first sample, ties half
    assert auc(a, b) == pytest.approx(u / (len(a) * len(b)), abs=1e-12)
    ranks = average_ranks(a + b)
    assert auc_of_rank_sums(ranks[: len(a)].sum(), len(a), len(b)) == auc(a, b)
