"""The designs whose stimuli a study of your own motion builds (CONTRACTS §10), one module each behind one
interface (base.StimulusDesign); this registry is the only place in generation that lists them. Everything else
asks `get(spec.design)`.
"""

from moglow_eval.core import study

from .appropriateness import Appropriateness
from .base import StimulusDesign, mismatch_partners
from .dyadic import Dyadic
from .semantic import Semantic

DESIGNS: dict[str, StimulusDesign] = {d.name: d for d in (Appropriateness(), Dyadic(), Semantic())}
assert set(DESIGNS) <= set(study.DESIGNS), "every design here is one of moglow_eval.core.study.DESIGNS"


class _NoStimuli(StimulusDesign):
    """A study whose design needs no stimuli of its own (acr, pairwise, parallel): nothing to check or add."""

    def check(self, path, spec):
        pass


NONE = _NoStimuli()

__all__ = ["DESIGNS", "NONE", "StimulusDesign", "get", "mismatch_partners"]


def get(name: str | None) -> StimulusDesign:
    """The design `name` (a key of DESIGNS, as study_file.py has checked), or NONE for a study without one."""
    return DESIGNS[name] if name else NONE
