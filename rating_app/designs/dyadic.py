"""dyadic (CONTRACTS §8; GENEA 2023's interlocutor appropriateness, GENEA 2026's dyadic task): does the agent respond
to the person it is talking with?

Each unit is (item, system): the system's agent motion made for this item's real interlocutor beside the motion the
same system made for another interlocutor (the manifest's `motion_item` names whose), both shown with this item's
interlocutor and the agent's own speech, so only the agent's response differs. The rater says which agent responds
more appropriately, on pairwise's five levels. Everything else is appropriateness's: units, viewing time, trial,
answer, storage, catch pairs; the export names the mismatched interlocutor's item in `mismatched_interlocutor`.

Only the systems that gave motion for a mismatched interlocutor are tested: the real agent takes part where the
study supplies its mismatched counterpart (GENEA 2023 had none for it), and is otherwise left out of the test units.
"""

from __future__ import annotations

from moglow_eval.core import study

from ..store.manifest import AppError
from .appropriateness import Appropriateness
from .base import Unit
from .pairwise import Pairwise


class Dyadic(Appropriateness):
    name = "dyadic"
    question = "Which character responds more appropriately to the other person?"
    export_noun = "interlocutor appropriateness answers"
    columns = (*Pairwise.columns, "matched", study.MISMATCH_COLUMN["dyadic"])
    dashboard = {
        **Appropriateness.dashboard,
        "note": " (a system's motion for the interlocutor shown and for another interlocutor, a preference; targets "
        "per item and system)",
        "mean": "mean interlocutor appropriateness score",
    }

    def test_units(self, tests, clips):
        """One unit per test item and system that has mismatched clips: a system with some items' but not all is
        refused, naming the item; one with none is not tested."""
        mismatched = {(c.item, c.condition): c.clip_id for c in clips if c.role == "test" and c.motion_item}
        systems = sorted({cond for _, cond in mismatched})
        if not systems:
            return super().test_units(tests, clips)  # its one-line error: no mismatched clips at all
        units = {}
        for item, by_cond in sorted(tests.items()):
            for cond in systems:
                if (item, cond) not in mismatched or cond not in by_cond:
                    raise AppError(f"dyadic: item {item!r} has no mismatched clip of condition {cond}")
                key = f"fit:{item}:{cond}"
                units[key] = Unit(key, "test", item, (by_cond[cond][0], mismatched[(item, cond)]))
        return units
