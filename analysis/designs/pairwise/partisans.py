"""Raters whose votes favour one condition far beyond the crowd's (for example a system's submitter who votes for it
whenever it is shown, and "no preference" elsewhere, passes every catch trial and can move the ranking).

**The rule.** For each rater r and condition c with at least MIN_VOTES of r's test votes on pairs with c: c's share
of those votes (a win 1, a tie 1/2) against the share the other raters gave c in the same pairs of conditions
(each of r's votes expected to go as the rest of the crowd's votes on that pair went, so a rater shown c against
weak systems is not flagged for c winning there). With n votes and expected shares p_i,

    z = (observed - sum p_i) / sqrt(sum p_i (1 - p_i) + n / 12),

the n / 12 standing in for the spread a tie adds, and for p_i of 0 or 1. The rater is flagged for c when z is at
least the one-sided normal quantile of 1 - ALPHA / (raters x conditions) (a Bonferroni split over every test made)
and c's share is at least MIN_EXCESS above the crowd's. Only favouring is tested: the attack is to lift one's own
system. The report then gives the ranking with and without the flagged raters; it excludes nobody by this rule.
"""

import numpy as np
import pandas as pd
from scipy.special import ndtri

MIN_VOTES = 8
ALPHA = 0.01
MIN_EXCESS = 0.25
COLUMNS = ("rater_id", "condition", "votes", "share", "crowd_share", "z")


def _votes_for(o):
    """One row per (test vote, condition in it): rater_id, condition, pair (first|second), score (1 for the
    condition's win, 0.5 a tie, 0 a loss), from the oriented test rows (preference.oriented)."""
    pair = o["first"] + "|" + o["second"]
    score_first = np.where(o["pref"] > 0, 1.0, np.where(o["pref"] < 0, 0.0, 0.5))
    a = pd.DataFrame({"rater_id": o["rater_id"], "condition": o["first"], "pair": pair, "score": score_first})
    b = pd.DataFrame({"rater_id": o["rater_id"], "condition": o["second"], "pair": pair, "score": 1.0 - score_first})
    return pd.concat([a, b], ignore_index=True)


def flag(o) -> pd.DataFrame:
    """The flagged (rater, condition) pairs of the oriented test rows `o`, strongest first: COLUMNS."""
    v = _votes_for(o)
    if v.empty:
        return pd.DataFrame(columns=COLUMNS)
    # The crowd's share for c on each pair, without the rater: (total - the rater's) / (count - the rater's).
    per_pair = v.groupby(["condition", "pair"])["score"].agg(sum_all="sum", count_all="count").reset_index()
    mine = v.groupby(["rater_id", "condition", "pair"])["score"].agg(["sum", "count"]).reset_index()
    mine = mine.merge(per_pair, on=["condition", "pair"])
    others = mine["count_all"] - mine["count"]
    mine["p"] = np.where(others > 0, (mine["sum_all"] - mine["sum"]) / others.where(others > 0, 1), 0.5)
    mine["expected"] = mine["p"] * mine["count"]
    mine["var"] = mine["count"] * (mine["p"] * (1 - mine["p"]) + 1 / 12)
    g = mine.groupby(["rater_id", "condition"])[["sum", "count", "expected", "var"]].sum().reset_index()
    g = g[g["count"] >= MIN_VOTES]
    if g.empty:
        return pd.DataFrame(columns=COLUMNS)
    tests = o["rater_id"].nunique() * len(set(o["first"]) | set(o["second"]))
    bar = float(ndtri(1 - ALPHA / max(tests, 1)))
    g["z"] = (g["sum"] - g["expected"]) / np.sqrt(g["var"])
    g["share"] = g["sum"] / g["count"]
    g["crowd_share"] = g["expected"] / g["count"]
    hit = g[(g["z"] >= bar) & (g["share"] - g["crowd_share"] >= MIN_EXCESS)]
    out = hit.rename(columns={"count": "votes"})[list(COLUMNS)].sort_values("z", ascending=False)
    out["votes"] = out["votes"].astype(int)
    return out.reset_index(drop=True)


def rule_text() -> str:
    """The rule in one sentence, as the report prints it."""
    return (
        f"a rater is flagged for a condition when, over at least {MIN_VOTES} of their test votes on pairs with it, "
        "its share of the votes (a tie half) beats the share the other raters gave it in the same pairs by a "
        f"one-sided z at the Bonferroni level {ALPHA} over raters x conditions, and by at least {MIN_EXCESS:g}"
    )
