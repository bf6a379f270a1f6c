"""Why a system lost: the share of each reason raters ticked when they preferred the other clip (CONTRACTS §8).

A pairwise vote may carry the reasons the rater ticked (`reasons`, ids joined by `;`) and a free text
(`reason_text`), as the app exports them and as the GENEA leaderboard's battle files hold them (Nagy et al. 2025,
arXiv:2511.01233, report the same shares per system). A reason ticked with a vote is read as a reason the losing
clip lost; ties name no loser and are left out, as are catch trials.
"""

import pandas as pd

from moglow_eval.core import votes

TEXT = "free_text"  # the column of the share of lost votes that came with a free text


def reason_ids(cell) -> list[str]:
    """The ids of one `reasons` cell: split at `;`, empty parts and blanks dropped."""
    if not isinstance(cell, str):
        return []
    return [x.strip() for x in cell.split(";") if x.strip()]


def when_lost(df):
    """Per condition, the share of its lost test votes that came with each reason.

    Parameters
    ----------
    df : DataFrame
        Answers with columns condition_a, condition_b, preference (-2..2, positive = A preferred), role and
        `reasons` (ids joined by ';'; optional `reason_text`), as preference.load_pairs returns pairs.csv.

    Returns
    -------
    DataFrame or None
        One row per condition that lost a test vote (alphabetical), columns `condition`, `lost` (votes lost),
        one column per reason id (GENEA's realism reasons first in their order, then the others alphabetically)
        holding the share of lost votes that ticked it, and `free_text` (the share that came with a text, when
        the file has `reason_text`). None when the file carries no reasons at all.

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.designs.pairwise.reasons import when_lost
    >>> df = pd.DataFrame({"condition_a": ["MG", "MG", "FL"], "condition_b": ["NAT", "NAT", "MG"],
    ...                    "preference": [-2, -1, -1], "role": ["test"] * 3,
    ...                    "reasons": ["UnrealisticMotion;MotionSmoothness", "UnrealisticMotion", ""]})
    >>> when_lost(df).to_dict(orient="records")  # doctest: +NORMALIZE_WHITESPACE
    [{'condition': 'FL', 'lost': 1, 'UnrealisticMotion': 0.0, 'MotionSmoothness': 0.0},
     {'condition': 'MG', 'lost': 2, 'UnrealisticMotion': 1.0, 'MotionSmoothness': 0.5}]
    """
    if "reasons" not in df.columns:
        return None
    t = df[(df["role"] == "test") & (df["preference"] != 0)]
    ticked = t["reasons"].map(reason_ids)
    has_text = "reason_text" in df.columns
    if not ticked.map(bool).any() and not (has_text and t["reason_text"].fillna("").astype(str).str.len().gt(0).any()):
        return None
    loser = t["condition_b"].where(t["preference"] > 0, t["condition_a"])
    known = [rid for rid, _ in votes.REALISM_REASONS]
    seen = {x for ids in ticked for x in ids}
    order = [r for r in known if r in seen] + sorted(seen - set(known))
    rows = []
    for cond in sorted(loser.unique()):
        mine = ticked[loser == cond]
        row = {"condition": cond, "lost": int(len(mine))}
        for rid in order:
            row[rid] = float(mine.map(lambda ids, r=rid: r in ids).mean())
        if has_text:
            row[TEXT] = float(t.loc[mine.index, "reason_text"].fillna("").astype(str).str.len().gt(0).mean())
        rows.append(row)
    return pd.DataFrame(rows, columns=["condition", "lost", *order, *([TEXT] if has_text else [])])


def as_json(table) -> dict:
    """{condition: {"lost": n, "shares": {reason: share}}} of a `when_lost` table (stats.json's
    "reasons_when_lost")."""
    out = {}
    for r in table.to_dict(orient="records"):
        cond, lost = r.pop("condition"), r.pop("lost")
        out[cond] = {"lost": lost, "shares": r}
    return out
