"""The gesture measures of a study (docs/metrics.md): which apply, each clip's value, each condition's.

- fgd: the Fréchet gesture distance (gesture_fgd) of a clip's chunks against the reference's chunks of the other
  items; a condition's, of its clips' chunks pooled against the whole reference's.
- beat_align: BeatAlign (gesture_timing) of a clip's motion against the onsets of the agent's own voice of its item
  (the sound it is shown with; in a two-person study that person's voice, not the mix).
- hellinger_{speed,accel}_{hands,arms,head}: the Hellinger distance (motion_histograms) of a clip's speed and
  acceleration histograms of a joint group against the reference's of the other items; a condition's, pooled
  against the whole reference's.
- diversity: the mean distance between a clip's encoder feature and those of the other items' clips of its
  condition (the same role, matched or mismatched alike); a condition's, the mean over every pair of its clips.
- listener_response (a study with the interlocutor's voice): gesture_timing's, per clip, and a condition's mean.

A condition's row is over its matched test clips (BAD's: its catch clips). The reference's own fgd and Hellinger
distances are against itself split in two halves of its items (a seeded draw): the floor a system's values are read
against, never 0 by construction. Each clip's value is against the reference without the clip's item, so the
reference's clips are not measured against themselves. A value that cannot be computed is nan, with its reason.
"""

import collections
from dataclasses import dataclass, field

import numpy as np

from moglow_eval.core import study

from . import gesture_fgd, gesture_timing, joint_groups, motion_histograms, voice
from .fmd import CHUNK, STRIDE

HELLINGER = {f"hellinger_{kind}_{g}": (kind, g) for kind in motion_histograms.KINDS for g in study.JOINT_GROUPS}
REFERENCE_ROLES = ("test", "training")  # the reference's clips: one per item (catch copies are a frame late)
# The settings of each measure, as measures.csv and the report's methods paragraph state them.
SETTINGS = {
    "fgd": (
        f"fmd's autoencoder, {gesture_fgd.HIDDEN} wide, on joint positions about the root with their velocities and "
        f"accelerations, trained on the reference ({gesture_fgd.STEPS} steps of {gesture_fgd.BATCH} chunks of "
        f"{CHUNK} frames, learning rate {gesture_fgd.LR:g}, the study's seed); features every {STRIDE} frames"
    ),
    "beat_align": (
        f"sigma {gesture_timing.SIGMA:g} s; motion beats at minima of the wrists' speed within "
        f"{gesture_timing.ORDER_S:.3g} s; spectral-flux onsets of the agent's voice in {voice.HOP_S * 1000:g} ms "
        "frames, backtracked"
    ),
    **{
        name: (
            f"{motion_histograms.SPEED_BINS} bins of {motion_histograms.SPEED_STEP:g} m/s"
            if kind == "speed"
            else f"{motion_histograms.ACCEL_BINS} bins of {motion_histograms.ACCEL_STEP:g} m/s^2"
        )
        + " of the group's joints about the root, the last bin open"
        for name, (kind, _) in HELLINGER.items()
    },
    "diversity": "Euclidean distance between clips' mean encoder features (the fgd's encoder)",
    "listener_response": (
        f"head and hand speed about the root; speech where a voice is within {voice.GATE_DB:g} dB of its loud "
        f"frames, pauses under {voice.BRIDGE_S:g} s bridged; at least {gesture_timing.MIN_SPAN_S:g} s of each"
    ),
}


@dataclass
class Clip:
    condition: str  # as the manifest names it (the reference NAT, catch clips BAD)
    role: str
    item: str  # whose sound it is shown with
    matched: bool  # its condition's own motion of its item (not a mismatched clip)
    joints: np.ndarray


@dataclass
class Voices:
    """Each item's voices: mono samples at `rate` from the item's first frame; `other` empty for one voice."""

    rate: int
    agent: dict = field(default_factory=dict)
    other: dict = field(default_factory=dict)


def plan(names, sound, two_voices):
    """{measure: None where it applies, else why it is skipped} over study.GESTURE_METRIC_NAMES."""
    found = joint_groups.groups(names)
    out = {"fgd": None, "diversity": None}
    out["beat_align"] = None if sound else "the study has no sound"
    if sound and not joint_groups.wrists(names):
        out["beat_align"] = "no hand or wrist joint found by name"
    for name, (_, group) in HELLINGER.items():
        out[name] = None if group in found else f"no {group} joint found by name"
    out["listener_response"] = None if two_voices else "needs two voices (a two-person study with both)"
    if two_voices and not (found.get("head") or found.get("hands")):
        out["listener_response"] = "no head or hand joint found by name"
    return {m: out[m] for m in study.GESTURE_METRIC_NAMES}


@dataclass
class Result:
    clips: list  # one {measure: value} per clip, in the clips' order
    conditions: list  # one row per condition: condition, n_clips, each measure
    reasons: dict  # {measure: Counter of why clips have none}


def measure(clips, names, parents, fps, voices, applies, seed=0, cache=None):
    """The gesture measures of every clip and condition (see the module's docstring); `applies` from plan()."""
    on = [m for m in study.GESTURE_METRIC_NAMES if applies[m] is None]
    values = [dict.fromkeys(study.GESTURE_METRIC_NAMES, float("nan")) for _ in clips]
    reasons = collections.defaultdict(collections.Counter)
    ref = [k for k, c in enumerate(clips) if c.condition == study.NATURAL and c.matched and c.role in REFERENCE_ROLES]
    state = _State(clips, ref, names, parents, fps, seed)
    if {"fgd", "diversity"} & set(on):
        state.encode(cache, reasons)
    for name in [m for m in on if m in HELLINGER]:
        state.hellinger(name, values, reasons)
    if state.features is not None:
        state.clip_fgd(values, reasons)
        state.clip_diversity(values, reasons)
    heard = _Heard(voices)  # each item's voices read once, whichever of its clips asks first
    for k, c in enumerate(clips):
        if "beat_align" in on:
            _timed(values[k], reasons, "beat_align", gesture_timing.clip_beat_align, c.joints, fps, names, parents,
                   heard.onsets(c.item))  # fmt: skip
        if "listener_response" in on:
            _timed(values[k], reasons, "listener_response", gesture_timing.listener_response, c.joints, fps, names,
                   parents, *heard.speaking(c.item))  # fmt: skip
    return Result(values, state.condition_rows(values, on), dict(reasons))


class _Heard:
    """Each item's onsets and speech, from its voices, computed once."""

    def __init__(self, voices):
        self.voices, self.found = voices, {}

    def _get(self, key, compute):
        if key not in self.found:
            self.found[key] = compute()
        return self.found[key]

    def onsets(self, item):
        return self._get(
            ("onsets", item), lambda: voice.onsets(self.voices.agent.get(item, np.zeros(0)), self.voices.rate)
        )

    def speaking(self, item):
        v = self.voices
        return self._get(("speaking", item), lambda: tuple(voice.speaking(who.get(item, np.zeros(0)), v.rate)
                                                           for who in (v.agent, v.other)))  # fmt: skip


def _timed(row, reasons, name, fn, *args):
    try:
        row[name] = fn(*args)
    except gesture_timing.Undefined as e:
        reasons[name][str(e)] += 1


class _State:
    """What the measures of one study share: the reference's clips, their features and histograms by item."""

    def __init__(self, clips, ref, names, parents, fps, seed):
        self.clips, self.ref, self.names, self.parents, self.fps, self.seed = clips, ref, names, parents, fps, seed
        self.groups = joint_groups.groups(names)
        self.features = None  # [chunk features per clip], with the encoder
        self.hists = {}  # {(kind, group): [counts per clip]}

    def ref_items(self):
        return sorted({self.clips[k].item for k in self.ref})

    def halves(self):
        """The reference's items in two seeded halves (the floor of the reference's own values)."""
        items = self.ref_items()
        order = [items[i] for i in np.random.default_rng(self.seed).permutation(len(items))]
        return set(order[: len(order) // 2]), set(order[len(order) // 2 :])

    def encode(self, cache, reasons):
        long_enough = [k for k in self.ref if len(self.clips[k].joints) >= CHUNK]
        if len(long_enough) < 2:
            why = f"fewer than two reference clips of {CHUNK} frames or more to train the encoder on"
            for name in ("fgd", "diversity"):
                reasons[name][why] += len(self.clips)
            return
        encoder = gesture_fgd.GestureEncoder.train(
            [self.clips[k].joints for k in long_enough], self.parents, self.fps, seed=self.seed, cache=cache
        )
        self.features = [encoder.features(c.joints) for c in self.clips]

    def _by_item(self, per_clip, add):
        """{item: the reference's sum of per_clip values of that item}, and the total (the values add)."""
        out = {}
        for k in self.ref:
            item = self.clips[k].item
            out[item] = per_clip[k] if item not in out else add(out[item], per_clip[k])
        total = None
        for v in out.values():
            total = v if total is None else add(total, v)
        return out, total

    def clip_fgd(self, values, reasons):
        moments = [gesture_fgd.moments(f) for f in self.features]
        by_item, total = self._by_item(moments, _add_moments)
        for k, c in enumerate(self.clips):
            ref = _less(total, by_item.get(c.item), _sub_moments)
            if len(self.features[k]) < 2 or ref[0] < 2:
                reasons["fgd"][f"under two chunks of {CHUNK} frames in the clip or the reference"] += 1
                continue
            values[k]["fgd"] = gesture_fgd.frechet(gesture_fgd.gaussian(moments[k]), gesture_fgd.gaussian(ref))

    def clip_diversity(self, values, reasons):
        means = [f.mean(axis=0) if len(f) else None for f in self.features]
        for k, c in enumerate(self.clips):
            others = [
                means[i]
                for i, o in enumerate(self.clips)
                if (o.condition, o.role, o.matched) == (c.condition, c.role, c.matched)
                and o.item != c.item
                and means[i] is not None
            ]
            if means[k] is None or not others:
                reasons["diversity"]["no other item's clip of its condition and role to compare with"] += 1
                continue
            values[k]["diversity"] = float(np.mean(np.linalg.norm(np.array(others) - means[k], axis=1)))

    def hellinger(self, name, values, reasons):
        kind, group = HELLINGER[name]
        counts = [motion_histograms.histograms(c.joints, self.fps, self.groups[group], self.parents)[kind]
                  for c in self.clips]  # fmt: skip
        self.hists[name] = counts
        by_item, total = self._by_item(counts, np.add)
        for k, c in enumerate(self.clips):
            ref = _less(total, by_item.get(c.item), np.subtract)
            value = motion_histograms.hellinger(counts[k], ref) if ref is not None else float("nan")
            if np.isfinite(value):
                values[k][name] = value
            else:
                reasons[name]["no reference motion of another item, or a clip under three frames"] += 1

    def condition_rows(self, values, on):
        """One row per condition (study.condition_order): its clips' pooled or mean values."""
        rows = []
        conditions = study.condition_order(c.condition for c in self.clips)
        for cond in conditions:
            role = study.ROLES[1] if cond == study.CATCH else study.ROLES[0]
            idx = [k for k, c in enumerate(self.clips) if c.condition == cond and c.role == role and c.matched]
            if not idx:
                continue
            row = {"condition": cond, "n_clips": len(idx), **dict.fromkeys(study.GESTURE_METRIC_NAMES, float("nan"))}
            for name in on:
                row[name] = self._condition_value(name, cond, idx, values)
            rows.append(row)
        return rows

    def _condition_value(self, name, cond, idx, values):
        if name in ("beat_align", "listener_response"):
            found = [values[k][name] for k in idx if np.isfinite(values[k][name])]
            return float(np.mean(found)) if found else float("nan")
        if name == "diversity":
            if self.features is None:
                return float("nan")
            return gesture_fgd.diversity([self.features[k].mean(axis=0) for k in idx if len(self.features[k])])
        pool = self.features if name == "fgd" else self.hists.get(name)
        if pool is None:
            return float("nan")
        if cond == study.NATURAL:  # the floor: one half of the reference's items against the other
            a, b = self.halves()
            mine = [k for k in self.ref if self.clips[k].item in a]
            ref = [k for k in self.ref if self.clips[k].item in b]
        else:
            mine, ref = idx, self.ref
        if name == "fgd":
            return gesture_fgd.fgd(_stack([pool[k] for k in mine]), _stack([pool[k] for k in ref]))
        return motion_histograms.hellinger(sum(pool[k] for k in mine), sum(pool[k] for k in ref))


def _stack(features):
    return np.concatenate(features) if features else np.zeros((0, 0))


def _add_moments(a, b):
    return a[0] + b[0], a[1] + b[1], a[2] + b[2]


def _sub_moments(a, b):
    return a[0] - b[0], a[1] - b[1], a[2] - b[2]


def _less(total, part, sub):
    """The reference's total less one item's part (the whole where the item has none); None without a reference."""
    if total is None:
        return None
    return total if part is None else sub(total, part)
