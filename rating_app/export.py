"""The study's export (ratings.csv, CONTRACTS §6, or its design's file, §8), straight from the database.

The study's design (stored in the database) gives the columns and the rows (designs/). Every text cell that a
spreadsheet would take for a formula (starting with = + - @, a tab or a carriage return) is written with a
leading apostrophe, so opening the export can never run anything a rater typed. The `flags` column marks
answers to look at before trusting them (export_cells.FLAGS).
"""

from __future__ import annotations

import csv
import io

from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session

from .db import study_design
from .designs import get

FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def cell(value):
    """A CSV cell that no spreadsheet evaluates."""
    if isinstance(value, str) and value.startswith(FORMULA_START):
        return "'" + value
    return value


def export_csv(engine: Engine, out=None) -> str | int:
    """Write the study's export to the file object `out` (returns the row count) or return it as a string."""
    buf = out if out is not None else io.StringIO()
    n = 0
    with Session(engine.execution_options(read_only=True)) as s:
        design = get(study_design(s))
        w = csv.DictWriter(buf, fieldnames=design.columns, lineterminator="\n")
        w.writeheader()
        for row in design.export_rows(s):
            w.writerow({k: cell(v) for k, v in row.items()})
            n += 1
    return n if out is not None else buf.getvalue()
