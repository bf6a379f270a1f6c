"""Statistics of a parallel (MUSHRA-like) test: the ratings.csv of CONTRACTS §8, with page_id and 0..100 ratings.

A page shows every condition of one item, so the natural comparison is within a page: for each pair of
conditions, the Wilcoxon signed-rank test on the page-paired ratings (pages holding both), Holm-corrected over
the pairs. Per condition: mean and median with 95% percentile intervals from a bootstrap over raters (a rater's
pages resampled together), and the linear mixed model rating ~ condition + (1|rater) + (1|item) of analysis.stats.anova
(REML, Satterthwaite t tests). A catch page is failed by rating a BAD clip at or above the page's NAT clip.
"""

import math
from itertools import combinations

import numpy as np
import pandas as pd
from scipy import stats as sps

from moglow_eval.core import study

from ...data.load import AnalysisError, read_export

REQUIRED = ("rater_id", "page_id", "item", "clip_id", "condition", "rating", "role")
ROLES = ("test", "catch")
BAD, REFERENCE = study.CATCH, study.NATURAL


def load_pages(path):
    """The parallel ratings.csv -> DataFrame (index = file line). Each problem is one AnalysisError naming the
    file and line: missing columns, empty fields, a rating that is not an integer 0..100, an unknown role, a page
    shared by two raters or two items, a clip or a condition twice on one page, a clip rated twice by one rater,
    no test rows."""
    path, df = read_export(path, REQUIRED, "ratings", strip=True)
    text = df["rating"]
    ok = text.str.fullmatch(r"\+?\d{1,3}") & text.str.isascii()
    values = pd.to_numeric(text.where(ok), errors="coerce")
    bad = ~ok | (values < 0) | (values > 100)
    if bad.any():
        line = bad.idxmax()
        raise AnalysisError(f"{path}:{line}: rating {df.at[line, 'rating']!r} is not an integer 0-100")
    df["rating"] = values.astype(int)
    df["role"] = df["role"].str.lower()
    bad_role = ~df["role"].isin(ROLES)
    if bad_role.any():
        line = bad_role.idxmax()
        raise AnalysisError(f"{path}:{line}: unknown role {df.at[line, 'role']!r} (expected test or catch)")
    for col in ("rater_id", "item", "role"):
        first = df.groupby("page_id", sort=False)[col].transform("first")
        clash = df[col] != first
        if clash.any():
            line = clash.idxmax()
            earlier = df.index[(df["page_id"] == df.at[line, "page_id"])][0]
            raise AnalysisError(
                f"{path}:{line}: page {df.at[line, 'page_id']} has {col} {df.at[line, col]!r} but "
                f"{first[line]!r} at line {earlier}"
            )
    for cols, what in (
        (["page_id", "clip_id"], "clip {clip_id} twice on page {page_id}"),
        (["page_id", "condition"], "condition {condition} twice on page {page_id}"),
        (["rater_id", "clip_id"], "clip {clip_id} rated twice by rater {rater_id}"),
    ):
        dup = df.duplicated(cols)
        if dup.any():
            line = dup.idxmax()
            first = df.index[(df[cols] == df.loc[line, cols]).all(axis=1)][0]
            raise AnalysisError(
                f"{path}:{line}: " + what.format(**df.loc[line, cols].to_dict()) + f" (first at line {first})"
            )
    if not (df["role"] == "test").any():
        raise AnalysisError(f"{path}: no test ratings (every row is a catch page)")
    return df


def failed_raters(df):
    """Raters excluded (study.excluded_raters) for rating a BAD clip at or above the NAT clip of its catch page."""
    c = df[df["role"] == "catch"]
    wide = c.pivot_table(
        index=["rater_id", "page_id"], columns="condition", values="rating", aggfunc="max", observed=True
    )
    if BAD not in wide.columns or REFERENCE not in wide.columns:
        return []
    fail = study.page_catch_failed(wide[BAD], wide[REFERENCE]).fillna(False)
    return study.excluded_raters(zip(wide.index.get_level_values("rater_id").tolist(), fail.tolist()))


def condition_summary(t, n_boot=1000, seed=0, level=0.95):
    """Per condition: n, mean, median and their percentile intervals from a bootstrap over raters."""
    conds = sorted(t["condition"].unique())
    raters, codes = np.unique(t["rater_id"].to_numpy(), return_inverse=True)
    rng = np.random.default_rng(seed)
    y = t["rating"].to_numpy(float)
    cond = t["condition"].to_numpy()
    by = {c: [y[(cond == c) & (codes == r)] for r in range(len(raters))] for c in conds}
    boot_mean = np.full((n_boot, len(conds)), np.nan)
    boot_med = np.full((n_boot, len(conds)), np.nan)
    for b in range(n_boot):
        pick = rng.integers(0, len(raters), len(raters))
        for k, c in enumerate(conds):
            v = np.concatenate([by[c][r] for r in pick])
            if len(v):
                boot_mean[b, k], boot_med[b, k] = v.mean(), np.median(v)
    lo, hi = 100 * (1 - level) / 2, 100 * (1 + level) / 2
    rows = []
    for k, c in enumerate(conds):
        v = y[cond == c]
        rows.append(
            {
                "condition": c,
                "n": int(len(v)),
                "mean": float(v.mean()),
                "median": float(np.median(v)),
                "sd": float(v.std(ddof=1)) if len(v) > 1 else math.nan,
                "mean_low": float(np.nanpercentile(boot_mean[:, k], lo)),
                "mean_high": float(np.nanpercentile(boot_mean[:, k], hi)),
                "median_low": float(np.nanpercentile(boot_med[:, k], lo)),
                "median_high": float(np.nanpercentile(boot_med[:, k], hi)),
            }
        )
    return pd.DataFrame(rows).set_index("condition")


def paired(t, a, b):
    """(ratings of a, ratings of b) on the pages that hold both, page by page."""
    wide = t.pivot_table(index="page_id", columns="condition", values="rating", aggfunc="first", observed=True)
    both = wide[[a, b]].dropna()
    return both[a].to_numpy(float), both[b].to_numpy(float)


def wilcoxon_pairs(t, alpha=0.05):
    """Wilcoxon signed-rank test (two-sided; zero differences dropped, as scipy's default) for every pair of
    conditions on page-paired ratings; Holm-corrected. group1 < group2 alphabetically; median_diff = median of
    group2 - group1 over the pages."""
    from ...stats.anova import holm

    rows = []
    for a, b in combinations(sorted(t["condition"].unique()), 2):
        x, y = paired(t, a, b)
        d = y - x
        if len(d) and np.any(d != 0):
            res = sps.wilcoxon(x, y)
            stat, p = float(res.statistic), float(res.pvalue)
        else:
            stat, p = math.nan, math.nan
        rows.append(
            {
                "group1": a,
                "group2": b,
                "n_pages": int(len(d)),
                "median_diff": float(np.median(d)) if len(d) else math.nan,
                "statistic": stat,
                "p": p,
            }
        )
    out = pd.DataFrame(rows)
    out["p_holm"] = np.nan
    ok = out["p"].notna().to_numpy()
    if ok.any():
        out.loc[ok, "p_holm"] = holm(out.loc[ok, "p"].to_numpy())
    out["reject"] = out["p_holm"] < alpha
    return out


def analyse(df, n_boot=1000, seed=0, alpha=0.05, mixed=True):
    """All parallel statistics of the test rows of `df` (catch pages never enter them)."""
    from ...stats import rating_models

    t = df[df["role"] == "test"]
    if t["condition"].nunique() < 2:
        raise AnalysisError(f"the test rows hold {t['condition'].nunique()} condition; comparisons need at least 2")
    out = {
        "n_test_ratings": int(len(t)),
        "n_raters": int(t["rater_id"].nunique()),
        "n_pages": int(t["page_id"].nunique()),
        "n_items": int(t["item"].nunique()),
        "summary": condition_summary(t, n_boot=n_boot, seed=seed),
        "wilcoxon": wilcoxon_pairs(t, alpha),
    }
    if not mixed:
        out["mixed"] = {"skipped": "--no-mixed", "fixed_effects": {}}
        return out
    try:
        out["mixed"] = rating_models.mixed_model(t, clip="item")
    except rating_models.ModelUndefined as exc:
        out["mixed"] = {"undefined": str(exc), "fixed_effects": {}}
    except (np.linalg.LinAlgError, ValueError) as exc:
        out["mixed"] = {"error": f"{type(exc).__name__}: {exc}".splitlines()[0], "fixed_effects": {}}
    return out
