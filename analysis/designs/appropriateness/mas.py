"""Statistics of an appropriateness test (GENEA 2023; Kucherenko et al. 2023): does a system's motion fit its speech?

Each test answer compares two clips of one system with the same item's speech: the motion the system made for
that speech (matched) and the motion it made for another item's (mismatched, cut to the same length). The rater
picks the one that fits the speech better on 5 levels: `preference` 2 = A clearly, 1 = A slightly, 0 = no
preference, -1 / -2 = B. Seen from the matched clip, that is a score of +2 (matched clearly) .. -2 (mismatched
clearly), and per system:
- MAS, the mean appropriateness score: the mean of those scores, 0 at chance, with its 95% Student-t interval
  over answers (GENEA 2023 reports MAS with 95% confidence intervals);
- the share of answers preferring the matched clip, of ties, and preferring the mismatched one, and the percent
  matched with ties split equally between the sides;
- a two-sided sign test of matched against mismatched preferences (ties dropped), Holm-corrected over systems:
  whether the system does better than chance.

Catch answers (a pair of a catch item's NAT clip and its broken BAD clip) exclude a rater who prefers BAD, as
in the pairwise design.
"""

import math

import numpy as np
import pandas as pd
from scipy import stats as sps

from moglow_eval.core import study

from ...data.load import AnalysisError
from ...stats.anova import holm
from ..pairwise.preference import REQUIRED, read_preferences  # a preference export, read and excluded as pairwise

MATCHED = "matched"  # a or b on test rows (the side showing the motion made for this speech); empty on catch rows


def load_answers(path):
    """The appropriateness export -> DataFrame with a `score` column (+2..-2 seen from the matched clip; NaN on
    catch rows). One AnalysisError naming the file and line for a bad preference, role or matched side."""
    path, df = read_preferences(path, REQUIRED)
    if MATCHED not in df.columns:
        raise AnalysisError(f"{path}:1: missing column {MATCHED} (an appropriateness export names the matched side)")
    test = df["role"] == "test"
    side = df[MATCHED].fillna("").str.strip().str.lower()
    bad = test & ~side.isin(["a", "b"])
    if bad.any():
        raise AnalysisError(f"{path}:{bad.idxmax()}: a test answer's matched side must be a or b")
    bad = test & (df["condition_a"] != df["condition_b"])
    if bad.any():
        raise AnalysisError(f"{path}:{bad.idxmax()}: a test pair shows one system twice, not two")
    if not test.any():
        raise AnalysisError(f"{path}: no test answers (every row is a catch trial)")
    df["score"] = np.where(test, np.where(side == "a", df["preference"], -df["preference"]), np.nan)
    return df


def mas_table(df, alpha=0.05):
    """Per system (the condition of the test pairs): n, MAS with its Student-t interval, the shares of matched,
    tied and mismatched preferences, percent matched (ties halved), and the sign test against chance (p and
    Holm-adjusted p)."""
    t = df[df["role"] == "test"]
    rows = []
    for cond in study.condition_order(t["condition_a"].unique()):
        s = t.loc[t["condition_a"] == cond, "score"].to_numpy(float)
        n = len(s)
        mean, sd = float(s.mean()), float(s.std(ddof=1)) if n > 1 else math.nan
        half = float(sps.t.ppf(1 - alpha / 2, n - 1) * sd / math.sqrt(n)) if n > 1 else math.nan
        pos, tie, neg = int((s > 0).sum()), int((s == 0).sum()), int((s < 0).sum())
        p = float(sps.binomtest(pos, pos + neg, 0.5).pvalue) if pos + neg else 1.0
        rows.append(
            dict(
                condition=cond,
                n=n,
                mas=mean,
                ci_low=mean - half,
                ci_high=mean + half,
                matched=pos / n,
                tie=tie / n,
                mismatched=neg / n,
                percent_matched=100 * (pos + tie / 2) / n,
                p=p,
            )
        )
    table = pd.DataFrame(rows)
    table["p_holm"] = holm(table["p"].to_numpy())
    return table


def analyse(df, alpha=0.05):
    """{"mas": table, "n_test_answers", "n_raters", "n_items"} of the test answers of `df`."""
    t = df[df["role"] == "test"]
    return dict(
        mas=mas_table(df, alpha),
        n_test_answers=int(len(t)),
        n_raters=int(t["rater_id"].nunique()),
        n_items=int(t["item"].nunique()),
    )
