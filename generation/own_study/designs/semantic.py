"""semantic (GENEA 2026's semantic alignment, CONTRACTS §10): appropriateness's clips under captions with one
keyword highlighted, which every item must say."""

from ..study_keys import err
from .base import OtherItemDesign


class Semantic(OtherItemDesign):
    name = "semantic"
    highlights_keyword = True

    def check(self, path, spec):
        super().check(path, spec)
        if spec.captions is None or spec.keywords is None:
            raise err(
                path, "design", "semantic highlights a keyword in the captions: give [captions] folder and keywords"
            )
