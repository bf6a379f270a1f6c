"""The cluster bootstrap of a rating test's condition means: raters and clips resampled together.

A pure function on the long table of ratings (one row per response), as the rest of the statistics (stats/anova.py).
"""

import math
from itertools import combinations

import numpy as np
import pandas as pd
from scipy import sparse

from moglow_eval.core.study import condition_order


def _resample_counts(rng, n_boot, size, dtype=np.float64):
    """n_boot rows of multiplicities of drawing `size` items with replacement from `size` items."""
    idx = rng.integers(0, size, size=(n_boot, size), dtype=np.int32 if size < 2**31 else np.int64)
    out = np.empty((n_boot, size), dtype=dtype)
    for b in range(n_boot):  # row-wise bincount: cache-friendly and no offset array (faster than one flat pass)
        out[b] = np.bincount(idx[b], minlength=size)
    return out


def cluster_bootstrap(
    df,
    dv="rating",
    between="condition",
    rater="rater_id",
    clip="clip_id",
    n_boot=2000,
    seed=0,
    level=0.95,
    dense_limit=30_000_000,
):
    """Two-way cluster bootstrap of the group means: raters resampled with replacement, and clips resampled with
    replacement within their condition (clips are nested in conditions, raters are crossed with them).

    Parameters
    ----------
    df : DataFrame
        One row per rating.
    dv : str
        The column of the ratings.
    between : str
        The column of the groups (conditions).
    rater : str
        The column of the rater ids.
    clip : str
        The column of the clip ids.
    n_boot : int
        The number of replicates.
    seed : int
        The seed of the resampling: a seed gives the same result bit for bit.
    level : float
        The coverage of the percentile intervals.
    dense_limit : int
        The largest rater x clip table, in cells, held as a dense matrix; beyond it the table is sparse. Both
        paths give the same numbers.

    Returns
    -------
    dict
        "means": a DataFrame per group (mean, boot_low, boot_high, boot_se); "differences": a DataFrame per pair
        (group1 < group2, meandiff = group2 - group1, boot_low, boot_high, and boot_p, the two-sided bootstrap
        p-value, add-one); "n_boot", "seed", "level"; "n_degenerate", the replicates in which some group drew no
        rating; "method", in words.

    Notes
    -----
    A replicate weights each rating by (times its rater was drawn) x (times its clip was drawn); a group mean is
    sum(w y) / sum(w). Vectorised: with the rater x clip table S of ratings, the weighted sums of all replicates
    are ((W_rater @ S) * W_clip) @ onehot(condition), one matrix product per chunk of 100 replicates, so memory
    stays bounded. Integer weights and ratings keep every sum exact, so results are bit-reproducible for a seed
    and identical on the dense and sparse paths.
    """
    rc, raters = pd.factorize(df[rater])
    cc, clips = pd.factorize(df[clip])
    cond_codes, conds = pd.factorize(df[between], sort=True)
    y = df[dv].to_numpy(dtype=np.float64)
    clip_cond = np.zeros(len(clips), dtype=np.int64)
    clip_cond[cc] = cond_codes
    boot = _replicate_means(y, rc, cc, clip_cond, len(raters), len(conds), n_boot, seed, dense_limit)
    full = pd.Series(y).groupby(cond_codes).mean().to_numpy()
    means, differences = _summarise(boot, full, conds, between, level)
    return {
        "means": means,
        "differences": differences,
        "n_boot": n_boot,
        "seed": seed,
        "level": level,
        "n_degenerate": int(np.isnan(boot).any(axis=1).sum()),
        "method": "two-way cluster bootstrap (raters; clips within condition), percentile intervals",
    }


def _rating_table(y, rc, cc, R, C, dtype, dense_limit):
    """(the rater x clip table of ratings and counts side by side, whether it is dense): one product per chunk."""
    # BLAS on the full table beats the sparse kernel until the table holds ~20 cells per rating
    use_dense = R * C <= min(dense_limit, 20 * len(y))
    if use_dense:
        SN = np.zeros((R, 2 * C), dtype=dtype)
        SN[rc, cc] = y
        SN[rc, C + cc] = 1.0
        return SN, True
    ratings = sparse.csr_matrix((y, (cc, rc)), shape=(C, R))
    counts = sparse.csr_matrix((np.ones_like(y), (cc, rc)), shape=(C, R))
    return sparse.vstack([ratings, counts]).tocsr().astype(dtype), False


def _replicate_means(y, rc, cc, clip_cond, R, K, n_boot, seed, dense_limit):
    """[n_boot, K] group means of the replicates (NaN where a replicate drew no rating of a group)."""
    C = len(clip_cond)
    onehot = np.zeros((C, K))
    onehot[np.arange(C), clip_cond] = 1.0
    members = [np.flatnonzero(clip_cond == k) for k in range(K)]
    # float32 products are exact while every per-clip sum of (rater weight x rating) stays below 2**24
    # (weights of one replicate sum to R); twice as fast as float64 in both the BLAS and the sparse kernels.
    exact32 = bool(np.all(y == np.rint(y))) and R * max(1.0, float(np.abs(y).max())) < 2**24
    dtype = np.float32 if exact32 else np.float64
    SN, use_dense = _rating_table(y, rc, cc, R, C, dtype, dense_limit)
    rng = np.random.default_rng(seed)
    num = np.empty((n_boot, K))
    den = np.empty((n_boot, K))
    step = 100  # replicates per chunk; fixed so that a seed gives the same draws on either path
    for s in range(0, n_boot, step):
        nb = min(step, n_boot - s)
        wr = _resample_counts(rng, nb, R, dtype)
        wc = np.zeros((nb, C))
        for m in members:  # stratified: each condition keeps its number of clips
            wc[:, m] = _resample_counts(rng, nb, len(m))
        ab = (wr @ SN) if use_dense else (SN @ np.ascontiguousarray(wr.T)).T
        ab = ab.astype(np.float64)
        num[s : s + nb] = (ab[:, :C] * wc) @ onehot
        den[s : s + nb] = (ab[:, C:] * wc) @ onehot
    with np.errstate(invalid="ignore", divide="ignore"):
        return num / den


def _summarise(boot, full, conds, between, level):
    """(per-group means with percentile intervals, per-pair differences with intervals and bootstrap p)."""
    lo, hi = 50 * (1 - level), 50 * (1 + level)
    means = pd.DataFrame(
        {
            "mean": full,
            "boot_low": np.nanpercentile(boot, lo, axis=0),
            "boot_high": np.nanpercentile(boot, hi, axis=0),
            "boot_se": np.nanstd(boot, axis=0, ddof=1),
        },
        index=pd.Index(conds, name=between),
    )
    rows = []
    for i, j in combinations(range(len(conds)), 2):
        d = boot[:, j] - boot[:, i]
        d = d[~np.isnan(d)]
        # add-one Monte Carlo p-value (Davison & Hinkley 1997, ch. 4): never 0 with finitely many resamples
        tail = min((d <= 0).sum(), (d >= 0).sum())
        p_boot = min(1.0, 2 * (tail + 1) / (len(d) + 1)) if len(d) else math.nan
        rows.append(
            {
                "group1": conds[i],
                "group2": conds[j],
                "meandiff": float(full[j] - full[i]),
                "boot_low": float(np.percentile(d, lo)),
                "boot_high": float(np.percentile(d, hi)),
                "boot_p": float(p_boot),
            }
        )
    if between == "condition":
        means = means.loc[condition_order(means.index)]
    return means, pd.DataFrame(rows)
