"""The test designs the app runs (CONTRACTS §8), one module each behind one interface (base.Design); this registry
is the only place that lists them. Everything else takes the study's design from `get(name)`.
"""

from __future__ import annotations

from flask import current_app

from moglow_eval.core import study

from ..store.manifest import AppError
from .acr import Acr
from .appropriateness import Appropriateness
from .base import LABELS, MAX_PAGE, Design, Unit
from .dyadic import Dyadic
from .pairwise import Pairwise
from .parallel import Parallel
from .semantic import Semantic

DESIGNS: dict[str, Design] = {
    d.name: d for d in (Acr(), Pairwise(), Parallel(), Appropriateness(), Dyadic(), Semantic())
}
assert tuple(DESIGNS) == study.DESIGNS, "moglow_eval.core.study.DESIGNS and the registry list the same designs"

__all__ = ["DESIGNS", "LABELS", "MAX_PAGE", "Design", "Unit", "build_units", "get", "of_app", "taking_reasons"]


def get(name: str | None) -> Design:
    """The design called `name` (None: the default, acr); AppError, one line, for any other name."""
    name = (name or study.DEFAULT_DESIGN).strip()
    if name not in DESIGNS:
        raise AppError(f"design {name!r} must be one of {', '.join(DESIGNS)}")
    return DESIGNS[name]


def taking_reasons() -> list[str]:
    """The names of the designs whose votes may carry reasons (base.Design.takes_reasons)."""
    return [d.name for d in DESIGNS.values() if d.takes_reasons]


def build_units(name: str, clips) -> dict[str, Unit]:
    """{key: Unit} of the test and catch units of a study of design `name`."""
    return get(name).build_units(clips)


def of_app() -> Design:
    """The design of the study this app serves (create_app stores it)."""
    return current_app.extensions["rating_app"]["design"]
