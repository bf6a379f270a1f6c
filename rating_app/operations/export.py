"""The study's export (ratings.csv, CONTRACTS §6, or its design's file, §8), straight from the database.

The study's design (stored in the database) gives the columns and the rows (designs/). Every text cell that a
spreadsheet would take for a formula (starting with = + - @, a tab or a carriage return) is written with a
leading apostrophe, so opening the export can never run anything a rater typed. The `flags` column marks
answers to look at before trusting them (export_cells.FLAGS); every row of a rater whom the exclusion rule
(moglow_eval.core.study.excluded_raters) excludes carries `failed_catch`.
"""

from __future__ import annotations

import csv
import io
import itertools

from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session

from moglow_eval.core import study
from moglow_eval.core.user_files import defuse

from ..designs import get
from ..designs.export_cells import (
    EXCLUDED,
    clip_samples,
    clip_styles,
    row_samples,
    row_style,
    sample_columns,
    with_flag,
)
from ..store.db import TARGET_RATERS, study_design, study_setting

# A CSV cell that no spreadsheet evaluates: the rule every CSV this project writes from a user's text follows.
cell = defuse


def export_csv(engine: Engine, out=None) -> str | int:
    """Write the study's export to the file object `out` (returns the row count) or return it as a string."""
    buf = out if out is not None else io.StringIO()
    n = 0
    with Session(engine.execution_options(read_only=True)) as s:
        design = get(study_design(s))
        # Every row says how many raters the study needs (as the app was last started), so that the report can
        # tell an export of a study that did not fill; a database from before it has none, and no column.
        target = study_setting(s, TARGET_RATERS)
        extra = {TARGET_RATERS: target} if target is not None else {}
        # A study of your own motion: the reference's own name, which the rows call NAT (CONTRACTS §4, §6).
        reference = study_setting(s, study.REFERENCE_NAME)
        if reference is not None:
            extra[study.REFERENCE_NAME] = reference
        # A manifest with a style column (CONTRACTS §4): every row says how its clips were drawn (§7).
        styles = clip_styles(s)
        style_col = ["style"] if styles else []
        # A stochastic system's samples (CONTRACTS §4): the sample behind each clip of a row (§6).
        samples = clip_samples(s)
        sample_cols = sample_columns(design.columns) if samples else []
        w = csv.DictWriter(buf, fieldnames=[*design.columns, *style_col, *sample_cols, *extra], lineterminator="\n")
        w.writeheader()
        for row in flagged(design, design.export_rows(s)):
            if styles:
                row = {**row, "style": row_style(row, styles)}
            if samples:
                row = {**row, **row_samples(row, samples)}
            w.writerow({k: cell(v) for k, v in {**row, **extra}.items()})
            n += 1
    return n if out is not None else buf.getvalue()


def flagged(design, rows):
    """The export rows with EXCLUDED added to every row of an excluded rater. The rows come rater by rater
    (designs/ order them so), so one rater's rows are held at a time."""
    for _, mine in itertools.groupby(rows, key=lambda r: r["rater_id"]):
        mine = list(mine)
        if study.excluded_raters(design.catch_answers(mine)):
            mine = [{**r, "flags": with_flag(r["flags"], EXCLUDED)} for r in mine]
        yield from mine
