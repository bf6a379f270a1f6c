"""semantic (CONTRACTS §8; GENEA 2026's semantic alignment): does the motion show what a highlighted word means?

Each unit is (item, system): the system's motion for this utterance beside its motion for another item's utterance
(the manifest's `motion_item`), both shown with this item's speech and its caption, the keyword highlighted, so only
the motion differs. The rater says which motion better shows the meaning of the highlighted word, on pairwise's five
levels. Everything else is appropriateness's; the export names the other utterance's item in `mismatched_utterance`.
"""

from __future__ import annotations

from moglow_eval.core import study

from .appropriateness import Appropriateness
from .pairwise import Pairwise


class Semantic(Appropriateness):
    name = "semantic"
    question = "Which motion better shows the meaning of the highlighted word?"
    export_noun = "semantic alignment answers"
    columns = (*Pairwise.columns, "matched", study.MISMATCH_COLUMN["semantic"])
    dashboard = {
        **Appropriateness.dashboard,
        "note": " (a system's motion for this utterance and for another, a preference; targets per item and system)",
        "mean": "mean semantic alignment score",
    }
