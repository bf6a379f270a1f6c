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
import json

from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session

from moglow_eval.core import votes

from ..designs import get
from ..store.db import study_design
from ..store.manifest import AppError
from .export import cell


def battle_row(user, input_code, model_a, model_b, preference: int, reasons, text: str) -> dict:
    """One battle row from a vote: `reasons` the ticked ids in order, `text` the free text ("" for none)."""
    winner, strong = votes.preference_to_battle(int(preference))
    ids = list(reasons)
    if text and votes.OTHER_REASON not in ids:
        ids.append(votes.OTHER_REASON)  # the leaderboard's free text belongs to its "other" box
    return {
        "user": user,
        "input_code": input_code,
        "model_a": model_a,
        "model_b": model_b,
        "winner": winner,
        "is_strong": strong,
        "juiceOptions": json.dumps(ids, separators=(",", ":")) if ids else "{}",
        "juiceOtherReason": json.dumps(text) if text else "",
    }


def battles_from_pairs(rows):
    """Battle rows from pairs.csv rows (dicts as the export writes them): the test votes, in order."""
    for r in rows:
        if r["role"] != "test":
            continue
        reasons = [x for x in (r.get("reasons") or "").split(";") if x]
        yield battle_row(
            r["rater_id"],
            r["item"],
            r["condition_a"],
            r["condition_b"],
            r["preference"],
            reasons,
            r.get("reason_text") or "",
        )


def export_battles(engine: Engine, out=None) -> str | int:
    """Write the battle file to `out` (returns the row count) or return it as a string; AppError for a study
    whose design is not pairwise."""
    buf = out if out is not None else io.StringIO()
    n = 0
    with Session(engine.execution_options(read_only=True)) as s:
        design = get(study_design(s))
        if design.name != "pairwise":
            raise AppError(f"--format battles: the study is {design.name}; the battle format holds pairwise votes")
        w = csv.DictWriter(buf, fieldnames=list(votes.BATTLE_COLUMNS), lineterminator="\n")
        w.writeheader()
        for row in battles_from_pairs(design.export_rows(s)):
            w.writerow({k: cell(v) for k, v in row.items()})
            n += 1
    return n if out is not None else buf.getvalue()
