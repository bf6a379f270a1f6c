"""What a test design asks of a study of your own motion (CONTRACTS §10): one small interface, which each design that
needs stimuli of its own implements. The study file's reader (study_file.py, study_people.py), the caption reader
(speech.py) and the builder (builder.py) ask the study's design, never its name; the designs that need nothing of
their own (acr, pairwise, parallel) have no module here.
"""

from __future__ import annotations

import numpy as np

from moglow_eval.core import study

from ..study_keys import err


class StimulusDesign:
    """One design's stimuli. Class attributes name its needs; methods check a study file and make its clips."""

    name = ""  # as moglow_eval.core.study.DESIGNS spells it
    # What a rater judges, for the message when the study file lacks [audio] (every design here asks about speech).
    judges = "whether motion fits its speech"
    mismatched_folders = False  # [mismatched]: per condition, its motion made for a mismatched interlocutor
    highlights_keyword = False  # every item's keyword must be among its words (speech.item_captions)

    def check(self, path, spec) -> None:
        """What this design needs of the rest of the study file; err(...), one line, for what is missing."""
        if spec.audio_folder is None:
            raise err(path, "design", f"{self.name} asks {self.judges}: give the [audio] table")

    def mismatched_clips(self, spec, motions, roles, people) -> list[dict]:
        """The design's mismatched clips, as builder.StudyClip's keywords: `motions` {condition: {item: Motion}},
        `roles` {item: role}, `people` the two-person inputs (dyad.read_people_motion)."""
        return []


class OtherItemDesign(StimulusDesign):
    """A design whose mismatched clip is another item's motion under this item's speech (appropriateness, semantic):
    each condition's motion for a partner item, cut or held to this item's length."""

    def mismatched_clips(self, spec, motions, roles, people):
        partners = mismatch_partners(motions, sorted(roles), spec.seed)
        out = []
        for item, role in roles.items():
            n = len(motions[study.NATURAL][item].joints)
            for name, by_item in motions.items():
                joints = _fit(by_item[partners[item]].joints, n)
                out.append(dict(condition=name, item=item, role=role, joints=joints, motion_item=partners[item]))
        return out


def mismatch_partners(motions, items, seed):
    """{item: partner}: for each item, another item whose motion is shown with its speech. Seeded; never the item
    itself; a partner at least as long as the item where one exists (its motion is cut to the item's length), else
    the longest other item (its last pose held to the item's length)."""
    rng = np.random.default_rng(seed + 7919)
    length = {i: len(motions[study.NATURAL][i].joints) for i in items}
    out = {}
    for i in items:
        longer = [j for j in items if j != i and length[j] >= length[i]]
        out[i] = str(rng.choice(longer)) if longer else max((j for j in items if j != i), key=length.get)
    return out


def _fit(joints, n):
    """joints cut, or held at their last frame, to n frames."""
    return joints[:n] if len(joints) >= n else np.concatenate([joints, np.repeat(joints[-1:], n - len(joints), 0)])
