"""Which round of a growing pairwise study each vote belongs to (CONTRACTS §8, *Rounds*): the votes per round and
the conditions each round brought in, for the report.

A study that takes systems round by round, as the GENEA leaderboard does (Nagy et al. 2025, arXiv:2511.01233),
exports each vote's `round` (1 = the start). A report over every round pools them; this table says what was
pooled.
"""

import pandas as pd


def per_round(df):
    """The test votes of each round, and the conditions first compared in it.

    Parameters
    ----------
    df : DataFrame
        Answers with columns condition_a, condition_b, role and `round` (an integer, 1 = the start; empty read as
        1), as analysis.designs.pairwise.preference.load_pairs returns pairs.csv.

    Returns
    -------
    list of dict or None
        One {"round", "n_votes", "new_conditions"} per round that has test votes, in round order; None when the
        file has no `round` column.

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.designs.pairwise.rounds import per_round
    >>> df = pd.DataFrame({"condition_a": ["MG", "SYS", "NAT"], "condition_b": ["NAT", "MG", "SYS"],
    ...                    "role": ["test"] * 3, "round": ["1", "2", "2"]})
    >>> per_round(df)  # doctest: +NORMALIZE_WHITESPACE
    [{'round': 1, 'n_votes': 1, 'new_conditions': ['MG', 'NAT']},
     {'round': 2, 'n_votes': 2, 'new_conditions': ['SYS']}]
    """
    if "round" not in df.columns:
        return None
    t = df[df["role"] == "test"]
    rounds = pd.to_numeric(t["round"].replace("", None), errors="coerce").fillna(1).astype(int)
    seen, out = set(), []
    for r in sorted(rounds.unique()):
        mine = t[rounds == r]
        conds = set(mine["condition_a"]) | set(mine["condition_b"])
        out.append({"round": int(r), "n_votes": int(len(mine)), "new_conditions": sorted(conds - seen)})
        seen |= conds
    return out
