"""The other files of a two-person or dyadic study: the real interlocutor of each item, and each condition's motion
made for a mismatched interlocutor.

`[interlocutor] folder` holds the real other person of every item (ITEM.npz in Seamless Interaction's layout,
BVH, .npy or any motion file a condition may hold; its own skeleton), shown beside every condition's clip of the
item. `[mismatched]` (design dyadic) names, per condition, a folder of the motion that condition made for the
item's agent speech with another person's behaviour as its interlocutor (GENEA 2023's mismatched condition): the
same skeleton as the condition's own, every item. Each is read and checked like a condition's files (one line
naming the file), and cut with the item (generation.own_study.builder.cut_items). The manifest's `motion_item`
of a dyadic mismatched clip is the item whose interlocutor that motion was made for, from the sources table's
`mismatched` column (the cutter's), else designs.dyadic.UNNAMED.
"""

import sys
from dataclasses import dataclass, field

from tqdm import tqdm

from moglow_eval.core import study

from ..data.motion_files import read_motion
from ..stimuli.files import StimuliError
from .inputs import check_same_skeleton, folder_files, read_options


@dataclass
class People:
    partners: dict = field(default_factory=dict)  # {item: Motion}: the real interlocutor
    mismatched: dict = field(default_factory=dict)  # {condition as in the manifest: {item: Motion}}
    made_for: dict = field(default_factory=dict)  # {item: the item whose interlocutor the mismatched motion had}

    def extra(self):
        """Every motion of these that is cut with its item: [{item: Motion}, ...]."""
        return [self.partners, *self.mismatched.values()]


def _files(name, folder, items, what):
    found = folder_files(name, folder)
    missing = [i for i in items if i not in found]
    if missing:
        raise StimuliError(f"{folder}: no file for item {missing[0]} ({what})")
    return {i: found[i] for i in items}


def read_people_motion(spec, reference, progress, sources=()):
    """People of a study: the interlocutors (with `[interlocutor]`) and the mismatched motion (with `[mismatched]`),
    `reference` {item: Motion} the reference condition's (as read), `sources` the rows of the sources table."""
    people = People()
    items = sorted(reference)
    jobs = []
    if spec.interlocutor is not None:
        jobs += [(None, i, p) for i, p in _files("interlocutor", spec.interlocutor, items, "the interlocutor").items()]
    for name, folder in spec.mismatched.items():
        label = study.NATURAL if name == spec.reference else name
        found = _files(name, folder, items, f"{name}'s motion for a mismatched interlocutor")
        jobs += [(label, i, p) for i, p in found.items()]
    options = read_options(spec)
    for label, item, path in tqdm(jobs, desc="read", unit="file", file=sys.stderr, disable=not progress or not jobs):
        m = read_motion(path, **options)
        if label is None:
            people.partners[item] = m
        else:
            check_same_skeleton(m, reference[item])
            people.mismatched.setdefault(label, {})[item] = m
    people.made_for = {r["item"].strip(): r.get("mismatched", "").strip() for r in sources if r.get("mismatched")}
    return people
