"""Ranks with ties averaged, and the AUC they give: one definition for the parts that rank values.

The two-sample tests' classifier scores (generation.metrics.c2st), the blinding check's coded sizes
(rendering.blinding) and the simulated raters' metric distances (rating_app.simulate.raters) rank values the way
scipy.stats.rankdata does by default, and the first two turn the ranks into an AUC. This is the same arithmetic in
numpy alone: importing scipy.stats costs a short command (a crowd, a small build) most of a second for one ranking.
"""

import numpy as np


def average_ranks(values, axis=0):
    """Ranks 1..n of `values` along `axis`, tied values given the mean of their ranks, as float64 (scipy.stats.rankdata
    with method="average"); a slice holding a NaN is all NaN, as scipy's default nan_policy gives."""
    x = np.moveaxis(np.atleast_1d(np.asarray(values, dtype=float)), axis, -1)
    ranks = np.empty(x.shape)
    for index in np.ndindex(x.shape[:-1]):  # each slice along `axis` on its own
        ranks[index] = _ranks_1d(x[index])
    return np.moveaxis(ranks, -1, axis)


def _ranks_1d(x):
    if np.isnan(x).any():
        return np.full(len(x), np.nan)
    order = np.argsort(x, kind="stable")
    ordered = x[order]
    starts = np.flatnonzero(np.r_[True, ordered[1:] != ordered[:-1]])  # where each run of equal values begins
    ends = np.r_[starts[1:], len(x)]
    ranks = np.empty(len(x))
    ranks[order] = np.repeat((starts + 1 + ends) / 2, ends - starts)  # each run: the mean of its ranks start+1 .. end
    return ranks


def auc(a, b):
    """P(a value of `a` > one of `b`), ties counted half: the Mann-Whitney U of `a` over n_a n_b, from the ranks of
    both together. NaN where either is empty or a value is NaN."""
    a, b = np.asarray(a, dtype=float).ravel(), np.asarray(b, dtype=float).ravel()
    if not len(a) or not len(b):
        return float("nan")
    ranks = average_ranks(np.concatenate([a, b]))
    return float(auc_of_rank_sums(ranks[: len(a)].sum(), len(a), len(b)))


def auc_of_rank_sums(rank_sums, n_a, n_b):
    """The AUC of `a` (P(a > b), ties half) from the sums of its ranks among all n_a + n_b values (arrays welcome)."""
    return (rank_sums - n_a * (n_a + 1) / 2) / (n_a * n_b)
