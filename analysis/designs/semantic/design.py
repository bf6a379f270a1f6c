"""semantic (CONTRACTS §8): pairs.csv with `matched` and `mismatched_utterance`. Per system, how much more its motion
for this utterance shows the highlighted word's meaning than its motion for another utterance: the mean score
(+2 .. -2, 0 = no preference) with its 95% Student-t interval, the shares, and a sign test against chance."""

from ..appropriateness.design import Appropriateness


class Semantic(Appropriateness):
    name = "semantic"
    methods_task = (
        "watched a system's motion for an utterance and its motion for another utterance, both with the utterance's "
        "speech and captions and one word highlighted, and chose the motion that better showed the meaning of that "
        "word on a five-level scale"
    )
    methods_stats = (
        "the mean semantic alignment score with Student-t intervals and sign tests against chance, Holm-adjusted"
    )
    score = "mean semantic alignment score"
    short = "alignment score"
    heading = (
        "Mean semantic alignment score (+2 = the motion made for this utterance clearly preferred, -2 = the "
        "one made for another; 0 = chance)"
    )
