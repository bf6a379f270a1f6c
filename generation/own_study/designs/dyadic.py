"""dyadic (GENEA 2023's interlocutor appropriateness, GENEA 2026's dyadic task; CONTRACTS §10): the agent beside its
real interlocutor, against the same system's motion made for another interlocutor, from a folder per condition."""

from ..study_keys import err
from .base import StimulusDesign

UNNAMED = "?"  # a mismatched clip's motion_item where the study file does not say whose interlocutor it had


class Dyadic(StimulusDesign):
    name = "dyadic"
    mismatched_folders = True

    def check(self, path, spec):
        super().check(path, spec)
        if spec.interlocutor is None:
            raise err(path, "design", "dyadic shows the agent beside its interlocutor: give the [interlocutor] table")
        lacking = [n for n in spec.conditions if n != spec.reference and n not in spec.mismatched]
        if lacking:
            raise err(
                path,
                f"[mismatched] {lacking[0]}",
                "missing: dyadic needs each system's motion made for a mismatched interlocutor (a folder each)",
            )

    def mismatched_clips(self, spec, motions, roles, people):
        out = []
        for item, role in roles.items():
            for name, by_item in people.mismatched.items():
                motion = by_item[item]
                made_for = people.made_for.get(item) or UNNAMED
                out.append(dict(condition=name, item=item, role=role, joints=motion.joints, motion_item=made_for,
                                path=motion.path))  # fmt: skip
        return out
