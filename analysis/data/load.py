"""Read and validate ratings.csv (CONTRACTS.md §6) and metrics.csv; every problem is one AnalysisError line.

Nothing is dropped silently: a bad row stops the analysis with the file line that holds it. The returned
frame's index is the file line number of each row (header = line 1), so later messages can name lines too.
"""

from pathlib import Path

import numpy as np
import pandas as pd

from moglow_eval.core import study, tables
from moglow_eval.core.cli import UserError

REQUIRED = ("rater_id", "clip_id", "condition", "rating")
ROLES = study.RATED_ROLES
SCALE = (1, 2, 3, 4, 5)


class AnalysisError(UserError):
    """Bad input for the analysis; the message is one line naming the file and the line or column."""


def _codes(series):
    """(codes, stripped unique values): string work is done once per distinct value, not once per row."""
    codes, uniques = pd.factorize(series)
    uniques = pd.Index(uniques).str.strip()
    return codes, uniques


def _clean_column(path, df, col, categorical=False):
    """Strip blanks around every value; an empty value is an error naming its line. Identifier columns become
    pandas Categoricals, so every later groupby/factorize over a million rows is integer work."""
    codes, uniques = _codes(df[col])
    empty = np.flatnonzero(uniques == "")
    if len(empty):
        raise AnalysisError(f"{path}:{tables.first_line(pd.Series(codes == empty[0], index=df.index))}: empty {col}")
    if uniques.has_duplicates:  # 'r1' and 'r1 ' are the same rater once stripped
        remap, uniques = pd.factorize(uniques)
        codes = remap[codes]
    if categorical:
        df[col] = pd.Categorical.from_codes(codes, categories=uniques)
    else:
        df[col] = np.asarray(uniques, dtype=object)[codes]
    return codes


def _parse_ratings(path, text):
    """Integers 1..5 only; '3.0', '3.5', 'x' and '7' are all errors naming their line."""
    codes, uniques = _codes(text)
    values = np.zeros(len(uniques), dtype=np.int64)
    for i, u in enumerate(uniques):
        ok = u.lstrip("+-").isdigit() and u.isascii() and len(u) <= 18
        if not ok:
            line = tables.first_line(pd.Series(codes == i, index=text.index))
            raise AnalysisError(f"{path}:{line}: rating {text.loc[line]!r} is not an integer 1-5")
        values[i] = int(u)
    bad = np.flatnonzero((values < SCALE[0]) | (values > SCALE[-1]))
    if len(bad):
        first = np.isin(codes, bad)
        line = tables.first_line(pd.Series(first, index=text.index))
        raise AnalysisError(f"{path}:{line}: rating {values[codes[text.index.get_loc(line)]]} is out of range 1-5")
    return pd.Series(values[codes].astype(np.int8), index=text.index)


def _check_unique_attribute(path, df, clip_codes, attr):
    """A clip has one condition (and one role): a clip under two of them is a corrupt export."""
    codes = pd.factorize(df[attr])[0]
    _, first_row = np.unique(clip_codes, return_index=True)  # each clip's first row (codes are 0..C-1)
    clash = codes[first_row][clip_codes] != codes
    if clash.any():
        i = int(np.flatnonzero(clash)[0])
        line = int(df.index[i])
        clip = df.at[line, "clip_id"]
        earlier = int(df.index[np.flatnonzero(clip_codes == clip_codes[i])[0]])
        raise AnalysisError(
            f"{path}:{line}: clip {clip} has {attr} {df.at[line, attr]!r} but "
            f"{df.at[earlier, attr]!r} at line {earlier}"
        )


def read_export(path, required, noun, strip=False):
    """(path, DataFrame of text, index = file line) of an exported CSV with the `required` columns and at least one
    row; with `strip`, the required fields stripped of blanks and none empty. AnalysisError naming file and line."""
    path, df = tables.read_csv(path, AnalysisError)
    missing = [c for c in required if c not in df.columns]
    if missing:
        raise AnalysisError(
            f"{path}: missing required column{'s' if len(missing) > 1 else ''} "
            f"{', '.join(missing)} (header has: {', '.join(df.columns)})"
        )
    if len(df) == 0:
        raise AnalysisError(f"{path}: no {noun} (header only)")
    for col in required if strip else ():
        df[col] = df[col].str.strip()
        empty = df[col] == ""
        if empty.any():
            raise AnalysisError(f"{path}:{empty.idxmax()}: empty {col}")
    return path, df


def load_ratings(path):
    """Read and check a ratings.csv export (CONTRACTS §6).

    Nothing is dropped silently: a bad row stops the reading with the line that holds it.

    Parameters
    ----------
    path : str or Path
        The export: columns rater_id, clip_id, condition and rating, optionally role, and any others.

    Returns
    -------
    DataFrame
        One row per rating, indexed by its line number in the file (the header is line 1), so that later
        messages can name lines too. rater_id and clip_id are categorical, condition is text, rating an integer
        (int8), role "test" or "catch" (without a role column, the rows of the catch condition are catch and the
        others test); extra columns are kept as text.

    Raises
    ------
    AnalysisError
        One line naming the file (and the line where there is one) for: a missing file, an empty file, a header
        only, missing required columns, empty required fields, non-integer or out-of-range ratings, unknown
        roles, duplicate (rater, clip) pairs, a clip listed under two conditions or roles, no test rows.
    """
    path, df = read_export(path, REQUIRED, "ratings")
    rater_codes = _clean_column(path, df, "rater_id", categorical=True)
    clip_codes = _clean_column(path, df, "clip_id", categorical=True)
    _clean_column(path, df, "condition")
    df["rating"] = _parse_ratings(path, df["rating"])
    if "role" in df.columns:
        codes, uniques = _codes(df["role"])
        uniques = uniques.str.lower()
        unknown = np.flatnonzero(~uniques.isin(ROLES))
        if len(unknown):
            line = tables.first_line(pd.Series(codes == unknown[0], index=df.index))
            raise AnalysisError(f"{path}:{line}: unknown role {df.at[line, 'role']!r} (expected test or catch)")
        df["role"] = np.asarray(uniques, dtype=object)[codes]
    else:
        df["role"] = np.where(df["condition"] == study.CATCH, "catch", "test")
    pair = pd.Series(rater_codes.astype(np.int64) * (clip_codes.max() + 1) + clip_codes, index=df.index)
    dup = pair.duplicated()
    if dup.any():
        line = tables.first_line(dup)
        first = tables.first_line(pair == pair.loc[line])
        raise AnalysisError(
            f"{path}:{line}: duplicate rating of clip {df.at[line, 'clip_id']} by rater "
            f"{df.at[line, 'rater_id']} (first at line {first})"
        )
    _check_unique_attribute(path, df, clip_codes, "condition")
    _check_unique_attribute(path, df, clip_codes, "role")
    if not (df["role"] == "test").any():
        raise AnalysisError(f"{path}: no test ratings (every row is a catch trial)")
    return df


def load_metrics(path):
    """metrics.csv -> DataFrame indexed by clip_id (moglow_eval.core.tables.read_metrics), errors as AnalysisError."""
    return tables.read_metrics(path, AnalysisError)


def load_c2st(path):
    """c2st.csv -> DataFrame (moglow_eval.core.tables.read_c2st), errors as AnalysisError."""
    return tables.read_c2st(path, AnalysisError)


def load_measure_clips(path):
    """metrics.csv with its keys, for the report's objective measures: a DataFrame indexed by clip_id with
    condition, role, item, `matched` and the metric columns. A clip is matched unless the manifest beside the file
    (CONTRACTS §4) gives it a `motion_item` (a mismatched clip: another item's motion, or motion made for another
    interlocutor); without a manifest every clip is. AnalysisError, one line, for a file without its keys."""
    df = tables.read_metrics(path, AnalysisError, keys=True)
    missing = [c for c in study.METRIC_KEYS[1:] if c not in df.columns]
    if missing:
        raise AnalysisError(f"{path}: missing column {missing[0]} (the measures need each clip's condition and item)")
    manifest = Path(path).resolve().parent / "manifest.csv"
    df.insert(3, "matched", True)
    if manifest.is_file():
        _, rows = tables.read_csv(manifest, AnalysisError)
        if "motion_item" in rows.columns and "clip_id" in rows.columns:
            mismatched = set(rows.loc[rows["motion_item"].str.strip() != "", "clip_id"].str.strip())
            df["matched"] = ~df.index.isin(mismatched)
    return df


MEASURE_NOTE_COLUMNS = ("measure", "status", "reason", "settings")


def load_measure_notes(path):
    """measures.csv beside metrics.csv (each measure's status, why, its settings; CONTRACTS §4) as a DataFrame with
    MEASURE_NOTE_COLUMNS; an empty one where the stimuli have none (the built-in study, an older set)."""
    notes = Path(path).resolve().parent / study.MEASURES_FILE
    if not notes.is_file():
        return pd.DataFrame(columns=list(MEASURE_NOTE_COLUMNS))
    _, df = tables.read_csv(notes, AnalysisError)
    missing = [c for c in MEASURE_NOTE_COLUMNS if c not in df.columns]
    if missing:
        raise AnalysisError(f"{notes}: missing column {missing[0]} (header has: {', '.join(df.columns)})")
    return df[list(MEASURE_NOTE_COLUMNS)].reset_index(drop=True)
