"""dyadic (CONTRACTS §8): pairs.csv with `matched` and `mismatched_interlocutor`. Per system, its preference for the
motion it made for the interlocutor shown over its motion for another interlocutor: the mean score (+2 .. -2, 0 = no
preference) with its 95% Student-t interval, the shares, and a sign test against no preference, as GENEA 2023
reported its interlocutor appropriateness. The real agent (NAT) is a system like any other where the study gave it
a mismatched counterpart."""

from ..appropriateness.design import Appropriateness


class Dyadic(Appropriateness):
    name = "dyadic"
    score = "mean interlocutor appropriateness score"
    heading = (
        "Mean interlocutor appropriateness score (+2 = the motion made for this interlocutor clearly "
        "preferred, -2 = the one made for another; 0 = no preference)"
    )
