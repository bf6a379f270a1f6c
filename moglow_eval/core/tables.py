"""Reading the project's CSV files: every problem is one line naming the file and the line (CONTRACTS §4, §6).

metrics.csv is read here and nowhere else, by the analysis and by the simulated raters alike, so an empty
cell and "nan" mean the same everywhere: not measured.
"""

from pathlib import Path

import numpy as np
import pandas as pd

from moglow_eval.core import study, user_files
from moglow_eval.core.cli import UserError

MAX_BYTES = 4 << 30  # an export of every answer of a large study is a few hundred MB; a table is never this large


class TableError(UserError):
    """A CSV file that breaks its contract; the message is one line naming the file and the line or column."""


def read_csv(path, error=TableError):
    """A CSV file as all-text columns, indexed by file line number (header = line 1); `error` names it. Only a
    regular file of at most MAX_BYTES is read (moglow_eval.core.user_files.open_regular)."""
    path = Path(path)
    try:
        with user_files.open_regular(path, MAX_BYTES, error) as fh:
            head = fh.read(4096)
            if not head.strip():
                raise error(f"{path}: file is empty (expected a CSV header and rows)")
            fh.seek(0)
            # All text, no NA guessing: "NA" or "" stay visible so we can name the line that holds them.
            df = pd.read_csv(
                fh, dtype=str, keep_default_na=False, na_filter=False, skip_blank_lines=False, encoding="utf-8-sig"
            )
    except pd.errors.ParserError as exc:
        raise error(f"{path}: malformed CSV: {str(exc).strip().splitlines()[-1]}") from None
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except pd.errors.EmptyDataError:
        raise error(f"{path}: file is empty (expected a CSV header and rows)") from None
    df.columns = [str(c).strip() for c in df.columns]
    df.index = np.arange(2, len(df) + 2)  # file line numbers (header is line 1)
    # Wholly blank lines are layout, not data (a trailing newline or two); anything else is kept and checked.
    if len(df.columns):
        maybe = df[df.columns[0]] == ""
        if maybe.any():
            blank = maybe & (df == "").all(axis=1)
            df = df[~blank]
    return path, df


def first_line(mask):
    """The file line of the first true row of a boolean column indexed as read_csv indexes."""
    return int(mask.index[np.flatnonzero(np.asarray(mask))[0]])


def read_metrics(path, error=TableError, keys=False):
    """metrics.csv (clip_id, condition, role, item, metric columns...) -> DataFrame indexed by clip_id.

    Every column other than the four keys is an objective metric and must be numeric (empty = missing,
    reported as such, never guessed). With `keys`, the key columns the file has (condition, role, item) come first,
    as text.
    """
    path, df = read_csv(path, error)
    if "clip_id" not in df.columns:
        raise error(f"{path}: missing required column clip_id (header has: {', '.join(df.columns)})")
    if len(df) == 0:
        raise error(f"{path}: no rows (header only)")
    df["clip_id"] = df["clip_id"].str.strip()
    empty = df["clip_id"] == ""
    if empty.any():
        raise error(f"{path}:{first_line(empty)}: empty clip_id")
    dup = df["clip_id"].duplicated()
    if dup.any():
        line = first_line(dup)
        raise error(f"{path}:{line}: duplicate clip_id {df.at[line, 'clip_id']}")
    metric_cols = [c for c in df.columns if c not in study.METRIC_KEYS]
    if not metric_cols:
        raise error(f"{path}: no metric columns besides {', '.join(study.METRIC_KEYS)}")
    out = pd.DataFrame(index=df["clip_id"].to_numpy())
    for col in [c for c in study.METRIC_KEYS[1:] if c in df.columns] if keys else []:
        out[col] = df[col].str.strip().to_numpy()
    for col in metric_cols:
        out[col] = _numbers(path, df, col, error)
    out.index.name = "clip_id"
    return out


def _numbers(path, df, col, error):
    """Column `col` as floats: an empty cell or `nan` is NaN (not measured), anything else not a finite number is
    one error naming the file and line (an infinite value would drop its clip from every correlation unsaid)."""
    text = df[col].str.strip()
    values = pd.to_numeric(text.replace("", np.nan).replace("nan", np.nan), errors="coerce")
    bad = values.isna() & ~text.isin(["", "nan"])
    if bad.any():
        line = first_line(bad)
        raise error(f"{path}:{line}: {col} {df.at[line, col]!r} is not a number")
    infinite = pd.Series(np.isinf(values.to_numpy(dtype=float)), index=values.index)
    if infinite.any():
        line = first_line(infinite)
        raise error(
            f"{path}:{line}: {col} {df.at[line, col]!r} is not a finite number "
            "(leave the cell empty or write nan where a clip was not measured)"
        )
    return values.to_numpy(dtype=float)


C2ST_COLUMNS = ("condition", "n_items", "auc", "auc_sd", "accuracy")  # c2st.csv (CONTRACTS §4)


def read_c2st(path, error=TableError):
    """c2st.csv (the classifier two-sample test of each condition against the reference) -> DataFrame with
    C2ST_COLUMNS, numbers parsed; one line naming the file and row otherwise."""
    path, df = read_csv(path, error)
    missing = [c for c in C2ST_COLUMNS if c not in df.columns]
    if missing:
        raise error(f"{path}: missing required column {missing[0]} (header has: {', '.join(df.columns)})")
    out = df[list(C2ST_COLUMNS)].copy()
    for col in C2ST_COLUMNS[1:]:
        out[col] = _numbers(path, df, col, error)
    return out.reset_index(drop=True)
