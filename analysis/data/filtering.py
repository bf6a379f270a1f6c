"""The paper's rater filter: drop every rater who rated any catch (bad-example) clip at or above a threshold.

MoGlow §5.4: raters who gave any of the BAD clips a rating of 3 or more were considered inattentive and all
their responses were discarded (1880 responses, 152 removed, 1728 kept).
"""

import pandas as pd

from moglow_eval.core import study

DEFAULT_THRESHOLD = study.CATCH_FAIL_AT


def failed_raters(df, threshold=DEFAULT_THRESHOLD):
    """Sorted list of the rater ids excluded (study.excluded_raters) for catch ratings >= threshold."""
    catch = df[df["role"] == "catch"]
    return study.excluded_raters(zip(catch["rater_id"].tolist(), (catch["rating"] >= threshold).tolist()))


def exclude_raters(df, threshold=DEFAULT_THRESHOLD):
    """The paper's rater filter: drop every rater who gave any catch clip a rating of `threshold` or more.

    Parameters
    ----------
    df : DataFrame
        Ratings as `load_ratings` returns them (columns rater_id, role and rating at least).
    threshold : int
        A catch rating at or above this fails its rater; the default is the paper's 3 (study.CATCH_FAIL_AT).

    Returns
    -------
    kept : DataFrame
        The rows, of every role, of the raters who pass.
    counts : dict
        Counts over all rows (test and catch), as in the paper: n_ratings_total, n_ratings_removed,
        n_ratings_kept, n_raters_total, n_raters_excluded, n_raters_kept; the counts that the statistics use
        (n_catch_ratings, n_test_ratings_total, n_test_ratings_kept); n_raters_without_catch, the raters who saw
        no catch trial at all (they cannot fail the check); the threshold; and excluded_raters, the sorted ids of
        the raters dropped.

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.data.filtering import exclude_raters
    >>> df = pd.DataFrame(
    ...     {
    ...         "rater_id": ["r1", "r1", "r2", "r2", "r3"],
    ...         "role": ["test", "catch", "test", "catch", "test"],
    ...         "rating": [4, 1, 5, 4, 2],
    ...     }
    ... )
    >>> kept, counts = exclude_raters(df)
    >>> counts["excluded_raters"], counts["n_ratings_kept"], counts["n_raters_without_catch"]
    (['r2'], 3, 1)
    >>> sorted(kept["rater_id"])
    ['r1', 'r1', 'r3']
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
    """The test rows of `df`: only they enter the statistics; catch rows never do.

    Parameters
    ----------
    df : DataFrame
        Rows with a role column.

    Returns
    -------
    DataFrame
        A new frame of the rows whose role is "test", in their order and with their index.

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.data.filtering import only_test_rows
    >>> df = pd.DataFrame({"role": ["test", "catch", "test"], "rating": [4, 1, 3]})
    >>> only_test_rows(df)["rating"].tolist()
    [4, 3]
    """
    out = df[df["role"] == "test"]
    return pd.DataFrame(out)
