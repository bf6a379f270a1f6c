"""The shared implementation of the designs whose trial shows several clips of one unit (pairwise, parallel,
appropriateness): units from the manifest, assignment by unit, trial clips labelled A, B, ..., and the dashboard's
per-unit figures. A design subclasses `UnitDesign` and adds its own units, answer, storage and export rows.

Catch units: every design pairs or pages a catch item's bad example with that item's NAT clip, which
make_stimuli writes with role `catch` for this (CONTRACTS §8); a catch item without it stops the start.
"""

from __future__ import annotations

from sqlalchemy import func, select

from moglow_eval.core import study

from ..pairing.assign import NO_TARGET, claim, cover, n_catch_slots, short_or_full, slots
from ..store.db import Clip, Trial
from ..store.manifest import AppError
from .base import Design, Unit


def by_item(clips, role) -> dict[str, dict[str, list[str]]]:
    """{item: {condition: [clip ids]}} of the clips of `role` that show their own item's motion."""
    out: dict[str, dict[str, list]] = {}
    for c in clips:
        if c.role == role and not c.motion_item:
            out.setdefault(c.item, {}).setdefault(c.condition, []).append(c.clip_id)
    return out


def check_comparable(design: str, item: str, by_cond: dict[str, list]) -> list[str]:
    """The conditions of a test item, sorted; AppError unless it has one clip of each and at least two."""
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
    return conds


class UnitDesign(Design):
    group_size = 2  # clips on a familiarisation trial pooled from items with too few training clips

    # ------------------------------------------------------------------------------------------ the units
    def build_units(self, clips):
        tests = by_item(clips, "test")
        if not tests:
            raise AppError("the manifest has no test clips")
        units = self.test_units(tests, clips)
        page_size = max((len(u.clips) for u in units.values()), default=0)  # a parallel test page's size
        for item, by_cond in sorted(by_item(clips, "catch").items()):
            if not by_cond.get(study.CATCH):
                continue
            if study.NATURAL not in by_cond:
                raise AppError(
                    f"{self.name}: catch item {item!r} has no {study.NATURAL} clip to compare its bad example "
                    "with; re-run generation.make_stimuli, which writes it (role catch)"
                )
            units.update(self.catch_units(item, by_cond, page_size))
        return units

    def test_units(self, tests: dict, clips) -> dict[str, Unit]:
        """The test units, from {item: {condition: [clip ids]}} of the test clips (and all clips)."""
        raise NotImplementedError

    def catch_units(self, item: str, by_cond: dict[str, list], page_size: int) -> dict[str, Unit]:
        """The units of one catch item, which has a bad example and a NAT clip."""
        raise NotImplementedError

    def cover_keys(self, clips, units):
        return list(units)

    def pool(self, clips, units):
        return sum(u.role == "test" for u in units.values()), sum(u.role == "catch" for u in units.values())

    def coverage(self, conn, units) -> dict[str, tuple[int, int]]:
        """{unit key: (answered trials, held slots)} for every test unit of this manifest."""
        cov = cover(conn)
        return {k: cov.get(k, (0, 0)) for k, u in units.items() if u.role == "test"}

    def is_full(self, conn, target, units):
        cov = self.coverage(conn, units)
        return bool(cov) and all(d >= target for d, _ in cov.values())

    # ------------------------------------------------------------------------------------------ assignment
    def item_groups(self, ids: list[str]) -> tuple[list[tuple[str, ...]], list[str]]:
        """(familiarisation trials made of one item's training clips, the clips left to pool with others')."""
        raise NotImplementedError

    def training_groups(self, clips, rng):
        """Familiarisation trials, in order: item_groups of each training item, then the clips left over pooled
        into trials of `group_size` (a lone clip is shown beside another training clip)."""
        training = sorted((c for c in clips if c.role == "training"), key=lambda c: c.clip_id)
        items: dict[str, list[str]] = {}
        for c in training:
            items.setdefault(c.item, []).append(c.clip_id)
        groups, single = [], []
        for ids in items.values():
            rng.shuffle(ids)
            made, left = self.item_groups(ids)
            groups += made
            single += left
        rng.shuffle(single)
        for i in range(0, len(single), self.group_size):
            chunk = tuple(single[i : i + self.group_size])
            if len(chunk) == 1 and len(training) > 1:
                chunk = (chunk[0], rng.choice([c.clip_id for c in training if c.clip_id != chunk[0]]))
            groups.append(chunk)
        rng.shuffle(groups)
        return groups

    def plan(self, conn, rng, cfg, clips, units):
        cov = self.coverage(conn, units)
        short = short_or_full(cov, cfg["RATINGS_PER_CLIP"], "comparison", "answers", "answered")
        per_rater = cfg["CLIPS_PER_RATER"]
        n_test = short if not per_rater else min(per_rater, short)
        pool = sum(u.role == "catch" for u in units.values())
        training = [("training", g) for g in self.training_groups(clips, rng)]
        return training + slots(rng, n_test, n_catch_slots(pool, cfg["CATCH_PER_RATER"]))

    def assign(self, conn, rng, rater_pk, kind, target, units, wait=False):
        """As acr's assignment, whose rules it follows; both kinds run the same statements."""
        keys = sorted(k for k, u in units.items() if u.role == kind)
        key = claim(conn, keys, "unit", rater_pk, target if kind == "test" else NO_TARGET, wait)
        return units[key] if key is not None else None

    def payload(self, clips):
        return {"design": self.name, "clips": clips}

    # ------------------------------------------------------------------------------------------ dashboard
    def per_condition(self, units, conditions: dict, rows, target) -> dict:
        """The dashboard's per-condition rows, each with "_sum" (the sum its mean divides), from the export rows."""
        raise NotImplementedError

    def answers(self, rows):
        """(rater_id, failed a catch trial, flags) per answer, from the export rows."""
        raise NotImplementedError

    def catch_answers(self, rows):
        return ((rid, failed) for rid, failed, _ in self.answers(rows))

    def progress(self, s, target, units):
        conditions = dict(s.execute(select(Clip.clip_id, Clip.condition)).all())
        counts = _unit_counts(s)
        rows = list(self.export_rows(s))
        per_unit = [
            {
                "clip_id": key,
                "condition": " / ".join(conditions.get(c, "?") for c in u.clips),
                "role": u.role,
                "item": u.item,
                "ratings": counts["done"].get(key, 0),
                "in_progress": counts["pending"].get(key, 0),
                "target": target if u.role == "test" else None,
                "mean": None,
            }
            for key, u in sorted(units.items(), key=lambda kv: (kv[1].role != "test", kv[0]))
        ]
        per_cond = self.per_condition(units, conditions, rows, target)
        for d in per_cond.values():
            d["mean"] = round(d.pop("_sum") / d["ratings"], 2) if d["ratings"] else None
        out = {"per_clip": per_unit, "per_condition": list(per_cond.values())}
        out.update(answers={}, fails={}, no_video={}, partial_video={})
        for rid, failed, flags in self.answers(rows):
            counts = {
                "answers": 1,
                "fails": failed,
                "no_video": "no_video" in flags,
                "partial_video": "partial_video" in flags,
            }
            for key, add in counts.items():
                out[key][rid] = out[key].get(rid, 0) + add
        return out


def record_head(head, role) -> dict:
    """The first fields of a simulated crowd's record of an answer (Design.records)."""
    return {
        "rater_id": head["rater_id"],
        "external_id": head["external_id"],
        "trial_id": head["trial_id"],
        "role": role,
        "careless": head["careless"],
    }


def _unit_counts(s) -> dict[str, dict[str, int]]:
    """{"done": {unit: answered trials}, "pending": {unit: served, unanswered, live trials}}."""
    rated = (Trial.unit.is_not(None), Trial.kind != "training")
    done = select(Trial.unit, func.count()).where(*rated, Trial.answered_at.is_not(None)).group_by(Trial.unit)
    pending = (
        select(Trial.unit, func.count())
        .where(*rated, Trial.answered_at.is_(None), Trial.released.is_(False), Trial.served_at.is_not(None))
        .group_by(Trial.unit)
    )
    return {"done": dict(s.execute(done).all()), "pending": dict(s.execute(pending).all())}
