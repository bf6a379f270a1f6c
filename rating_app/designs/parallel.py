"""parallel (CONTRACTS §8, MUSHRA-like as HEMVIP): every condition's clip of one item on one page, labelled A, B,
C..., a rating 0..100 each; the unit is the item (its page).

A catch page holds a catch item's NAT clip and bad example, filled up with its other conditions' clips to the
size of a test page, so that a page's size never tells a catch page; failing it is rating the bad example at or
above the NAT clip. The clips play one at a time, so the viewing rule counts the sum of their durations. The
export is a ratings.csv with one row per clip rated, `page_id` naming the page.
"""

from __future__ import annotations

from flask import abort
from sqlalchemy import insert, select

from moglow_eval.core import study

from ..guard.bodies import int_field
from ..store.db import Clip, PageRating, Rater, Trial, TrialClip
from ..store.manifest import AppError
from .base import MAX_PAGE, Unit, new_condition_row
from .export_cells import RATER_EXTRA, TAIL, common
from .units import UnitDesign, check_comparable, record_head

COLUMNS = ("rater_id", "page_id", "item", "clip_id", "condition", "rating", "role", *TAIL)


class Parallel(UnitDesign):
    name = "parallel"
    answer_field = "ratings"
    question = "How natural does each motion look?"
    export_file = "ratings.csv"
    export_noun = "clip ratings of parallel pages"
    columns = COLUMNS
    group_size = MAX_PAGE
    page = "page"
    dashboard = {
        **UnitDesign.dashboard,
        "note": " (every condition of an item on one page, 0-100; targets per page)",
        "units": "pages",
        "per_unit": "page",
    }

    # ------------------------------------------------------------------------------------------ the units
    def test_units(self, tests, clips):
        units = {}
        for item, by_cond in sorted(tests.items()):
            conds = check_comparable(self.name, item, by_cond)
            if len(conds) > MAX_PAGE:
                raise AppError(f"parallel: item {item!r} has {len(conds)} conditions; a page shows at most {MAX_PAGE}")
            units[f"page:{item}"] = Unit(f"page:{item}", "test", item, tuple(by_cond[c][0] for c in conds))
        return units

    def catch_units(self, item, by_cond, page_size):
        nat, bad = by_cond[study.NATURAL][0], by_cond[study.CATCH][0]
        fillers = [ids[0] for cond, ids in sorted(by_cond.items()) if cond not in (study.NATURAL, study.CATCH)]
        page = (nat, bad, *fillers)[: max(2, page_size)]
        return {f"catchpage:{item}": Unit(f"catchpage:{item}", "catch", item, page)}

    def item_groups(self, ids):
        """One page per training item (an item with a single clip is pooled into pages of up to MAX_PAGE)."""
        return ([tuple(ids[:MAX_PAGE])], []) if len(ids) >= 2 else ([], list(ids))

    # ----------------------------------------------------------------------------------- a trial, its answer
    def required_ms(self, durations):
        return sum(durations)

    def parse_answer(self, body, shown):
        ratings = body.get("ratings")
        if not isinstance(ratings, dict):
            abort(400, "field 'ratings' must be an object {clip_id: rating 0-100} for every clip of the page")
        want = {r.clip_id for r in shown}
        if set(ratings) != want:
            abort(400, "field 'ratings' must rate every clip of the page, and only those")
        return {cid: int_field(ratings, cid, 0, 100) for cid in sorted(want)}

    def store(self, conn, trial, rater_pk, shown, value, watched_ms, now, flags):
        rows = [
            {
                "trial_pk": trial.id,
                "rater_pk": rater_pk,
                "clip_id": cid,
                "rating": v,
                "watched_ms": watched_ms,
                "submitted_at": now,
                "flags": flags,
            }
            for cid, v in value.items()
        ]
        conn.execute(insert(PageRating), rows)

    def stored_answer(self, conn, trial_pk):
        q = select(PageRating.clip_id, PageRating.rating).where(PageRating.trial_pk == trial_pk)
        return dict(conn.execute(q).all()) or None

    # ---------------------------------------------------------------------------------- export, dashboard
    def export_rows(self, s):
        yield from iter_page_rows(s)

    def per_condition(self, units, conditions, rows, target):
        """Per condition and role."""
        per_cond = {}
        for u in units.values():
            for c in u.clips:
                cond = conditions.get(c, "?")
                d = per_cond.setdefault((cond, u.role), new_condition_row(cond, u.role))
                d["clips"] += 1
                d["target"] += target if u.role == "test" else 0
        for r in rows:
            d = per_cond.setdefault((r["condition"], r["role"]), new_condition_row(r["condition"], r["role"]))
            d["ratings"] += 1
            d["_sum"] += r["rating"]
        return per_cond

    def answers(self, rows):
        """One answer per page."""
        failed_pages, seen = page_failures(rows), set()
        for r in rows:
            if r["page_id"] not in seen:
                seen.add(r["page_id"])
                yield r["rater_id"], r["page_id"] in failed_pages, r["flags"]

    # --------------------------------------------------------------------------------- the simulated crowd
    def simulated_answer(self, rater, ids, shown):
        watched = rater.watched(shown)  # drawn before the answer, so a crowd's answers stay those of its seed
        return dict(zip(ids, rater.page(shown))), watched

    def catch_failed(self, ids, conditions, value):
        by = {c: value[i] for i, c in zip(ids, conditions)}
        if study.CATCH not in by or study.NATURAL not in by:
            return False
        return bool(study.page_catch_failed(by[study.CATCH], by[study.NATURAL]))

    def records(self, head, ids, shown, value, role):
        conds = [c.condition if c else None for c in shown]
        base = record_head(head, role)
        return [
            {**base, "page_id": f"p{head['trial_id']}", "clip_id": i, "condition": c, "rating": value[i]}
            for i, c in zip(ids, conds)
        ]


def page_failures(rows) -> set[str]:
    """Page ids of catch pages where a BAD clip got at least the NAT clip's rating."""
    pages: dict[str, dict[str, list[int]]] = {}
    for r in rows:
        if r["role"] == "catch":
            pages.setdefault(r["page_id"], {}).setdefault(r["condition"], []).append(r["rating"])
    both = {p: by for p, by in pages.items() if study.NATURAL in by and study.CATCH in by}
    return {p for p, by in both.items() if study.page_catch_failed(max(by[study.CATCH]), min(by[study.NATURAL]))}


def iter_page_rows(s):
    """The parallel ratings.csv (CONTRACTS §8): one row per clip rated, in the order the page showed them."""
    q = (
        select(
            Rater.rater_id,
            PageRating.trial_pk,
            Clip.item,
            PageRating.clip_id,
            Clip.condition,
            PageRating.rating,
            Trial.kind,
            Trial.index,
            PageRating.watched_ms,
            PageRating.submitted_at,
            *RATER_EXTRA,
            PageRating.flags,
            Rater.n_early,
        )
        .join(Trial, Trial.id == PageRating.trial_pk)
        .join(Rater, Rater.id == PageRating.rater_pk)
        .join(TrialClip, (TrialClip.trial_pk == PageRating.trial_pk) & (TrialClip.clip_id == PageRating.clip_id))
        .join(Clip, Clip.clip_id == PageRating.clip_id)
        .order_by(Rater.id, Trial.index, TrialClip.position)
    )
    for rater_id, trial_pk, item, clip_id, cond, rating, kind, *rest in s.execute(q):
        row = {
            "page_id": f"p{trial_pk}",
            "item": item,
            "clip_id": clip_id,
            "condition": cond,
            "rating": rating,
            "role": kind,
        }
        row.update(common(rater_id, *rest))
        yield row
