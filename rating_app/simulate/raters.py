"""The simulated raters' model: how good each clip looks to them, and the answers they can give (a rating, a
preference, a fit to the speech, a page of ratings); each design (rating_app/designs/) picks the one its page asks.

An attentive rater answers round(quality(clip) + bias + noise), clipped to the scale, with a personal bias and
noise level (acr, parallel); in a pairwise test its choice follows a Bradley-Terry model of the two clips'
qualities, its certainty (no preference, slightly, clearly) blurred by its noise level. It
recognises the bad examples (catch clips) as such: it rates them below CATCH_FAIL_AT (acr), never prefers them
(pairwise) and puts them below the page's NAT clip (parallel). A careless rater answers
uniformly at random in every design, and so fails catch trials.

The per-clip quality comes by default from metrics.csv (objective metrics farther from the reference's -> lower
quality; the condition nearest the reference gets QUALITY_HIGH, the farthest QUALITY_LOW), else from
DEFAULT_QUALITY, and can be set per condition. Only the manifest and metrics.csv say which condition a clip is:
the server never tells.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from moglow_eval.core import study
from moglow_eval.core.ranks import average_ranks
from moglow_eval.core.tables import read_metrics

from ..store.manifest import AppError, load_manifest

# The paper's order (MG above FL); a condition the metrics rank overrides these.
DEFAULT_QUALITY = {study.NATURAL: 4.2, **dict(zip(study.GENERATED, (3.6, 2.6))), study.CATCH: 1.3}
OTHER_QUALITY = 3.0  # an imported system without metrics, or a clip missing from the manifest
QUALITY_HIGH, QUALITY_LOW = 4.3, 1.3
BIAS_SD = 0.3
PREFERENCE_TIE, PREFERENCE_CLEAR = 0.3, 1.0  # quality margins: below the first no preference, above the second clear
# Pairwise choices follow Bradley-Terry on the qualities: log strength = BT_SCALE * quality, so A wins with
# probability 1 / (1 + exp(-BT_SCALE (quality A - quality B))) (one quality point: 88%; NAT over MG by default: 77%).
BT_SCALE = 2.0
# How sure a rater is of a choice: |2 P(A wins) - 1| plus its own noise (CERTAINTY_NOISE x its noise level); below
# TIE_BELOW it answers no preference, above CLEAR_ABOVE clearly, in between slightly.
TIE_BELOW, CLEAR_ABOVE, CERTAINTY_NOISE = 0.1, 0.5, 0.3
NOISE_SD = (0.35, 0.7)  # each rater's own noise level is drawn from this range
UNKNOWN_DURATION_MS = 2000  # a clip the manifest gives no frames/fps for


@dataclass
class ClipInfo:
    clip_id: str
    condition: str
    role: str
    duration_ms: int = UNKNOWN_DURATION_MS
    quality: float | None = None
    metrics: dict = field(default_factory=dict)  # metric name -> value; nan where not measured
    motion_item: str = ""  # appropriateness: a mismatched clip shows this other item's motion


def duration_ms(clip: ClipInfo | None) -> int:
    return clip.duration_ms if clip else UNKNOWN_DURATION_MS


def quality_of(clip: ClipInfo | None) -> float:
    return clip.quality if clip and clip.quality is not None else OTHER_QUALITY


def parse_quality(text: str | None) -> dict[str, float]:
    """--quality "NAT=4.3,MG=3.8" -> {condition: mean rating 1..5}."""
    out = {}
    for part in (text or "").split(","):
        if not part.strip():
            continue
        name, sep, value = part.partition("=")
        try:
            q = float(value)
        except ValueError:
            q = math.nan
        if not sep or not name.strip() or not 1.0 <= q <= 5.0:
            raise AppError(f"--quality: {part.strip()!r} must be CONDITION=NUMBER with 1 <= NUMBER <= 5")
        out[name.strip()] = q
    return out


def load_clips(manifest) -> dict[str, ClipInfo]:
    """The manifest's clips, with their metrics from metrics.csv beside it when there is one."""
    clips = {
        c.clip_id: ClipInfo(
            c.clip_id, c.condition, c.role, c.duration_ms or UNKNOWN_DURATION_MS, motion_item=c.motion_item
        )
        for c in load_manifest(manifest, check_files=False)
    }
    metrics_csv = Path(manifest).resolve().parent / "metrics.csv"
    if metrics_csv.is_file():
        table = read_metrics(metrics_csv, AppError)
        names = [m for m in study.METRIC_NAMES if m in table.columns]
        for cid, row in table[names].iterrows():
            if cid in clips:
                clips[cid].metrics = {m: float(row[m]) for m in names}
    return clips


def load_audio_answers(manifest) -> dict[str, str]:
    """{sha256 of a sound-check sample: its digits} from audio_check.csv beside the manifest ({} without one): the
    simulated raters 'hear' a sample by recognising its bytes."""
    import csv
    import hashlib

    base = Path(manifest).resolve().parent
    path = base / "audio_check.csv"
    if not path.is_file():
        return {}
    with open(path, newline="", encoding="utf-8") as f:
        return {hashlib.sha256((base / r["file"]).read_bytes()).hexdigest(): r["answer"] for r in csv.DictReader(f)}


def metric_distances(clips: list[ClipInfo], name: str) -> np.ndarray:
    """How far each clip's metric `name` is from the reference's (the median over the NAT clips, else over every
    clip): |log ratio|, each side shifted by a tenth of the metric's median so that a reference value of 0
    (bones of exactly constant length) stays finite; for a metric with negative values, the absolute difference
    in units of its standard deviation. NaN where the clip has no value. Far in either direction is
    worse: motion smoother (lower jerk) than the reference's is as unlike it as motion jerkier by the same ratio."""
    vals = np.array([c.metrics.get(name, np.nan) for c in clips], float)  # metrics hold floats, NaN unmeasured
    ok = np.isfinite(vals)
    ref_vals = vals[ok & np.array([c.condition == study.NATURAL for c in clips])]
    if not ref_vals.size:
        ref_vals = vals[ok]
    if not ref_vals.size:
        return np.full(len(clips), np.nan)
    ref = float(np.median(ref_vals))
    if (vals[ok] < 0).any():  # a signed metric: the distance in units of its spread
        return np.abs(vals - ref) / (float(np.std(vals[ok])) + 1e-12)
    shift = 0.1 * float(np.median(vals[ok])) + 1e-12
    return np.abs(np.log((vals + shift) / (ref + shift)))


def quality_from_metrics(clips: dict[str, ClipInfo]) -> dict[str, float]:
    """Per-condition quality from the clips' objective metrics; also sets a small per-clip offset.

    A clip's metrics count by how far they are from the reference's (metric_distances), never by how low they
    are: a heavily smoothed system has a low jerk, but not the reference's. Each metric's distance is turned
    into a percentile rank over all clips (0 = nearest the reference, 1 = farthest; ranks, so one extreme
    condition does not squash the others together); a clip's badness is its mean rank. Conditions are placed
    linearly between QUALITY_HIGH (least bad) and QUALITY_LOW (most bad) by mean badness."""
    have = [c for c in clips.values() if any(np.isfinite(c.metrics.get(m, np.nan)) for m in study.METRIC_NAMES)]
    if not have:
        return {}
    total = np.zeros(len(have))
    n = np.zeros(len(have))
    for m in study.METRIC_NAMES:
        vals = metric_distances(have, m)
        ok = np.isfinite(vals)
        if ok.sum() < 2 or np.ptp(vals[ok]) == 0:
            continue
        total[ok] += (average_ranks(vals[ok]) - 1) / (ok.sum() - 1)
        n[ok] += 1
    badness = np.where(n > 0, total / np.maximum(n, 1), 0.5)
    by_cond: dict[str, list[float]] = {}
    for c, b in zip(have, badness):
        by_cond.setdefault(c.condition, []).append(float(b))
    mean = {k: float(np.mean(v)) for k, v in by_cond.items()}
    lo, hi = min(mean.values()), max(mean.values())
    quality = {
        k: (QUALITY_HIGH + QUALITY_LOW) / 2
        if hi - lo < 1e-9
        else QUALITY_HIGH - (QUALITY_HIGH - QUALITY_LOW) * (b - lo) / (hi - lo)
        for k, b in mean.items()
    }
    for c, b in zip(have, badness):
        # Within a condition, worse clips are rated a little lower (at most 0.4 of a point).
        c.quality = quality[c.condition] - float(np.clip(1.5 * (b - mean[c.condition]), -0.4, 0.4))
    return quality


def set_qualities(clips: dict[str, ClipInfo], override: dict[str, float] | None) -> dict[str, float]:
    """Give every clip its quality (the metrics', else the default, --quality over both); the per-condition
    qualities used."""
    by_condition = dict(DEFAULT_QUALITY)
    by_condition.update(quality_from_metrics(clips))
    by_condition.update(override or {})
    for c in clips.values():
        if c.quality is None or (override and c.condition in override):
            c.quality = by_condition.get(c.condition, OTHER_QUALITY)
    return by_condition


# How much better, on the 1-5 quality scale, the motion made for the speech fits it than another item's motion:
# the simulated raters' appropriateness (real motion clearly, a system a little).
FIT = {study.NATURAL: 1.2}
FIT_SYSTEM = 0.4


@dataclass
class Rater:
    """One simulated rater: who it says it is to the server, and how it answers."""

    index: int
    external_id: str
    session_id: str  # as Prolific's link gives one: also the proof for resuming after a lost reply
    careless: bool
    bias: float
    noise_sd: float
    seed: int

    def __post_init__(self):
        self.rng = np.random.default_rng(self.seed)

    def watched(self, shown: list[ClipInfo | None]) -> int:
        """The watched_ms a rater reports for a trial of several clips: all of them, and a little more."""
        return int(sum(map(duration_ms, shown)) + self.rng.uniform(0, 300))

    def rate(self, clip: ClipInfo | None) -> tuple[int, int]:
        """An acr rating 1..5 and the watched_ms it reports (careless raters skip ahead)."""
        dur = duration_ms(clip)
        if self.careless:
            return int(self.rng.integers(1, 6)), int(dur * self.rng.uniform(0.2, 1.0))
        x = int(np.clip(round(quality_of(clip) + self.bias + self.rng.normal(0, self.noise_sd)), 1, 5))
        if clip is not None and clip.role == "catch":
            x = min(x, study.CATCH_FAIL_AT - 1)  # an attentive rater recognises a bad example
        return x, int(dur + self.rng.uniform(0, 300))

    def prefer(self, a: ClipInfo | None, b: ClipInfo | None) -> int:
        """A pairwise answer: 2 = A clearly .. -2 = B clearly. The side comes from Bradley-Terry on the two clips'
        qualities (bt_probability); how sure the rater is (tie, slightly, clearly) from how far that probability
        is from a half, blurred by the rater's own noise, and drawn apart from the side, so that among the answers
        that prefer one clip, A's share is exactly the model's probability."""
        if self.careless:
            return int(self.rng.integers(-2, 3))
        p = bt_probability(quality_of(a), quality_of(b))
        a_wins = self.rng.random() < p
        sure = abs(2.0 * p - 1.0) + self.rng.normal(0, CERTAINTY_NOISE * self.noise_sd)
        level = 0 if sure < TIE_BELOW else 1 if sure < CLEAR_ABOVE else 2
        pref = level if a_wins else -level
        if a is not None and b is not None and study.CATCH in (a.condition, b.condition):
            strength = abs(pref) or 1  # never the bad example, never a tie with it
            pref = strength if b.condition == study.CATCH else -strength
        return pref

    def prefer_fit(self, a: ClipInfo | None, b: ClipInfo | None) -> int:
        """An appropriateness answer: 2 = A fits the speech clearly better .. -2 = B. The motion made for the speech
        fits by FIT[condition] (real motion best); a catch pair is answered as in pairwise."""
        if a is None or b is None or study.CATCH in (a.condition, b.condition) or self.careless:
            return self.prefer(a, b)
        fit = FIT.get(a.condition, FIT_SYSTEM)
        d = (0 if a.motion_item else fit) - (0 if b.motion_item else fit) + self.rng.normal(0, self.noise_sd)
        level = 0 if abs(d) < PREFERENCE_TIE else 1 if abs(d) < PREFERENCE_CLEAR else 2
        return level if d > 0 else -level

    def page(self, shown: list[ClipInfo | None]) -> list[int]:
        """Parallel ratings 0..100 of the clips of one page, in order (the 1..5 quality scaled)."""
        if self.careless:
            return [int(self.rng.integers(0, 101)) for _ in shown]
        out = [
            int(np.clip(round(25.0 * (quality_of(c) + self.bias + self.rng.normal(0, self.noise_sd) - 1.0)), 0, 100))
            for c in shown
        ]
        conds = [c.condition if c else None for c in shown]
        if study.CATCH in conds and study.NATURAL in conds:
            _below_natural(out, conds)
        return out

    def think(self, mean_s: float) -> float:
        """A pause before answering, seconds (exponential with mean `mean_s`)."""
        return float(self.rng.exponential(mean_s)) if mean_s else 0.0


def _below_natural(ratings: list[int], conds: list[str | None]) -> None:
    """An attentive rater puts the bad example below the natural clip of its page."""
    at = conds.index(study.NATURAL)
    nat = ratings[at]
    for i, cond in enumerate(conds):
        if cond == study.CATCH and study.page_catch_failed(ratings[i], nat):
            ratings[i] = max(0, nat - 10)
            if nat == 0:
                ratings[at] = 10


def bt_probability(quality_a: float, quality_b: float) -> float:
    """The chance a simulated rater prefers A: Bradley-Terry with log strengths BT_SCALE x quality."""
    return 1.0 / (1.0 + math.exp(-BT_SCALE * (quality_a - quality_b)))


def make_raters(n: int, seed: int, careless: float, prefix: str) -> list[Rater]:
    """`n` raters, round(careless * n) of them careless, each with its own bias, noise and random stream."""
    rng = np.random.default_rng(seed)
    n_careless = int(round(careless * n))
    careless_set = set(rng.choice(n, size=n_careless, replace=False).tolist()) if n_careless else set()
    raters = []
    for i in range(n):
        external_id = f"{prefix}-{i:05d}"
        session_id = f"{external_id}-{int(rng.integers(2**62)):x}"
        bias = float(rng.normal(0, BIAS_SD))
        noise_sd = float(rng.uniform(*NOISE_SD))
        raters.append(Rater(i, external_id, session_id, i in careless_set, bias, noise_sd, int(rng.integers(2**31))))
    return raters
