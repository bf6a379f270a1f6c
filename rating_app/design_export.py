"""pairs.csv and the parallel ratings.csv (CONTRACTS §8), and the dashboard's figures for those designs.

One row per pairwise answer (A = the clip that rater saw as A) or per clip rated on a parallel page, with the same
extra columns and flags as the acr export (export.py), formula-safe cells included. A catch trial is failed by
preferring the BAD clip at either level (pairwise), or by rating the BAD clip at or above the page's NAT clip
(parallel); the dashboard counts those failures per rater.
"""

from __future__ import annotations

from sqlalchemy import func, select
from sqlalchemy.orm import Session, aliased

from core.study import CATCH, NATURAL, page_catch_failed, pair_catch_failed

from .db import Clip, PageRating, Preference, Rater, Trial, TrialClip

PAIR_COLUMNS = (
    "rater_id",
    "item",
    "clip_a",
    "clip_b",
    "condition_a",
    "condition_b",
    "preference",
    "role",
    "trial_index",
    "watched_ms",
    "submitted_at",
    "external_id",
    "study_id",
    "rater_completed",
    "flags",
)
# appropriateness: pairs.csv's columns, and which side shows the motion made for the speech heard (a or b; empty
# on catch rows) and the item whose motion the other side shows (CONTRACTS §8).
FIT_COLUMNS = (*PAIR_COLUMNS, "matched", "mismatched_item")
PAGE_COLUMNS = (
    "rater_id",
    "page_id",
    "item",
    "clip_id",
    "condition",
    "rating",
    "role",
    "trial_index",
    "watched_ms",
    "submitted_at",
    "external_id",
    "study_id",
    "rater_completed",
    "flags",
)
FILENAMES = {"acr": "ratings.csv", "pairwise": "pairs.csv", "parallel": "ratings.csv", "appropriateness": "pairs.csv"}


def _common(rater_id, idx, watched, at, ext, study, completed, flags, n_early):
    from .export import row_flags

    return {
        "rater_id": rater_id,
        "trial_index": idx,
        "watched_ms": "" if watched is None else watched,
        "submitted_at": at.strftime("%Y-%m-%dT%H:%M:%S.%fZ"),
        "external_id": ext or "",
        "study_id": study or "",
        "rater_completed": int(completed is not None),
        "flags": row_flags(flags, n_early),
    }


RATER_EXTRA = (Rater.external_id, Rater.study_id, Rater.completed_at)


def iter_fit_rows(s: Session):
    """The appropriateness export: pairs.csv's rows, with the matched side and the mismatched clip's item."""
    motion = dict(s.execute(select(Clip.clip_id, Clip.motion_item)).all())
    for row in iter_pair_rows(s):
        ma, mb = motion.get(row["clip_a"]) or "", motion.get(row["clip_b"]) or ""
        test = row["role"] == "test"
        row["matched"] = ("b" if ma else "a") if test else ""
        row["mismatched_item"] = (ma or mb) if test else ""
        yield row


def iter_pair_rows(s: Session):
    ca, cb = aliased(Clip), aliased(Clip)
    q = (
        select(
            Rater.rater_id,
            ca.item,
            Preference.clip_a,
            Preference.clip_b,
            ca.condition,
            cb.condition,
            Preference.preference,
            Trial.kind,
            Trial.index,
            Preference.watched_ms,
            Preference.submitted_at,
            *RATER_EXTRA,
            Preference.flags,
            Rater.n_early,
        )
        .join(Trial, Trial.id == Preference.trial_pk)
        .join(Rater, Rater.id == Preference.rater_pk)
        .join(ca, ca.clip_id == Preference.clip_a)
        .join(cb, cb.clip_id == Preference.clip_b)
        .order_by(Rater.id, Trial.index)
    )
    for (
        rater_id,
        item,
        a,
        b,
        cond_a,
        cond_b,
        pref,
        kind,
        idx,
        watched,
        at,
        ext,
        study,
        completed,
        flags,
        n_early,
    ) in s.execute(q):
        row = {
            "item": item,
            "clip_a": a,
            "clip_b": b,
            "condition_a": cond_a,
            "condition_b": cond_b,
            "preference": pref,
            "role": kind,
        }
        row.update(_common(rater_id, idx, watched, at, ext, study, completed, flags, n_early))
        yield row


def iter_page_rows(s: Session):
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
    for (
        rater_id,
        trial_pk,
        item,
        clip_id,
        cond,
        rating,
        kind,
        idx,
        watched,
        at,
        ext,
        study,
        completed,
        flags,
        n_early,
    ) in s.execute(q):
        row = {
            "page_id": f"p{trial_pk}",
            "item": item,
            "clip_id": clip_id,
            "condition": cond,
            "rating": rating,
            "role": kind,
        }
        row.update(_common(rater_id, idx, watched, at, ext, study, completed, flags, n_early))
        yield row


def pair_failed(row) -> bool:
    """A pairwise catch answer that prefers the bad example (either level)."""
    return bool(pair_catch_failed(row["condition_a"], row["condition_b"], row["preference"]))


def page_failures(rows) -> set[str]:
    """Page ids of parallel catch pages where a BAD clip got at least the NAT clip's rating."""
    pages: dict[str, dict[str, list[int]]] = {}
    for r in rows:
        if r["role"] == "catch":
            pages.setdefault(r["page_id"], {}).setdefault(r["condition"], []).append(r["rating"])
    return {
        p
        for p, by in pages.items()
        if NATURAL in by and CATCH in by and page_catch_failed(max(by[CATCH]), min(by[NATURAL]))
    }


def progress_units(s: Session, design: str, units: dict, target: int) -> dict:
    """The dashboard's tables for a pairwise or parallel study: per unit (as per_clip), per condition pair or
    condition (as per_condition), and each rater's answers and catch failures."""
    clips = dict(s.execute(select(Clip.clip_id, Clip.condition)).all())
    done = dict(
        s.execute(
            select(Trial.unit, func.count())
            .where(Trial.unit.is_not(None), Trial.kind != "training", Trial.answered_at.is_not(None))
            .group_by(Trial.unit)
        ).all()
    )
    pending = dict(
        s.execute(
            select(Trial.unit, func.count())
            .where(
                Trial.unit.is_not(None),
                Trial.kind != "training",
                Trial.answered_at.is_(None),
                Trial.released.is_(False),
                Trial.served_at.is_not(None),
            )
            .group_by(Trial.unit)
        ).all()
    )
    rows = list(iter_page_rows(s) if design == "parallel" else iter_pair_rows(s))
    per_unit = []
    for key, u in sorted(units.items(), key=lambda kv: (kv[1].role != "test", kv[0])):
        conds = [clips.get(c, "?") for c in u.clips]
        per_unit.append(
            {
                "clip_id": key,
                "condition": " / ".join(conds),
                "role": u.role,
                "item": u.item,
                "ratings": done.get(key, 0),
                "in_progress": pending.get(key, 0),
                "target": target if u.role == "test" else None,
                "mean": None,
            }
        )
    if design == "appropriateness":
        rows = list(iter_fit_rows(s))
    per_cond = _per_condition(design, units, clips, rows, target)
    for d in per_cond.values():
        d["mean"] = round(d.pop("_sum") / d["ratings"], 2) if d["ratings"] else None
    answers, fails, no_video, partial = {}, {}, {}, {}
    failed_pages = page_failures(rows) if design == "parallel" else set()
    seen_pages = set()
    for r in rows:
        rid = r["rater_id"]
        if design == "parallel":
            if r["page_id"] in seen_pages:
                continue
            seen_pages.add(r["page_id"])
            failed = r["page_id"] in failed_pages
        else:
            failed = r["role"] == "catch" and pair_failed(r)
        answers[rid] = answers.get(rid, 0) + 1
        fails[rid] = fails.get(rid, 0) + failed
        no_video[rid] = no_video.get(rid, 0) + ("no_video" in r["flags"])
        partial[rid] = partial.get(rid, 0) + ("partial_video" in r["flags"])
    return {
        "per_clip": per_unit,
        "per_condition": list(per_cond.values()),
        "answers": answers,
        "fails": fails,
        "no_video": no_video,
        "partial_video": partial,
    }


def _per_condition(design, units, clips, rows, target) -> dict:
    """The dashboard's per-condition rows before their means: per condition pair (pairwise, appropriateness: the
    MAS, seen from the matched clip) or per condition and role (parallel)."""
    per_cond = {}
    if design in ("pairwise", "appropriateness"):
        for key, u in units.items():
            name = " vs ".join(sorted(clips.get(c, "?") for c in u.clips))
            d = per_cond.setdefault(
                name, {"condition": name, "role": u.role, "clips": 0, "ratings": 0, "target": 0, "_sum": 0}
            )
            d["clips"] += 1
            d["target"] += target if u.role == "test" else 0
        for r in rows:
            first = min(r["condition_a"], r["condition_b"])
            d = per_cond[" vs ".join(sorted((r["condition_a"], r["condition_b"])))]
            d["ratings"] += 1
            if r.get("matched"):  # appropriateness: the mean is the MAS, seen from the matched clip
                d["_sum"] += r["preference"] if r["matched"] == "a" else -r["preference"]
            else:
                d["_sum"] += r["preference"] if r["condition_a"] == first else -r["preference"]
    else:
        for u in units.values():
            for c in u.clips:
                d = per_cond.setdefault(
                    (clips.get(c, "?"), u.role),
                    {"condition": clips.get(c, "?"), "role": u.role, "clips": 0, "ratings": 0, "target": 0, "_sum": 0},
                )
                d["clips"] += 1
                d["target"] += target if u.role == "test" else 0
        for r in rows:
            d = per_cond.setdefault(
                (r["condition"], r["role"]),
                {"condition": r["condition"], "role": r["role"], "clips": 0, "ratings": 0, "target": 0, "_sum": 0},
            )
            d["ratings"] += 1
            d["_sum"] += r["rating"]
    return per_cond
