"""Statistics of a rating test as pure functions on DataFrames that return dicts or tables (pingouin style).

Every function takes the long table of ratings (one row per response) and the names of its columns, so the
same code serves ratings.csv, the NIST reference data and R's PlantGrowth in the tests. Plotting lives in
page/figures.py; file handling in data/load.py and report.py.

The cluster bootstrap of the means is in bootstrap.py, the mixed and ordinal models in rating_models.py.
"""

import functools
import math
from itertools import combinations

import numpy as np
import pandas as pd
from scipy import stats as sps

from moglow_eval.core.study import condition_order

NO_VARIANCE = "no variance (every rating is the same): test undefined"
NO_WITHIN_VARIANCE = "no variance within conditions (every condition's ratings are all the same): test undefined"
# scipy's studentized-range tail is a numerical integral: below ~1e-9 it loses its digits (R's ptukey too;
# both reach 0 or a floor far out), so smaller Tukey p-values are reported as an upper bound instead.
TUKEY_P_RESOLVED = 1e-9


# ---------------------------------------------------------------------------------------------- one-way ANOVA
def _group_moments(y, codes, k):
    """Group sizes, means and within-group sum of squares, numerically stable.

    The data are first shifted by one observation (removing the constant leading digits that defeat a naive
    sum of squares, NIST SmLs07-09), then a corrected two-pass algorithm: means, residuals, and a second-pass
    correction of each mean by the mean residual (Chan, Golub & LeVeque 1983). Sums are numpy's pairwise sums.
    """
    d = y - y[0]
    n = np.bincount(codes, minlength=k).astype(np.int64)
    means = np.bincount(codes, weights=d, minlength=k) / n
    r = d - means[codes]
    corr = np.bincount(codes, weights=r, minlength=k) / n
    means += corr
    r -= corr[codes]
    ss_within = float(np.dot(r, r))
    return n, means + y[0], means, ss_within  # shifted means kept for the between-groups sum


def one_way_anova(df, dv="rating", between="condition"):
    """One-way ANOVA of `dv` across the groups of `between`.

    Parameters
    ----------
    df : DataFrame
        One row per rating (or other observation).
    dv : str
        The column of the dependent variable.
    between : str
        The column naming each row's group (condition).

    Returns
    -------
    dict
        F, df_between, df_within, p, ss_between, ss_within, ms_between, ms_within, eta_squared, n and k (the
        number of groups). Where there is no variance within the groups, F and p are NaN and "undefined" says
        why (an x / 0 is no evidence of anything).

    Raises
    ------
    ValueError
        Fewer than 2 groups, or no more observations than groups.

    Notes
    -----
    A shifted, corrected two-pass algorithm keeps >= 9 significant digits on every NIST StRD ANOVA set that
    float64 can hold (tests/analysis/test_stats.py).

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.stats.anova import one_way_anova
    >>> df = pd.DataFrame({"condition": ["A"] * 3 + ["B"] * 3, "rating": [1, 2, 3, 3, 4, 5]})
    >>> r = one_way_anova(df)
    >>> r["F"], r["df_between"], r["df_within"], round(r["p"], 4)
    (6.0, 1, 4, 0.0705)
    """
    codes, levels = pd.factorize(df[between], sort=True)
    k = len(levels)
    if k < 2:
        raise ValueError(f"one-way ANOVA needs at least 2 groups in {between!r}, got {k}")
    if len(df) - k < 1:
        raise ValueError("one-way ANOVA needs more observations than groups")
    y = df[dv].to_numpy().astype(np.float64)
    n, _, means, ss_within = _group_moments(y, codes, k)
    grand = float(np.dot(n, means)) / int(n.sum())
    ss_between = float(np.dot(n, (means - grand) ** 2))
    return anova_table(int(n.sum()), k, ss_between, ss_within)


def anova_table(n, k, ss_between, ss_within):
    """The one-way ANOVA table from its sums of squares: F, p, mean squares and eta squared.

    The sums may be exact fractions; F is formed before rounding to float, so exact sums give an exact F.
    """
    df_b, df_w = k - 1, n - k
    F = float((ss_between / df_b) / (ss_within / df_w)) if ss_within > 0 else math.nan
    ssb, ssw = float(ss_between), float(ss_within)
    out = {
        "F": F,
        "df_between": df_b,
        "df_within": df_w,
        "p": float(sps.f.sf(F, df_b, df_w)) if ssw else math.nan,
        "ss_between": ssb,
        "ss_within": ssw,
        "ms_between": ssb / df_b,
        "ms_within": ssw / df_w,
        "eta_squared": ssb / (ssb + ssw) if ssb + ssw else math.nan,
        "n": n,
        "k": k,
    }
    if not ssw:
        # F = x / 0 is no evidence of anything: with no spread within conditions there is no error variance to
        # compare against (every rating identical, or one per condition), so the test is undefined, not p = 0.
        out["undefined"] = NO_VARIANCE if not ssb else NO_WITHIN_VARIANCE
    return out


# ---------------------------------------------------------------------------------------------- descriptives
def group_summary(df, dv="rating", between="condition", level=0.95):
    """Per group: n, mean, sd, sem and the t-based confidence interval of the mean (own-group variance). `between`:
    a column, or a list of columns for their cells (condition x style)."""
    g = df.groupby(between, sort=True)[dv]
    out = pd.DataFrame({"n": g.size(), "mean": g.mean(), "sd": g.std(ddof=1)})
    out["sem"] = out["sd"] / np.sqrt(out["n"])
    tcrit = sps.t.ppf(0.5 + level / 2, out["n"] - 1)
    out["t_low"] = out["mean"] - tcrit * out["sem"]
    out["t_high"] = out["mean"] + tcrit * out["sem"]
    if isinstance(between, str):
        out.index.name = between
    return out.loc[condition_order(out.index)] if between == "condition" else out


def rating_histogram(df, dv="rating", between="condition", scale=(1, 2, 3, 4, 5)):
    """Counts of each scale point per group (rows: groups, columns: scale points) — the paper's Fig. 5 data."""
    table = pd.crosstab(df[between], df[dv]).reindex(columns=list(scale), fill_value=0)
    table.columns.name = dv
    return table.loc[condition_order(table.index)] if between == "condition" else table


def per_clip_means(df, dv="rating", between="condition", clip="clip_id", level=0.95):
    """Mean rating of every clip, sorted worst to best within each condition (the paper's Fig. 6 data).

    Columns: clip, condition, n, mean, sd, ci_low, ci_high (t-based, per clip), rank (1 = worst in condition).
    """
    g = df.groupby(clip, sort=False, observed=True)
    out = pd.DataFrame({between: g[between].first(), "n": g.size(), "mean": g[dv].mean(), "sd": g[dv].std(ddof=1)})
    out.index = out.index.astype(str)
    sem = out["sd"] / np.sqrt(out["n"])
    with np.errstate(invalid="ignore"):
        tcrit = sps.t.ppf(0.5 + level / 2, out["n"] - 1)
    out["ci_low"] = out["mean"] - tcrit * sem
    out["ci_high"] = out["mean"] + tcrit * sem
    out = out.reset_index()
    order = {c: i for i, c in enumerate(condition_order(out[between]))}
    out["_o"] = out[between].map(order)
    out = out.sort_values(["_o", "mean", clip], kind="mergesort").drop(columns="_o")
    out["rank"] = out.groupby(between, sort=False).cumcount() + 1
    return out.reset_index(drop=True)


# ---------------------------------------------------------------------------------------------- Tukey HSD
def tukey_hsd(df, dv="rating", between="condition", alpha=0.05):
    """Tukey's HSD over all pairs of groups at family-wise error `alpha` (Tukey-Kramer for unequal group sizes).

    Parameters
    ----------
    df : DataFrame
        One row per rating (or other observation).
    dv : str
        The column of the dependent variable.
    between : str
        The column naming each row's group (condition).
    alpha : float
        The family-wise error rate: the intervals cover 1 - alpha, and a pair is rejected where p_adj < alpha.

    Returns
    -------
    DataFrame
        One row per pair, in statsmodels' convention: group1 < group2 alphabetically, meandiff = mean(group2) -
        mean(group1). Columns group1, group2, meandiff, lower, upper, p_adj, p_adj_bound, reject, se, q.
        p_adj_bound is True where the tail is below what scipy resolves (1e-9) and p_adj is an upper bound
        instead. Without error variance a pair has no test (NaN, never rejected) and attrs["undefined"] says why.

    Raises
    ------
    ValueError
        Fewer than 2 groups, or no more observations than groups.

    Notes
    -----
    The pooled MSE is the one-way ANOVA's; the studentized range quantile and tail come from scipy (the same
    distribution as R's qtukey/ptukey).

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.stats.anova import tukey_hsd
    >>> df = pd.DataFrame({"condition": ["A"] * 3 + ["B"] * 3, "rating": [1, 2, 3, 3, 4, 5]})
    >>> row = tukey_hsd(df).iloc[0]
    >>> row["group1"], row["group2"], float(row["meandiff"]), round(float(row["p_adj"]), 4), bool(row["reject"])
    ('A', 'B', 2.0, 0.0705, False)
    """
    codes, levels = pd.factorize(df[between], sort=True)
    k = len(levels)
    y = df[dv].to_numpy(dtype=np.float64)
    n, means, _, ssw = _group_moments(y, codes, k)
    df_w = int(n.sum()) - k
    if k < 2 or df_w < 1:
        raise ValueError("Tukey HSD needs at least 2 groups and more observations than groups")
    mse = ssw / df_w
    qcrit = tukey_qcrit(alpha, k, df_w)
    rows = []
    for i, j in combinations(range(k), 2):
        diff = means[j] - means[i]
        se = math.sqrt(mse / 2 * (1 / n[i] + 1 / n[j]))
        if not se > 0:  # no error variance: no test (never "reject" on a 0 / 0 or x / 0)
            rows.append(
                {
                    "group1": levels[i],
                    "group2": levels[j],
                    "meandiff": float(diff),
                    "lower": math.nan,
                    "upper": math.nan,
                    "p_adj": math.nan,
                    "p_adj_bound": False,
                    "reject": False,
                    "se": se,
                    "q": math.nan,
                }
            )
            continue
        q = abs(diff) / se
        p, bound = tukey_p(q, k, df_w)
        rows.append(
            {
                "group1": levels[i],
                "group2": levels[j],
                "meandiff": float(diff),
                "lower": float(diff - qcrit * se),
                "upper": float(diff + qcrit * se),
                "p_adj": p,
                "p_adj_bound": bound,
                "reject": bool(p < alpha),
                "se": se,
                "q": q,
            }
        )
    out = pd.DataFrame(rows)
    out.attrs["undefined"] = (NO_VARIANCE if np.ptp(y) == 0 else NO_WITHIN_VARIANCE) if not mse > 0 else None
    return out


@functools.lru_cache(maxsize=256)
def tukey_qcrit(alpha, k, df):
    """Studentized-range quantile, cached: scipy inverts a numerical integral (~0.1 s), and simulations
    (analysis.plan's validation, bootstrap-style checks) ask for the same (alpha, k, df) many times."""
    return float(sps.studentized_range.ppf(1 - alpha, k, df))


def tukey_p(q, k, df):
    """Tail P(Q_k,df > q) -> (p, is_bound). Where the numerical tail falls below TUKEY_P_RESOLVED its digits
    are noise, so it returns an upper bound instead: the union bound over the k(k-1)/2 pairs,
    P(Q > q) <= C(k, 2) P(|T_df| > q / sqrt 2) (rigorous, and within 1% of the tail from 1e-7 down), capped
    at TUKEY_P_RESOLVED and rounded up to one significant digit for printing."""
    p = float(sps.studentized_range.sf(q, k, df))
    if p >= TUKEY_P_RESOLVED:
        return min(p, 1.0), False
    union = k * (k - 1) * float(sps.t.sf(q / math.sqrt(2), df))
    bound = min(TUKEY_P_RESOLVED, union)
    if bound > 0:
        exp = math.floor(math.log10(bound))
        bound = math.ceil(bound / 10**exp) * 10.0**exp
    else:
        bound = 1e-300  # below the smallest double the t tail can give
    return bound, True


# ---------------------------------------------------------------------------------------------- rank tests
def holm(pvalues):
    """Holm step-down adjusted p-values (same order as the input)."""
    p = np.asarray(pvalues, dtype=float)
    m = len(p)
    if m == 0:
        return p
    order = np.argsort(p, kind="mergesort")
    adj = np.minimum(1.0, np.maximum.accumulate((m - np.arange(m)) * p[order]))
    out = np.empty(m)
    out[order] = adj
    return out


def kruskal_wallis(df, dv="rating", between="condition"):
    """Kruskal-Wallis H test (tie-corrected) of `dv` across the groups of `between`.

    Parameters
    ----------
    df : DataFrame
        One row per rating (or other observation).
    dv : str
        The column of the dependent variable.
    between : str
        The column naming each row's group (condition).

    Returns
    -------
    dict
        H, df, p and epsilon_squared (H / (n - 1)). Where every value is tied, H, p and epsilon_squared are NaN
        and "undefined" says why.

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.stats.anova import kruskal_wallis
    >>> df = pd.DataFrame({"condition": ["A"] * 3 + ["B"] * 3, "rating": [1, 2, 3, 3, 4, 5]})
    >>> r = kruskal_wallis(df)
    >>> r["df"], round(r["H"], 2), round(r["p"], 3)
    (1, 3.14, 0.077)
    """
    groups = [g.to_numpy() for _, g in df.groupby(between, sort=True)[dv]]
    n = sum(len(g) for g in groups)
    if np.ptp(np.concatenate(groups)) == 0:  # every rank tied: H is 0 / 0
        return {
            "H": math.nan,
            "df": len(groups) - 1,
            "p": math.nan,
            "epsilon_squared": math.nan,
            "undefined": NO_VARIANCE,
        }
    h, p = sps.kruskal(*groups)
    return {"H": float(h), "df": len(groups) - 1, "p": float(p), "epsilon_squared": float(h / (n - 1))}


def pairwise_mannwhitney(df, dv="rating", between="condition", alpha=0.05):
    """Two-sided Mann-Whitney U for every pair (normal approximation with tie and continuity correction, as
    R's wilcox.test with ties), Holm-adjusted over the family.

    group1 < group2 alphabetically like tukey_hsd; U is group2's statistic, so cles = P(group2 > group1) +
    P(tie)/2 and rank_biserial = 2 cles - 1 (positive: group2 rated higher).
    """
    by = {name: g.to_numpy() for name, g in df.groupby(between, sort=True)[dv]}
    names = sorted(by)
    rows = []
    for a, b in combinations(names, 2):
        res = sps.mannwhitneyu(by[b], by[a], alternative="two-sided", method="asymptotic", use_continuity=True)
        cles = float(res.statistic) / (len(by[a]) * len(by[b]))
        # all ratings of the pair tied: the normal approximation has zero variance, no test
        tied = np.ptp(np.concatenate([by[a], by[b]])) == 0
        rows.append(
            {
                "group1": a,
                "group2": b,
                "U": float(res.statistic),
                "p": math.nan if tied else float(res.pvalue),
                "cles": cles,
                "rank_biserial": 2 * cles - 1,
            }
        )
    out = pd.DataFrame(rows)
    p = out["p"].to_numpy()
    ok = np.isfinite(p)
    out["p_holm"] = np.nan
    out.loc[ok, "p_holm"] = holm(p[ok])  # the family is the pairs that have a test
    out["reject"] = out["p_holm"] < alpha
    return out


# ---------------------------------------------------------------------------------------------- objective metrics
def metric_correlations(clip_means, metrics, between="condition"):
    """Correlation of each per-clip objective metric with the per-clip mean rating.

    clip_means: per_clip_means() table; metrics: DataFrame indexed by clip id, one column per metric.
    Rows per metric: scope "all" (every rated clip with that metric) and one per condition. Columns: metric,
    scope, n, pearson_r, pearson_p, spearman_rho, spearman_p.
    """
    merged = clip_means.set_index(clip_means.columns[0]).join(metrics, how="inner")
    rows = []
    for metric in metrics.columns:
        scopes = [("all", merged)] + [
            (c, merged[merged[between] == c]) for c in condition_order(merged[between].unique())
        ]
        for scope, part in scopes:
            part = part[np.isfinite(part[metric])]
            row = {
                "metric": metric,
                "scope": scope,
                "n": int(len(part)),
                "pearson_r": math.nan,
                "pearson_p": math.nan,
                "spearman_rho": math.nan,
                "spearman_p": math.nan,
            }
            if len(part) >= 3 and part[metric].std() > 0 and part["mean"].std() > 0:
                r = sps.pearsonr(part[metric], part["mean"])
                s = sps.spearmanr(part[metric], part["mean"])
                row.update(
                    pearson_r=float(r.statistic),
                    pearson_p=float(r.pvalue),
                    spearman_rho=float(s.statistic),
                    spearman_p=float(s.pvalue),
                )
            rows.append(row)
    return pd.DataFrame(rows)
