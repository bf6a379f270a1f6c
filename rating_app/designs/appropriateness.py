"""appropriateness (CONTRACTS §8, GENEA 2023): two clips of one system with the same item's speech, the motion it
made for that speech and the motion it made for another item's (the manifest's `motion_item`), a preference
-2..2 as in pairwise, whose trial payload, answer, storage, catch units and page it reuses.

The unit is (item, condition). The clips play one after the other with their speech, so the viewing rule counts
the sum of their durations. The export is pairs.csv with `matched` (the side showing the motion made for the
speech heard; empty on catch rows) and `mismatched_item`. A manifest with such clips serves the other designs too,
without the mismatched clips, so one stimulus set holds GENEA's human-likeness and appropriateness tests.
"""

from __future__ import annotations

from sqlalchemy import select

from moglow_eval.core import study

from ..store.db import Clip
from ..store.manifest import AppError
from .base import Unit
from .pairwise import Pairwise, iter_pair_rows


class Appropriateness(Pairwise):
    name = "appropriateness"
    question = "Which motion fits the speech better?"
    export_noun = "appropriateness answers"
    columns = (*Pairwise.columns, "matched", study.MISMATCH_COLUMN["appropriateness"])
    default_reasons, default_reason_text = (), 0  # GENEA's reasons are about realism; set VOTE_REASONS to ask
    # A system's score is against its own mismatched motion, not a ranking of pairs: no rounds, no adaptive pairing,
    # no battles (the leaderboard's battles are between two systems).
    grows = ranks_conditions = battles = False
    dashboard = {
        **Pairwise.dashboard,
        "note": " (a system's motion for the speech heard and for another item's, a preference; targets per item "
        "and condition)",
        "per_condition": "system",
        "mean": "mean appropriateness score",
    }

    def serving_clips(self, clips):
        return list(clips)  # the mismatched clips are this design's

    def test_units(self, tests, clips):
        """One unit per test item and condition: its matched clip beside its mismatched one."""
        mismatched = {(c.item, c.condition): c.clip_id for c in clips if c.role == "test" and c.motion_item}
        if not mismatched:
            raise AppError(
                f"{self.name}: the manifest has no mismatched clips (a motion_item column); build the stimuli "
                f'with design = "{self.name}" in the study file'
            )
        systems = sorted({cond for _, cond in mismatched})
        units = {}
        for item, by_cond in sorted(tests.items()):
            for cond in self.tested(by_cond, systems):
                if (item, cond) not in mismatched or cond not in by_cond:
                    raise AppError(f"{self.name}: item {item!r} has no mismatched clip of condition {cond}")
                key = f"fit:{item}:{cond}"
                units[key] = Unit(key, "test", item, (by_cond[cond][0], mismatched[(item, cond)]))
        return units

    def tested(self, by_cond, systems):
        """The conditions of an item's test units: every condition of the item (`systems`: those with any
        mismatched clip)."""
        return sorted(by_cond)

    def required_ms(self, durations):
        return sum(durations)

    def export_rows(self, s):
        yield from iter_fit_rows(s, study.MISMATCH_COLUMN[self.name])

    def signed(self, row, first):
        """The mean is the MAS, seen from the matched clip (a catch row: as pairwise)."""
        if row["matched"]:
            return row["preference"] if row["matched"] == "a" else -row["preference"]
        return super().signed(row, first)

    def simulated_answer(self, rater, ids, shown):
        watched = rater.watched(shown)
        return rater.prefer_fit(shown[0], shown[1]), watched


def iter_fit_rows(s, mismatch_column):
    """pairs.csv's rows, with the matched side and, in `mismatch_column`, the item the mismatched motion was
    made for."""
    motion = dict(s.execute(select(Clip.clip_id, Clip.motion_item)).all())
    for row in iter_pair_rows(s):
        ma, mb = motion.get(row["clip_a"]) or "", motion.get(row["clip_b"]) or ""
        test = row["role"] == "test"
        row["matched"] = ("b" if ma else "a") if test else ""
        row[mismatch_column] = (ma or mb) if test else ""
        yield row
