"""The export in the GENEA leaderboard's battle format (CONTRACTS §8, *Battles*): one row per pairwise test vote,
`python -m rating_app export --format battles` and `/admin/export.csv?format=battles`.

The leaderboard (Nagy et al. 2025, arXiv:2511.01233) writes a vote as its columns (moglow_eval.core.votes.
BATTLE_COLUMNS): the rater, the stimulus (our item), the two systems in the order shown (our conditions A and B),
the winner (`model_a`, `model_b`, `tie`) and whether the preference was strong (empty for a tie), the ticked
reasons as a compact JSON list (`{}` when none), and the free text JSON-quoted, its "other" reason then ticked
too, as the leaderboard's own files have it. Catch trials are attention checks, not battles: they are left out.
"""

from __future__ import annotations

import csv
import io

from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session

from moglow_eval.core import votes

from ..designs import DESIGNS, get
from ..store.db import study_design
from ..store.manifest import AppError
from .export import cell

# Where they were before the design held its battles (old imports): the rows from a vote, from pairs.csv rows.
battle_row, battles_from_pairs = votes.battle_row, votes.battles_from_pairs


def export_battles(engine: Engine, out=None) -> str | int:
    """Write the battle file to `out` (returns the row count) or return it as a string; AppError for a study
    whose design has no battles (Design.battle_rows)."""
    buf = out if out is not None else io.StringIO()
    n = 0
    with Session(engine.execution_options(read_only=True)) as s:
        design = get(study_design(s))
        rows = design.battle_rows(s)
        if rows is None:
            takes = " or ".join(d.name for d in DESIGNS.values() if d.battles)
            raise AppError(
                f"--format battles: the study is {design.name}; the battle format holds votes between two systems "
                f"({takes} studies)"
            )
        w = csv.DictWriter(buf, fieldnames=list(votes.BATTLE_COLUMNS), lineterminator="\n")
        w.writeheader()
        for row in rows:
            w.writerow({k: cell(v) for k, v in row.items()})
            n += 1
    return n if out is not None else buf.getvalue()
