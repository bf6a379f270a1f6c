"""What the report says about the user's own study rather than the MoGlow paper's: the reference's own name,
captions that cite the paper only for the built-in study, and notes on the classifier two-sample test (C2ST).

- The manifest (and so the export) names the reference condition NAT whatever the study file calls it
  (CONTRACTS §10); `--reference-name NAME` or `--study STUDY.toml` (its `reference` key) give it back its own
  name in every table, figure and model of the report.
- A study is the built-in one when its conditions are within NAT, MG, FL and BAD and hold MG and FL: only then do
  the captions cite the paper's figures.
- A C2ST AUC on fewer than C2ST_MIN_ITEMS items says little: folds are grouped by item, so with 7 items the
  out-of-fold AUC of two identical distributions spreads over roughly 0.2-0.8 by chance. An AUC below
  C2ST_LOW_AUC is not "better than real": the classifier tells the two apart systematically the wrong way round,
  which happens when it has learned the items rather than the systems (a system that shows other items' real
  clips, say).
"""

from pathlib import Path

import pandas as pd

from moglow_eval.core import study, user_files

from ..data.load import AnalysisError

STUDY_FILE_BYTES = 1 << 20  # a study file is a few dozen keys

C2ST_MIN_ITEMS = 10
C2ST_LOW_AUC = 0.3


def is_builtin_study(conditions) -> bool:
    """Conditions within NAT, MG, FL and BAD, with MG and FL: the MoGlow paper's study."""
    conds = set(conditions)
    return conds <= set(study.RESERVED) and set(study.GENERATED) <= conds


def reference_from_study_file(path) -> str:
    """The `reference` key of a study file (CONTRACTS §10), or AnalysisError naming the file."""
    path = Path(path)
    doc = user_files.read_toml(path, STUDY_FILE_BYTES, AnalysisError, "study file")
    ref = doc.get("reference")
    if not isinstance(ref, str) or not ref.strip():
        raise AnalysisError(f"{path}: no 'reference' key naming the reference condition")
    return ref.strip()


def rename_reference(df, name, column="condition"):
    """The rows with the reference condition NAT called `name`; AnalysisError if another condition has that name."""
    if not name or name == study.NATURAL:
        return df
    if name in set(df[column]):
        raise AnalysisError(f"--reference-name {name!r}: the file already has a condition of that name")
    return df.assign(**{column: df[column].replace(study.NATURAL, name)})


def rename_c2st(table, name):
    """c2st.csv's rows with NAT (and NAT:split) under the reference's own name."""
    if table is None or not name or name == study.NATURAL:
        return table
    cond = table["condition"].astype(str).str.replace(rf"^{study.NATURAL}(?=$|:)", name, regex=True)
    return table.assign(condition=cond)


def c2st_note(row) -> str:
    """What a C2ST row needs said beside its AUC: too few items to mean anything, or an AUC far below 0.5."""
    notes = []
    n = row.get("n_items")
    if pd.notna(n) and n < C2ST_MIN_ITEMS:
        notes.append(f"only {int(n)} items (< {C2ST_MIN_ITEMS}): the AUC's chance spread is too wide to mean much")
    auc = row.get("auc")
    if pd.notna(auc) and auc < C2ST_LOW_AUC:
        notes.append(
            f"AUC below {C2ST_LOW_AUC}: the classifier learned the item, not the system (e.g. clips of other items)"
        )
    return "; ".join(notes)


def c2st_with_notes(table):
    """The C2ST table with a `note` column (empty where there is nothing to say)."""
    return table.assign(note=[c2st_note(r) for _, r in table.iterrows()])


def captions(conditions) -> dict[str, str]:
    """The figure captions of an acr report: the paper's figure numbers only for the built-in study."""
    paper = is_builtin_study(conditions)

    def caption(figure, text):
        return f"Fig. {figure} of the paper: {text}" if paper else text[0].upper() + text[1:]

    return {
        "ratings_histogram": caption(5, "responses per scale point and condition; dashed lines at the means."),
        "per_clip_means": caption(6, "mean rating of each clip, sorted worst to best within each condition."),
    }
