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

from .appropriateness import Appropriateness
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

    def tested(self, by_cond, systems):
        """Only the systems that gave motion for a mismatched interlocutor: one with some items' but not all is
        refused by test_units, naming the item; one with none is not tested."""
        return systems
