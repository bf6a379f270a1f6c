"""The three test designs (CONTRACTS §8) and the units a study balances over.

A study's design decides what one trial shows and what its answer is:
- `acr`: one clip, a rating 1..5 (CONTRACTS §5-6; the unit is the clip);
- `pairwise`: two clips of one item from two conditions, labelled A and B, a preference -2..2; the unit is
  (item, condition pair), so every pair of conditions of every item reaches its target separately;
- `parallel`: every condition's clip of one item on one page (MUSHRA-like), labelled A, B, C..., a rating 0..100
  each; the unit is the item (its page);
- `appropriateness` (GENEA 2023): two clips of one system with the same item's speech, the motion it made for that
  speech and the motion it made for another item's (the manifest's `motion_item`), a preference -2..2 as in
  pairwise; the unit is (item, condition). Its catch units are pairwise's.
A manifest with appropriateness clips (a `motion_item`) serves the other designs too: `serving_clips` leaves the
mismatched clips out of them, so one stimulus set holds GENEA's human-likeness and appropriateness tests.
Units are derived from the manifest alone (the same on every worker and after every restart), and named by a key
that is stored with each trial, so coverage is counted per unit in the database.

Catch units: pairwise pairs each BAD clip of a catch item with the NAT clip of the same item; a parallel catch
page holds the catch item's NAT and BAD clips, filled up with its other conditions' clips to the size of a test
page, so that a page's size never tells a catch page. make_stimuli writes NAT, MG and FL clips of each catch
item with role `catch` for this; in `acr` only the bad examples (condition BAD) are catch trials.
"""

from __future__ import annotations

import random
from dataclasses import dataclass

from core import study

from .manifest import AppError

MAX_PAGE = 8  # clips on a parallel page (labels A..H)
LABELS = "ABCDEFGH"
# The JSON field that carries a trial's answer, in the API (CONTRACTS §8) and so in the simulated crowd.
ANSWER_FIELD = {"acr": "rating", "pairwise": "preference", "parallel": "ratings", "appropriateness": "preference"}
QUESTIONS = {
    "acr": "How natural does this motion look?",
    "pairwise": "Which motion looks more natural?",
    "parallel": "How natural does each motion look?",
    "appropriateness": "Which motion fits the speech better?",
}


@dataclass(frozen=True)
class Unit:
    key: str  # stored in trials.unit
    role: str  # test | catch
    item: str
    clips: tuple[str, ...]  # clip ids (shuffled per trial when served)


def check_design(design: str | None) -> str:
    design = (design or "acr").strip()
    if design not in study.DESIGNS:
        raise AppError(f"design {design!r} must be one of {', '.join(study.DESIGNS)}")
    return design


def acr_catch(clip) -> bool:
    """A catch trial of an acr study: a bad example, never the other clips a catch item also holds."""
    return clip.role == "catch" and clip.condition == study.CATCH


def serving_clips(design: str, clips) -> list:
    """The manifest's clips a study of `design` serves: all of them in appropriateness, the others without the
    mismatched clips (those showing another item's motion)."""
    return list(clips) if design == "appropriateness" else [c for c in clips if not c.motion_item]


def _by_item(clips, role):
    out: dict[str, dict[str, list]] = {}
    for c in clips:
        if c.role == role and not c.motion_item:
            out.setdefault(c.item, {}).setdefault(c.condition, []).append(c.clip_id)
    return out


def _mismatched(clips):
    """{(item, condition): clip id} of the test clips showing another item's motion."""
    return {(c.item, c.condition): c.clip_id for c in clips if c.role == "test" and c.motion_item}


def build_units(design: str, clips) -> dict[str, Unit]:
    """{key: Unit} of the test and catch units of a pairwise or parallel study; AppError when the manifest cannot
    make that design (an item with one condition, a page over MAX_PAGE, a catch item without its NAT clip)."""
    if design == "acr":
        return {}
    tests = _by_item(clips, "test")
    if not tests:
        raise AppError("the manifest has no test clips")
    units: dict[str, Unit] = {}
    if design == "appropriateness":
        units.update(_appropriateness_units(tests, _mismatched(clips)))
    else:
        for item, by_cond in sorted(tests.items()):
            units.update(_test_units(design, item, by_cond))
    page_size = max((len(u.clips) for u in units.values()), default=0)  # parallel: every test page's size
    for item, by_cond in sorted(_by_item(clips, "catch").items()):
        units.update(_catch_units(design, item, by_cond, page_size))
    return units


def _test_units(design: str, item: str, by_cond: dict[str, list]) -> dict[str, Unit]:
    """The units of one test item: every pair of its conditions (pairwise) or its page (parallel)."""
    twice = [c for c, ids in by_cond.items() if len(ids) > 1]
    if twice:
        raise AppError(
            f"{design}: item {item!r} has {len(by_cond[twice[0]])} test clips of condition "
            f"{twice[0]}; a {design} study needs one clip per condition and item"
        )
    conds = sorted(by_cond)
    if len(conds) < 2:
        raise AppError(
            f"{design}: item {item!r} has test clips of one condition only ({conds[0]}); comparisons need at least two"
        )
    if design == "pairwise":
        keys = {(a, b): f"pair:{item}:{a}:{b}" for i, a in enumerate(conds) for b in conds[i + 1 :]}
        return {key: Unit(key, "test", item, (by_cond[a][0], by_cond[b][0])) for (a, b), key in keys.items()}
    if len(conds) > MAX_PAGE:
        raise AppError(f"parallel: item {item!r} has {len(conds)} conditions; a page shows at most {MAX_PAGE}")
    return {f"page:{item}": Unit(f"page:{item}", "test", item, tuple(by_cond[c][0] for c in conds))}


def _appropriateness_units(tests, mismatched) -> dict[str, Unit]:
    """One unit per test item and condition: its matched clip beside its mismatched one."""
    if not mismatched:
        raise AppError(
            "appropriateness: the manifest has no mismatched clips (a motion_item column); build the stimuli with "
            'design = "appropriateness" in the study file'
        )
    units = {}
    for item, by_cond in sorted(tests.items()):
        for cond, ids in sorted(by_cond.items()):
            if (item, cond) not in mismatched:
                raise AppError(f"appropriateness: item {item!r} has no mismatched clip of condition {cond}")
            key = f"fit:{item}:{cond}"
            units[key] = Unit(key, "test", item, (ids[0], mismatched[(item, cond)]))
    return units


def _catch_units(design: str, item: str, by_cond: dict[str, list], page_size: int) -> dict[str, Unit]:
    """The units of one catch item: each bad example beside the item's NAT clip (pairwise), or one page of NAT,
    the bad example and the item's other clips, as many as a test page holds (parallel)."""
    bads = by_cond.get(study.CATCH, [])
    if not bads:
        return {}
    if study.NATURAL not in by_cond:
        raise AppError(
            f"{design}: catch item {item!r} has no {study.NATURAL} clip to compare its bad example "
            "with; re-run generation.make_stimuli, which writes it (role catch)"
        )
    nat = by_cond[study.NATURAL][0]
    if design in study.PAIR_DESIGNS:
        return {f"catch:{item}:{k}": Unit(f"catch:{item}:{k}", "catch", item, (nat, bad)) for k, bad in enumerate(bads)}
    fillers = [ids[0] for cond, ids in sorted(by_cond.items()) if cond not in (study.NATURAL, study.CATCH)]
    page = (nat, bads[0], *fillers)[: max(2, page_size)]
    return {f"catchpage:{item}": Unit(f"catchpage:{item}", "catch", item, page)}


def training_groups(design: str, clips, rng: random.Random) -> list[tuple[str, ...]]:
    """Familiarisation trials of a session, in order: acr one clip each; pairwise two clips (of the same item
    where an item has two, else two different clips); parallel one page per training item (items with a single
    clip are pooled into pages of up to MAX_PAGE)."""
    training = sorted((c for c in clips if c.role == "training"), key=lambda c: c.clip_id)
    if design == "acr":
        ids = [c.clip_id for c in training]
        rng.shuffle(ids)
        return [(c,) for c in ids]
    by_item: dict[str, list[str]] = {}
    for c in training:
        by_item.setdefault(c.item, []).append(c.clip_id)
    groups, single = [], []
    for ids in by_item.values():
        rng.shuffle(ids)
        if design in study.PAIR_DESIGNS:
            while len(ids) >= 2:
                groups.append((ids.pop(), ids.pop()))
            single += ids
        elif len(ids) >= 2:
            groups.append(tuple(ids[:MAX_PAGE]))
        else:
            single += ids
    rng.shuffle(single)
    size = 2 if design in study.PAIR_DESIGNS else MAX_PAGE
    for i in range(0, len(single), size):
        chunk = tuple(single[i : i + size])
        if len(chunk) == 1 and len(training) > 1:  # a lone clip is shown beside another training clip
            chunk = (chunk[0], rng.choice([c.clip_id for c in training if c.clip_id != chunk[0]]))
        groups.append(chunk)
    rng.shuffle(groups)
    return groups


def required_ms(design: str, durations: list[int]) -> int:
    """How long the clips of one trial take to play to the end: in pairwise the two clips can play at once
    (side by side on a wide screen), so the longer one; a parallel page plays one clip at a time, so the sum, and
    so do an appropriateness pair's clips, heard one after the other with their speech."""
    if not durations:
        return 0
    return sum(durations) if design in ("parallel", "appropriateness") else max(durations)
