"""The paper's rater filter: drop every rater who rated any catch (bad-example) clip at or above a threshold.

MoGlow §5.4: raters who gave any of the BAD clips a rating of 3 or more were considered inattentive and all
their responses were discarded (1880 responses, 152 removed, 1728 kept).
"""

import pandas as pd

from moglow_eval.core import study

DEFAULT_THRESHOLD = study.CATCH_FAIL_AT


def failed_raters(df, threshold=DEFAULT_THRESHOLD):
    """Sorted list of rater ids with at least one catch rating >= threshold."""
    catch = df[df["role"] == "catch"]
    return sorted(catch.loc[catch["rating"] >= threshold, "rater_id"].unique().tolist())


def exclude_raters(df, threshold=DEFAULT_THRESHOLD):
    """-> (kept rows of every role, counts dict).

    Counts are over all rows (test and catch), as in the paper: n_ratings_total, n_ratings_removed,
    n_ratings_kept, n_raters_total, n_raters_excluded, n_raters_kept; plus the test-only counts that the
    statistics use and the number of raters who saw no catch trial at all (they cannot fail the check).
    """
    bad = failed_raters(df, threshold)
    drop = df["rater_id"].isin(bad)
    kept = df[~drop]
    raters_with_catch = df.loc[df["role"] == "catch", "rater_id"].nunique()
    counts = {
        "threshold": threshold,
        "n_ratings_total": int(len(df)),
        "n_ratings_removed": int(drop.sum()),
        "n_ratings_kept": int(len(kept)),
        "n_raters_total": int(df["rater_id"].nunique()),
        "n_raters_excluded": len(bad),
        "n_raters_kept": int(kept["rater_id"].nunique()),
        "n_raters_without_catch": int(df["rater_id"].nunique() - raters_with_catch),
        "n_catch_ratings": int((df["role"] == "catch").sum()),
        "n_test_ratings_total": int((df["role"] == "test").sum()),
        "n_test_ratings_kept": int((kept["role"] == "test").sum()),
        "excluded_raters": bad,
    }
    return kept, counts


def only_test_rows(df):
    """Only test rows enter the statistics; catch rows never do."""
    out = df[df["role"] == "test"]
    return pd.DataFrame(out)
