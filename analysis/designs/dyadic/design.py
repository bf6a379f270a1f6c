"""dyadic (CONTRACTS §8): pairs.csv with `matched` and `mismatched_interlocutor`. Per system, its preference for the
motion it made for the interlocutor shown over its motion for another interlocutor: the mean score (+2 .. -2, 0 = no
preference) with its 95% Student-t interval, the shares, and a sign test against no preference, as GENEA 2023
reported its interlocutor appropriateness. The real agent (NAT) is a system like any other where the study gave it
a mismatched counterpart."""

from ..appropriateness.design import Appropriateness


class Dyadic(Appropriateness):
    name = "dyadic"
    methods_task = (
        "watched two people in conversation, the same real interlocutor and the same audio in both videos, one with a "
        "system's agent motion made for that interlocutor and one with the same system's motion made for another, "
        "and chose the agent that responded more appropriately on a five-level scale"
    )
    methods_stats = (
        "the mean interlocutor appropriateness score with Student-t intervals and sign tests against no preference, "
        "Holm-adjusted"
    )
    score = "mean interlocutor appropriateness score"
    heading = (
        "Mean interlocutor appropriateness score (+2 = the motion made for this interlocutor clearly "
        "preferred, -2 = the one made for another; 0 = no preference)"
    )
