"""A stochastic system's samples (the manifest's `sample`, CONTRACTS §4): several clips of one condition, role,
item, shown motion and style that differ only in the sample of the system's output they show.

To the balancing they are one stimulus: the clip that stands for them (the first by sample name) is the clip or
the unit's clip that assignment counts, so a study with five samples per item needs no more answers than one with
one. Which sample a rater sees is drawn when a trial is served, from the study's secret seed (db.SAMPLE_SEED), the
rater and the unit, and stored with the trial (acr: `Trial.sample_clip`; a unit: its `TrialClip` rows hold the
drawn samples), so the export names the sample behind every answer. The same rater, unit and seed always draw
the same sample; nothing a rater receives names it (clip ids are opaque, and every sample of an item is one byte
size: CONTRACTS §4).
"""

from __future__ import annotations

import dataclasses
import hashlib
import hmac
from collections import defaultdict


def group(clips) -> tuple[list, dict[str, tuple[str, ...]]]:
    """(the clips with every clip's `sample_of` set, {standing clip id: its samples' clip ids, itself first}).
    A clip with no sample, or the only one of its kind, stands for itself and is not in the map."""
    kinds = defaultdict(list)
    for c in clips:
        if c.sample:
            kinds[(c.condition, c.role, c.item, c.motion_item, c.style)].append(c)
    of, samples = {}, {}
    for members in kinds.values():
        members.sort(key=lambda c: (len(c.sample), c.sample, c.clip_id))  # "2" before "10"
        head = members[0].clip_id
        for c in members:
            of[c.clip_id] = head
        if len(members) > 1:
            samples[head] = tuple(c.clip_id for c in members)
    return [dataclasses.replace(c, sample_of=of.get(c.clip_id, "")) for c in clips], samples


def standing(clips) -> list:
    """The clips that the balancing counts: every clip but the other samples of one that stands for them."""
    return [c for c in clips if not c.sample_of or c.sample_of == c.clip_id]


def draw(seed: str, rater_pk: int, unit: str, clip_id: str, samples: dict[str, tuple[str, ...]]) -> str:
    """The clip a rater is shown for `clip_id` in `unit` (a unit's key, or the clip itself): one of its samples,
    drawn by an HMAC of the rater and the unit under the study's seed; `clip_id` itself where it has none."""
    choices = samples.get(clip_id)
    if not choices:
        return clip_id
    mac = hmac.new(seed.encode(), f"{rater_pk}\0{unit}\0{clip_id}".encode(), hashlib.sha256).digest()
    return choices[int.from_bytes(mac[:8], "big") % len(choices)]
