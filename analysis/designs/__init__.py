"""The test designs the analysis reads (CONTRACTS §8), one module each behind one interface (base.Design); this
registry is the only place that lists them. A file's design is told by its columns: exactly one design claims
them.
"""

import csv
from pathlib import Path

from moglow_eval.core import study, tables, user_files

from ..data.load import AnalysisError
from .acr.design import Acr
from .appropriateness.design import Appropriateness
from .base import DESIGN_OPTIONS, Design, Options
from .dyadic.design import Dyadic
from .pairwise.design import Pairwise
from .parallel.design import Parallel
from .semantic.design import Semantic

DESIGNS: dict[str, Design] = {
    d.name: d for d in (Acr(), Pairwise(), Parallel(), Appropriateness(), Dyadic(), Semantic())
}
assert tuple(DESIGNS) == study.DESIGNS, "moglow_eval.core.study.DESIGNS and the registry list the same designs"

__all__ = ["DESIGNS", "Design", "Options", "check_design_options", "design_of", "detect_design"]


def design_of(path) -> Design:
    """The design of the CSV file at `path`, from its header (AnalysisError if it cannot be opened). A file that
    cannot be read as CSV goes to the default design (acr), whose loader names the problem."""
    path = Path(path)
    with user_files.open_regular(path, tables.MAX_BYTES, AnalysisError) as fh:
        try:
            header = next(csv.reader(user_files.lines(fh, path, tables.MAX_BYTES, AnalysisError)), [])
        except (AnalysisError, csv.Error):  # a header that is not text or CSV: the default design's reader names it
            return DESIGNS[study.DEFAULT_DESIGN]
    columns = {c.strip() for c in header}
    return next(d for d in DESIGNS.values() if d.detects(columns))


def detect_design(path) -> str:
    """The name of the design of the CSV file at `path`."""
    return design_of(path).name


def check_design_options(design: Design, options: Options, path) -> None:
    """AnalysisError, one line, for an option given (not at its default) that `design` does not read
    (base.DESIGN_OPTIONS), naming the designs that do."""
    defaults = Options()
    for field, flag in DESIGN_OPTIONS.items():
        if field not in design.reads and getattr(options, field) != getattr(defaults, field):
            readers = ", ".join(d.name for d in DESIGNS.values() if field in d.reads)
            raise AnalysisError(f"{flag}: {path} holds {design.name} answers; {flag} is for {readers} exports only")
