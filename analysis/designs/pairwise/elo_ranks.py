"""The ranking a pairwise study supports: Elo, rank intervals, groups, and how reliable the order is.

Pure functions on the Bradley-Terry fit of analysis.designs.pairwise.preference and its bootstrap over raters:

- **Elo.** The log strengths on the chess scale the GENEA leaderboard reports (Nagy et al. 2025): 400 points per
  factor of ten in the odds of winning, the reference condition at 1000. A gap of 400 Elo means odds of 10 to 1.
- **Rank intervals.** Each bootstrap resample ranks the conditions (1 = strongest); a condition's interval holds
  the central `level` share of its ranks. They come from the same resampling of raters as the strength intervals,
  so they respect that one rater's answers hang together.
- **Groups.** Conditions in the point estimates' order, merged while their rank intervals overlap: two conditions
  in different groups have disjoint rank intervals, so the table never states an order the data do not support
  (the leaderboard's combined rank averages point estimates, which can order conditions whose intervals overlap).
- **Split-half reliability.** The raters are split into two random halves many times; each half is fitted on its
  own, and Kendall's tau between the halves' strengths says how well the order replicates with half the raters.
"""

import math

import numpy as np
import pandas as pd
from scipy import stats as sps

from moglow_eval.core import pair_posterior

# The scale is the app's (moglow_eval.core.pair_posterior): 400 Elo per factor of ten in the odds; the report puts the
# reference condition, not the mean one, at ELO_ANCHOR.
ELO_ANCHOR, ELO_PER_LOG = pair_posterior.ELO_ANCHOR, pair_posterior.ELO_PER_LOG


def elo(theta, reference_theta=0.0):
    """Log strengths (scalar or array) as Elo, the reference's strength at ELO_ANCHOR."""
    return ELO_ANCHOR + ELO_PER_LOG * (np.asarray(theta, dtype=float) - reference_theta)


# Log strengths closer than this are one strength when ranked: the fit is far more precise, and conditions the votes
# treat alike (ties among them, the same wins and losses) come out equal only to rounding.
SAME_STRENGTH = 1e-3  # 0.07 Elo points


def tied_ranks(row):
    """Ranks of strengths `row` (1 = strongest); strengths within SAME_STRENGTH of their neighbour in order share
    their mean rank."""
    row = np.asarray(row, dtype=float)
    order = np.argsort(-row, kind="stable")
    run = np.r_[0, np.cumsum(np.diff(-row[order]) > SAME_STRENGTH)]  # a new run where the gap is real
    positions = np.arange(1, len(row) + 1, dtype=float)
    mean = np.bincount(run, weights=positions) / np.bincount(run)
    out = np.empty(len(row))
    out[order] = mean[run]
    return out


def ranks(boot):
    """Ranks [B, K] of bootstrap strengths [B, K]: 1 = strongest; equal strengths share their mean rank."""
    return np.apply_along_axis(tied_ranks, 1, np.atleast_2d(boot))


def groups(order, rank_low, rank_high, tied=()):
    """Group numbers (1 = best) for conditions in `order` (strongest first), merging neighbours while their rank
    intervals overlap, or where a condition is `tied` with the one above it (within the indifference margin);
    `rank_low`/`rank_high` are dicts by condition."""
    out, g, reach = {}, 0, -math.inf
    for c in order:
        if rank_low[c] > reach and c not in tied:  # disjoint from every condition above: a new group starts
            g += 1
        out[c] = g
        reach = max(reach, rank_high[c])
    return out


def unbounded(pairs):
    """{condition: note} for conditions whose strength has no finite estimate: one that never won a vote (nor
    tied one) sits at the ridge's floor, one that never lost at its ceiling; their Elo is a bound, not a value."""
    notes = {}
    for cond in set(pairs["condition_a"]) | set(pairs["condition_b"]):
        a, b = pairs[pairs["condition_a"] == cond], pairs[pairs["condition_b"] == cond]
        won = a["wins_a"].sum() + b["wins_b"].sum() + a["ties"].sum() + b["ties"].sum()
        lost = a["wins_b"].sum() + b["wins_a"].sum() + a["ties"].sum() + b["ties"].sum()
        if won == 0:
            notes[cond] = "never won a vote: its Elo is an upper bound"
        elif lost == 0:
            notes[cond] = "never lost a vote: its Elo is a lower bound"
    return notes


def tied_with_above(order, boot, conds, margin_elo, confidence=pair_posterior.TIE_CONFIDENCE):
    """The conditions of `order` (strongest first) whose Elo difference from the one above lies within
    `margin_elo` in at least `confidence` of the bootstrap resamples: the app's indifference zone
    (moglow_eval.core.pair_posterior.tied), which the report groups."""
    if not margin_elo or len(boot) == 0:
        return set()
    col = {c: k for k, c in enumerate(conds)}
    m = margin_elo / ELO_PER_LOG
    return {
        c
        for above, c in zip(order[:-1], order[1:])
        if np.mean(np.abs(boot[:, col[above]] - boot[:, col[c]]) < m) >= confidence
    }


def rank_table(strengths, boot, conds, reference, level=0.95, notes=None, margin_elo=0.0):
    """One row per condition, strongest first.

    Parameters
    ----------
    strengths : dict
        {condition: log strength}, as from analysis.designs.pairwise.preference.bradley_terry.
    boot : ndarray
        The bootstrap's log strengths [B, K], columns in `conds` order.
    conds : list of str
        The conditions, in the order of `boot`'s columns.
    reference : str
        The condition at ELO_ANCHOR.
    level : float
        The coverage of the intervals.
    notes : dict or None
        {condition: note} shown beside it (`unbounded`).
    margin_elo : float
        The indifference margin: a condition whose Elo lies within it of the one above in 95% of the resamples
        shares its group (the app's PAIRING_INDIFFERENCE, off by default; 0: groups by rank intervals alone).

    Returns
    -------
    DataFrame
        condition, log_strength, elo, elo_low, elo_high, rank (of the point estimate), rank_low, rank_high,
        group (1 = best; conditions in one group are not told apart, or are tied within the margin), rank_range
        (e.g. "1-3"), note (`notes`' entry, e.g. from `unbounded`, else empty).
    """
    boot = np.asarray(boot, dtype=float).reshape(-1, len(conds))
    ref = strengths[reference]
    lo_q, hi_q = 100 * (1 - level) / 2, 100 * (1 + level) / 2
    r = ranks(boot)
    point = dict(zip(conds, tied_ranks([strengths[c] for c in conds])))
    rows = []
    for k, c in enumerate(conds):
        e = elo(boot[:, k], boot[:, conds.index(reference)]) if len(boot) else np.array([elo(strengths[c], ref)])
        rows.append(
            {
                "condition": c,
                "log_strength": strengths[c] - ref,
                "elo": float(elo(strengths[c], ref)),
                "elo_low": float(np.percentile(e, lo_q)),
                "elo_high": float(np.percentile(e, hi_q)),
                "rank": float(point[c]),
                # Ranks are whole numbers (or halves where resampled strengths tie): the interval's ends are ranks
                # that occurred, the lower percentile rounded down and the upper one up.
                "rank_low": float(math.floor(np.percentile(r[:, k], lo_q))) if len(r) else float(point[c]),
                "rank_high": float(math.ceil(np.percentile(r[:, k], hi_q))) if len(r) else float(point[c]),
            }
        )
    table = pd.DataFrame(rows).sort_values(["elo", "condition"], ascending=[False, True], ignore_index=True)
    order = list(table["condition"])
    g = groups(
        order,
        dict(zip(table["condition"], table["rank_low"])),
        dict(zip(table["condition"], table["rank_high"])),
        tied_with_above(order, boot, conds, margin_elo),
    )
    table["group"] = table["condition"].map(g)
    # A group's ranks are the places its members take in the order (equal strengths share a mean rank, 3 for
    # places 2-4, and the range names the places).
    span = pd.Series(np.arange(1, len(table) + 1), index=table.index).groupby(table["group"]).agg(["min", "max"])
    table["rank_range"] = [_range(span.at[g_, "min"], span.at[g_, "max"]) for g_ in table["group"]]
    table["note"] = [(notes or {}).get(c, "") for c in table["condition"]]
    return table


def _range(lo, hi):
    lo, hi = int(math.floor(lo)), int(math.ceil(hi))
    return f"{lo}" if lo == hi else f"{lo}-{hi}"


def win_rates(pairs, conds):
    """Win rates [K, K] of row over column (ties counting half) and the Holm-adjusted sign-test p of each pair,
    from analysis.designs.pairwise.preference.pair_counts' table; NaN where two conditions never met."""
    idx = {c: k for k, c in enumerate(conds)}
    rate = np.full((len(conds), len(conds)), np.nan)
    p = np.full_like(rate, np.nan)
    for _, r in pairs.iterrows():
        a, b = idx[r["condition_a"]], idx[r["condition_b"]]
        n = float(r["n"])
        if n:
            rate[a, b] = (r["wins_a"] + r["ties"] / 2) / n
            rate[b, a] = 1 - rate[a, b]
        p[a, b] = p[b, a] = r["p_holm"]
    return rate, p


def split_half(tables, pairs, conds, fit, n_splits=200, seed=0, level=0.95):
    """How well the ranking replicates: raters split at random into two halves, `n_splits` times.

    Parameters
    ----------
    tables : ndarray
        Per rater count tables [R, P, 3] (analysis.designs.pairwise.preference._tables).
    pairs : ndarray
        The pairs [P, 2] of condition indices.
    conds : list of str
        The conditions.
    fit : callable
        fit(counts [B, P, 3]) -> list of {"strengths": {cond: value}} (preference.fit_bradley_terry).
    n_splits, seed, level
        The number of random splits, their seed, and the coverage of the interval.

    Returns
    -------
    dict
        tau_median, tau_low, tau_high (Kendall's tau between the two halves' strengths over the splits),
        same_order (the share of splits whose halves give the same strict order), n_splits, n_raters; None
        where there are fewer than 4 raters or 3 conditions.
    """
    n_r = tables.shape[0]
    if n_r < 4 or len(conds) < 3:
        return None
    rng = np.random.default_rng(seed)
    halves = []
    for _ in range(n_splits):
        perm = rng.permutation(n_r)
        a, b = perm[: n_r // 2], perm[n_r // 2 :]
        halves += [tables[a].sum(axis=0), tables[b].sum(axis=0)]
    fits = fit(np.stack(halves))
    s = np.array([[f["strengths"][c] for c in conds] for f in fits]).reshape(n_splits, 2, len(conds))
    taus = np.array([sps.kendalltau(x[0], x[1]).statistic for x in s])
    same = np.mean([np.array_equal(np.argsort(-x[0]), np.argsort(-x[1])) for x in s])
    taus = np.nan_to_num(taus, nan=0.0)  # a half with every strength equal has no order: it agrees with nothing
    return {
        "tau_median": float(np.median(taus)),
        "tau_low": float(np.percentile(taus, 100 * (1 - level) / 2)),
        "tau_high": float(np.percentile(taus, 100 * (1 + level) / 2)),
        "same_order": float(same),
        "n_splits": int(n_splits),
        "n_raters": int(n_r),
    }
