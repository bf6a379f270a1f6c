"""How far a stochastic system's ratings depend on which of its samples was shown (the export's sample columns,
CONTRACTS §4, §6): pure functions on the exported rows, returning tables.

Where the app drew a sample per rater and unit, an item's answers fall on several samples, and a nested
random-effects ANOVA (samples within items, per condition) separates the spread between samples from the raters'
noise: sigma_sample is the standard deviation of the samples' true scores around their item's. Where one sample
was drawn per item, samples and items coincide, and their spread is part of the items'. Either way the report's
intervals resample clips, and every sample is a clip of its own, so they include this variation.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

from moglow_eval.core.study import condition_order

SIDES = (("sample_a", "condition_a", 1), ("sample_b", "condition_b", -1))


def _text(col: pd.Series) -> pd.Series:
    """A sample column as text ("" for none), whichever type the CSV reader gave it."""
    return col.map(lambda v: "" if pd.isna(v) else (f"{v:g}" if isinstance(v, float) else str(v).strip()))


def _scores(rows, condition: str, sample: str, score) -> pd.DataFrame:
    """(condition, item, sample, score) of `rows`, the condition and the sample from the named columns."""
    return pd.DataFrame(
        {"condition": rows[condition], "item": rows["item"], "sample": _text(rows[sample]), "score": score}
    )


def sample_scores(df: pd.DataFrame) -> pd.DataFrame:
    """(condition, item, sample, score) of every test answer about a clip that names a sample: a rating (acr,
    parallel), or a preference seen from the sample's side (-2..2, the designs that compare two clips; where a
    system's matched clip is set against its mismatched one, the matched clip's sample and the preference for it).
    Empty where the export has no sample column."""
    test = df[df["role"] == "test"] if "role" in df else df
    parts = []
    if "sample" in test and "rating" in test:
        parts.append(_scores(test, "condition", "sample", test["rating"].astype(float)))
    for col, cond, sign in SIDES:
        if col in test and "preference" in test:
            # a system against itself, matched against mismatched: the matched side's sample
            side = test[test["matched"] == col[-1]] if "matched" in test else test
            parts.append(_scores(side, cond, col, sign * side["preference"].astype(float)))
    if not parts:
        return pd.DataFrame(columns=["condition", "item", "sample", "score"])
    out = pd.concat(parts, ignore_index=True)
    return out[out["sample"] != ""].reset_index(drop=True)


def sample_spread(scores: pd.DataFrame) -> pd.DataFrame:
    """Per condition with samples: its items, samples per item, answers, the mean score, the samples' spread
    (`sample_range`: the mean over items of the highest sample mean less the lowest) and the nested ANOVA's
    `sigma_sample` with its F test (`F`, `df_samples`, `df_within`, `p`; NaN where one sample per item was
    shown)."""
    rows = []
    for cond, d in scores.groupby("condition", sort=False):
        g = d.groupby(["item", "sample"])["score"].agg(["count", "mean", "var"]).reset_index()
        per_item = g.groupby("item")
        k = per_item.size()
        n_total, n_groups = int(g["count"].sum()), len(g)
        item_mean = d.groupby("item")["score"].mean()
        ss_b = float((g["count"] * (g["mean"] - g["item"].map(item_mean)) ** 2).sum())
        ss_w = float(((g["count"] - 1) * g["var"].fillna(0.0)).sum())
        df_b, df_w = int((k - 1).sum()), n_total - n_groups
        f = p = sigma = np.nan
        if df_b > 0 and df_w > 0:
            ms_b, ms_w = ss_b / df_b, ss_w / df_w
            sq = (g["count"] ** 2).groupby(g["item"]).sum() / g.groupby("item")["count"].sum()
            n0 = (n_total - float(sq.sum())) / df_b  # the mean group size of an unbalanced nested design
            sigma = float(np.sqrt(max(0.0, (ms_b - ms_w) / n0)))
            if ms_w > 0:
                f = ms_b / ms_w
                p = float(stats.f.sf(f, df_b, df_w))
        spread = per_item["mean"].agg(lambda m: m.max() - m.min())
        rows.append(
            {
                "condition": cond,
                "items": int(len(k)),
                "samples_per_item": int(k.max()),
                "clips": n_groups,
                "answers": n_total,
                "mean": float(d["score"].mean()),
                "sample_range": float(spread[k > 1].mean()) if (k > 1).any() else np.nan,
                "sigma_sample": sigma,
                "F": f,
                "df_samples": df_b,
                "df_within": df_w,
                "p": p,
            }
        )
    out = pd.DataFrame(rows)
    if out.empty:
        return out
    order = condition_order(out["condition"].tolist())
    return out.set_index("condition").loc[order].reset_index()
