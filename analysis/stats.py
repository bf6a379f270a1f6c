"""Statistics of a rating test as pure functions on DataFrames that return dicts or tables (pingouin style).

Every function takes the long table of ratings (one row per response) and the names of its columns, so the
same code serves ratings.csv, the NIST reference data and R's PlantGrowth in the tests. Plotting lives in
figures.py; file handling in load.py and report.py.

At about 600 lines it is longer than the house's 400: it is one concept (the tests of ratings on a scale, which
acr's report (designs/acr.py) and the power planner run), each function short and standing alone; the two fitting
engines it calls are already modules of their own (mixed.py, ordinal.py).
"""

import functools
import math
from itertools import combinations

import numpy as np
import pandas as pd
from scipy import sparse
from scipy import stats as sps

from moglow_eval.core import study
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
    """One-way ANOVA -> dict(F, df_between, df_within, p, ss_between, ss_within, ms_between, ms_within,
    eta_squared, n, k).

    A shifted, corrected two-pass algorithm keeps >= 9 significant digits on every NIST StRD ANOVA set that
    float64 can hold (tests/test_analysis_stats.py).
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
    """Per group: n, mean, sd, sem and the t-based confidence interval of the mean (own-group variance)."""
    g = df.groupby(between, sort=True)[dv]
    out = pd.DataFrame({"n": g.size(), "mean": g.mean(), "sd": g.std(ddof=1)})
    out["sem"] = out["sd"] / np.sqrt(out["n"])
    tcrit = sps.t.ppf(0.5 + level / 2, out["n"] - 1)
    out["t_low"] = out["mean"] - tcrit * out["sem"]
    out["t_high"] = out["mean"] + tcrit * out["sem"]
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
    """Tukey HSD (Tukey-Kramer for unequal n) over all pairs at family-wise error alpha.

    statsmodels convention: group1 < group2 alphabetically, meandiff = mean(group2) - mean(group1).
    Columns: group1, group2, meandiff, lower, upper, p_adj, reject, se, q. Pooled MSE from the one-way ANOVA;
    studentized range quantile and tail from scipy (the same distribution as R's qtukey/ptukey).
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
    """Kruskal-Wallis H test (tie-corrected) -> dict(H, df, p, epsilon_squared)."""
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


# ---------------------------------------------------------------------------------------------- bootstrap
def _resample_counts(rng, n_boot, size, dtype=np.float64):
    """n_boot rows of multiplicities of drawing `size` items with replacement from `size` items."""
    idx = rng.integers(0, size, size=(n_boot, size), dtype=np.int32 if size < 2**31 else np.int64)
    out = np.empty((n_boot, size), dtype=dtype)
    for b in range(n_boot):  # row-wise bincount: cache-friendly and no offset array (2x faster than one flat pass)
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
    """Two-way cluster bootstrap of the group means: raters resampled with replacement, and clips resampled
    with replacement within their condition (clips are nested in conditions, raters are crossed with them).

    A replicate weights each rating by (times its rater was drawn) x (times its clip was drawn); a group
    mean is sum(w y) / sum(w). Vectorised: with the rater x clip table S of ratings, the weighted sums of all
    replicates are ((W_rater @ S) * W_clip) @ onehot(condition) — one matrix product per chunk of
    replicates (dense for tables up to `dense_limit` cells, sparse beyond), 100 replicates at a time so memory
    stays bounded. Integer weights and ratings keep every sum exact, so results are bit-reproducible for a
    seed and identical on both paths.

    -> {"means": DataFrame per group (mean, boot_low, boot_high, boot_se), "differences": DataFrame per pair
        (group1 < group2, meandiff = group2 - group1, boot_low, boot_high, boot_p = two-sided bootstrap
        p-value, add-one), "n_boot", "seed", "level", "n_degenerate"}.
    """
    rc, raters = pd.factorize(df[rater])
    cc, clips = pd.factorize(df[clip])
    cond_codes, conds = pd.factorize(df[between], sort=True)
    R, C, K = len(raters), len(clips), len(conds)
    y = df[dv].to_numpy(dtype=np.float64)
    clip_cond = np.zeros(C, dtype=np.int64)
    clip_cond[cc] = cond_codes
    onehot = np.zeros((C, K))
    onehot[np.arange(C), clip_cond] = 1.0
    members = [np.flatnonzero(clip_cond == k) for k in range(K)]
    # float32 products are exact while every per-clip sum of (rater weight x rating) stays below 2**24
    # (weights of one replicate sum to R); twice as fast as float64 in both the BLAS and the sparse kernels.
    exact32 = bool(np.all(y == np.rint(y))) and R * max(1.0, float(np.abs(y).max())) < 2**24
    dtype = np.float32 if exact32 else np.float64
    nnz = len(y)
    use_dense = R * C <= min(dense_limit, 20 * nnz)  # BLAS on the full table beats the sparse kernel up to ~20x
    if use_dense:
        SN = np.zeros((R, 2 * C), dtype=dtype)  # ratings and counts side by side: one product per chunk
        SN[rc, cc] = y
        SN[rc, C + cc] = 1.0
    else:
        SN = (
            sparse.vstack(
                [
                    sparse.csr_matrix((y, (cc, rc)), shape=(C, R)),
                    sparse.csr_matrix((np.ones_like(y), (cc, rc)), shape=(C, R)),
                ]
            )
            .tocsr()
            .astype(dtype)
        )
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
        boot = num / den
    degenerate = int(np.isnan(boot).any(axis=1).sum())
    lo, hi = 50 * (1 - level), 50 * (1 + level)
    full = pd.Series(y).groupby(cond_codes).mean().to_numpy()
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
    for i, j in combinations(range(K), 2):
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
    return {
        "means": means,
        "differences": pd.DataFrame(rows),
        "n_boot": n_boot,
        "seed": seed,
        "level": level,
        "n_degenerate": degenerate,
        "method": "two-way cluster bootstrap (raters; clips within condition), percentile intervals",
    }


# ---------------------------------------------------------------------------------------------- mixed model
class ModelUndefined(ValueError):
    """The data cannot identify the model (a statement for the report, not a failure)."""


def random_effects_problem(df, dv="rating", between="condition", rater="rater_id", clip="clip_id"):
    """Why  dv ~ between + (1|rater) + (1|clip)  cannot be fitted on these rows, or None. Each case would
    otherwise give numbers that look like results: a 0/0 residual variance, a rater variance from one rater,
    or a clip variance that is the condition effect itself (one clip per condition)."""
    if df[dv].nunique() < 2:
        return "no variance (every rating is the same): model undefined"
    if df[rater].nunique() < 2:
        return "a single rater: the rater variance cannot be estimated; model not fitted"
    if df.groupby(between, observed=True)[clip].nunique().max() < 2:
        return "one clip per condition: the clip variance is confounded with the condition; model not fitted"
    if df.groupby(between, observed=True)[dv].nunique().max() < 2:
        return "no variance within conditions (every condition's ratings are all the same): model undefined"
    return None


def mixed_model(df, dv="rating", between="condition", rater="rater_id", clip="clip_id", reference=None):
    """Linear mixed model  dv ~ between + (1|rater) + (1|clip)  with crossed random intercepts, REML
    (analysis/mixed.py: lme4's profiled criterion from sufficient statistics; checked against statsmodels
    MixedLM in the tests). Treatment coding; the reference level is NAT when present (effects read as "vs
    natural motion"), else the first level alphabetically. Wald z tests and 95% intervals for fixed effects.

    -> dict: formula, method, reference, fixed_effects {Intercept, condition[T.X]: estimate}, std_errors,
    z, p_values, ci_low, ci_high, variance_components {rater, clip, residual}, condition_means (model-based),
    reml_log_likelihood, converged, n, n_raters, n_clips.
    """
    from .mixed import fit_crossed

    problem = random_effects_problem(df, dv, between, rater, clip)
    if problem:
        raise ModelUndefined(problem)
    levels = sorted(df[between].unique())
    if reference is None:
        reference = study.NATURAL if study.NATURAL in levels else levels[0]
    others = [c for c in levels if c != reference]
    cond = df[between].to_numpy()
    X = np.column_stack([np.ones(len(df))] + [(cond == c).astype(float) for c in others])
    names = ["Intercept"] + [f"{between}[T.{c}]" for c in others]
    rater_codes = pd.factorize(df[rater])[0]
    clip_codes = pd.factorize(df[clip])[0]
    fit = fit_crossed(df[dv].to_numpy(dtype=float), X, rater_codes, clip_codes, names)
    fe = fit["fixed_effects"]
    means = {reference: fe["Intercept"], **{c: fe["Intercept"] + fe[f"{between}[T.{c}]"] for c in others}}
    return {
        "formula": f"{dv} ~ {between} + (1|{rater}) + (1|{clip})",
        "method": "REML, crossed random intercepts (profiled criterion, L-BFGS-B then Nelder-Mead polish); "
        "t tests on Satterthwaite df",
        "reference": reference,
        **fit,
        "condition_means": {c: means[c] for c in condition_order(means)},
        "n": int(len(df)),
        "n_raters": int(rater_codes.max() + 1),
        "n_clips": int(clip_codes.max() + 1),
        "warnings": [] if fit["converged"] else ["optimiser did not report convergence"],
    }


# ---------------------------------------------------------------------------------------------- ordinal model
def ordinal_model(df, dv="rating", between="condition", rater="rater_id", clip="clip_id", reference=None, level=0.95):
    """Cumulative-link (logit) mixed model  factor(dv) ~ between + (1|rater) + (1|clip), ML with the Laplace
    approximation as R's ordinal::clmm (analysis/ordinal.py; matched to clmm in the tests).

    Effects are log-odds of a higher rating against the reference (NAT when present), so exp(effect) is an
    odds ratio: 0.5 means half the odds of a rating above any cut point. Thresholds are named by adjacent
    observed levels ("1|2" ... "4|5" when every level occurs; an unused level has no cut point, as in clmm).

    -> dict: formula, method, reference, fixed_effects, std_errors, z, p_values (Wald), odds_ratios,
    or_ci_low, or_ci_high, thresholds, threshold_std_errors, sd_rater, sd_clip, log_likelihood, converged,
    fitted_distribution and observed_distribution {COND: {level: proportion}}, n, n_raters, n_clips, warnings.
    """
    from .ordinal import fit_clmm, marginal_probabilities

    problem = random_effects_problem(df, dv, between, rater, clip)
    if problem:
        raise ModelUndefined(problem)
    lo, hi = df[dv].min(), df[dv].max()
    for c, g in df.groupby(between, observed=True)[dv]:
        if g.nunique() == 1 and g.iloc[0] in (lo, hi):
            # the likelihood rises forever as that condition's effect runs to +-infinity: no estimate exists
            raise ModelUndefined(
                f"every rating of {c} is {g.iloc[0]}, the {'top' if g.iloc[0] == hi else 'bottom'} "
                "category: its effect is infinite (separation); model not fitted"
            )
    levels = sorted(df[between].unique())
    if reference is None:
        reference = study.NATURAL if study.NATURAL in levels else levels[0]
    others = [c for c in levels if c != reference]
    cond = df[between].to_numpy()
    X = np.column_stack([(cond == c).astype(float) for c in others])
    names = [f"{between}[T.{c}]" for c in others]
    y_codes, y_levels = pd.factorize(df[dv], sort=True)
    y_levels = [int(v) if float(v).is_integer() else v for v in y_levels]
    fit = fit_clmm(
        y_codes,
        X,
        pd.factorize(df[rater])[0],
        pd.factorize(df[clip])[0],
        names,
        len(y_levels),
        [str(v) for v in y_levels],
    )
    fit.pop("random_effects")
    b = np.array(list(fit["fixed_effects"].values()))
    se = np.array(list(fit["std_errors"].values()))
    th = np.array(list(fit["thresholds"].values()))
    if (
        np.any(np.abs(b) > 15)
        or max(fit["sd_rater"], fit["sd_clip"]) > 20
        or np.ptp(th) > 60
        or not np.all(np.isfinite(b))
    ):
        # the likelihood keeps rising as an effect, an SD or the cut points run off to infinity (quasi-separation:
        # some condition, rater or clip sits in an end category), so no estimate or interval means anything
        raise ModelUndefined(
            "estimates run off to infinity (quasi-separation: ratings of some condition, rater "
            "or clip sit in an end category); model not identified"
        )
    warnings = []
    if not fit["converged"]:
        warnings.append(f"optimiser did not converge (max |gradient| {fit['max_abs_gradient']:.2g})")
    if not np.all(np.isfinite(se)):
        warnings.append("the information matrix is singular: standard errors undefined")
    zq = sps.norm.ppf(0.5 + level / 2)
    eta = np.array([0.0] + list(b))
    probs = marginal_probabilities(th, eta, math.hypot(fit["sd_rater"], fit["sd_clip"]))
    order = [reference] + others
    observed = pd.crosstab(df[between], df[dv], normalize="index").reindex(columns=y_levels, fill_value=0.0)
    with np.errstate(over="ignore"):  # an unidentified effect's interval overflows to inf (JSON null), no warning
        ors = [np.exp(b).tolist(), np.exp(b - zq * se).tolist(), np.exp(b + zq * se).tolist()]
    return {
        "formula": f"{dv} ~ {between} + (1|{rater}) + (1|{clip})  (cumulative logit)",
        "method": "ML, Laplace approximation, crossed random intercepts (as ordinal::clmm)",
        "reference": reference,
        **fit,
        "odds_ratios": dict(zip(names, ors[0])),
        "or_ci_low": dict(zip(names, ors[1])),
        "or_ci_high": dict(zip(names, ors[2])),
        "fitted_distribution": {
            c: dict(zip(map(str, y_levels), probs[order.index(c)].tolist())) for c in condition_order(levels)
        },
        "observed_distribution": {
            c: {str(k): float(v) for k, v in observed.loc[c].items()} for c in condition_order(levels)
        },
        "n": int(len(df)),
        "n_raters": int(df[rater].nunique()),
        "n_clips": int(df[clip].nunique()),
        "warnings": warnings,
    }


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
