"""acr (CONTRACTS §5-6, the paper's design): one clip per trial, a rating 1..5; the unit is the clip.

A slot gets the least-covered clip of its role that the rater has not had (assign.claim); the catch trials are the
bad examples (condition BAD) only, never the other clips a catch item holds for the other designs.
"""

from __future__ import annotations

from sqlalchemy import bindparam, func, insert, or_, select

from moglow_eval.core import study

from ..guard.bodies import int_field
from ..pairing.assign import NO_TARGET, StudyFull, claim, cover, n_catch_slots, short_or_full, slots
from ..store.db import STANDING_CLIP, Clip, Cover, Rater, Rating, Trial
from .base import Design, new_condition_row
from .export_cells import RATER_EXTRA, TAIL, common

# The clips a slot of each kind draws from: test clips, or the bad examples among the catch clips. One statement
# for both kinds, so that their timing matches.
_ROLE_CLIPS = select(Clip.clip_id).where(
    Clip.role == bindparam("role"),
    or_(Clip.role != "catch", Clip.condition == study.CATCH),
    STANDING_CLIP,  # a stochastic system's clip once, by the clip that stands for its samples
)


def acr_catch(clip) -> bool:
    """A catch trial of an acr study: a bad example, never the other clips a catch item also holds."""
    return clip.role == "catch" and clip.condition == study.CATCH


class Acr(Design):
    name = "acr"
    answer_field = "rating"
    answer_noun = "rating"
    question = "How natural does this motion look?"
    export_file = "ratings.csv"
    export_noun = "ratings"
    columns = ("rater_id", "clip_id", "condition", "rating", "role", "item", *TAIL)
    several_clips = False
    page = "one"
    dashboard = {
        **Design.dashboard,
        "note": " (one clip at a time, 1-5)",
        "answers": "ratings",
        "unit_column": "clip",
    }

    # -------------------------------------------------------------------------------- units and assignment
    def build_units(self, clips):
        return {}

    def cover_keys(self, clips, units):
        return [c.clip_id for c in clips if c.role == "test" or acr_catch(c)]

    def pool(self, clips, units):
        return sum(c.role == "test" for c in clips), sum(acr_catch(c) for c in clips)

    def coverage(self, conn) -> dict[str, tuple[int, int]]:
        """{clip_id: (stored ratings, held slots)} for every test clip (of this manifest: rows are never deleted)."""
        return cover(conn, Cover.key.in_(select(Clip.clip_id).where(Clip.role == "test")))

    def is_full(self, conn, target, units):
        cov = self.coverage(conn)
        return bool(cov) and all(d >= target for d, _ in cov.values())

    def plan(self, conn, rng, cfg, clips, units):
        """Every training clip, one per trial, then the test and catch slots, shuffled; StudyFull."""
        cov = self.coverage(conn)
        if not cov:
            raise StudyFull("the study has no test clips")
        short = short_or_full(cov, cfg["RATINGS_PER_CLIP"], "clip", "ratings", "rated")
        per_rater = cfg["CLIPS_PER_RATER"]
        n_test = short if not per_rater else min(per_rater, short)
        pool = conn.execute(
            select(func.count()).select_from(Clip).where(Clip.role == "catch", Clip.condition == study.CATCH)
        ).scalar()
        training = list(
            conn.execute(select(Clip.clip_id).where(Clip.role == "training").order_by(Clip.clip_id)).scalars()
        )
        rng.shuffle(training)
        return [("training", c) for c in training] + slots(rng, n_test, n_catch_slots(pool, cfg["CATCH_PER_RATER"]))

    def assign(self, conn, rng, rater_pk, kind, target, units, wait=False):
        """Both kinds run the same statements, so their timing does not tell them apart."""
        target = target if kind == "test" else NO_TARGET
        return claim(conn, _ROLE_CLIPS, "clip_id", rater_pk, target, wait, params={"role": kind})

    # ----------------------------------------------------------------------------------- a trial, its answer
    def required_ms(self, durations):
        return max(durations, default=0)

    def payload(self, clips):
        return {"clip_id": clips[0]["clip_id"], "video_url": clips[0]["video_url"]}  # no "design": as in §5

    def parse_answer(self, body, shown):
        return int_field(body, "rating", 1, 5)

    def store(self, conn, trial, rater_pk, shown, value, watched_ms, now, flags):
        conn.execute(
            insert(Rating).values(
                trial_pk=trial.id,
                rater_pk=rater_pk,
                clip_id=trial.clip_id,
                rating=value,
                watched_ms=watched_ms,
                submitted_at=now,
                flags=flags,
            )
        )

    def stored_answer(self, conn, trial_pk):
        return conn.execute(select(Rating.rating).where(Rating.trial_pk == trial_pk)).scalar()

    # ---------------------------------------------------------------------------------- export, dashboard
    def export_rows(self, s):
        yield from iter_rows(s)

    def catch_answers(self, rows):
        return ((r["rater_id"], r["role"] == "catch" and study.acr_catch_failed(r["rating"])) for r in rows)

    def progress(self, s, target, units):
        return progress_tables(s, target)

    # --------------------------------------------------------------------------------- the simulated crowd
    def simulated_answer(self, rater, ids, shown):
        return rater.rate(shown[0])

    def catch_failed(self, ids, conditions, value):
        return bool(study.acr_catch_failed(value))

    def records(self, head, ids, shown, value, role):
        clip = shown[0]
        return [
            {
                "rater_id": head["rater_id"],
                "external_id": head["external_id"],
                "trial_id": head["trial_id"],
                "clip_id": ids[0],
                "condition": clip.condition if clip else None,
                "role": clip.role if clip else None,
                "rating": value,
                "careless": head["careless"],
            }
        ]


def iter_rows(s):
    """ratings.csv (CONTRACTS §6): one row per rating."""
    q = (
        select(
            Rater.rater_id,
            func.coalesce(Trial.sample_clip, Rating.clip_id),  # the clip shown: a stochastic system's drawn sample
            Clip.condition,
            Rating.rating,
            Clip.role,
            Clip.item,
            Trial.index,
            Rating.watched_ms,
            Rating.submitted_at,
            *RATER_EXTRA,
            Rating.flags,
            Rater.n_early,
        )
        .join(Trial, Trial.id == Rating.trial_pk)
        .join(Rater, Rater.id == Rating.rater_pk)
        .join(Clip, Clip.clip_id == Rating.clip_id)
        .order_by(Rater.id, Trial.index)
    )
    for rater_id, clip_id, cond, rating, role, item, *rest in s.execute(q):
        row = {"clip_id": clip_id, "condition": cond, "rating": rating, "role": role, "item": item}
        row.update(common(rater_id, *rest))
        yield row


def progress_tables(s, target) -> dict:
    """The dashboard's figures of an acr study: per clip, per condition, and each rater's ratings and failures."""
    clips = s.execute(
        select(Clip.clip_id, Clip.condition, Clip.role, Clip.item)
        .where(Clip.role != "training", (Clip.role != "catch") | (Clip.condition == study.CATCH), STANDING_CLIP)
        .order_by(Clip.role, Clip.condition, Clip.clip_id)
    ).all()
    # One pass over the ratings: count and sum per clip (condition means come from the exact sums).
    stats = {
        c: (n, int(total))
        for c, n, total in s.execute(
            select(Rating.clip_id, func.count(), func.sum(Rating.rating)).group_by(Rating.clip_id)
        )
    }
    pending = dict(
        s.execute(
            select(Trial.clip_id, func.count())
            .where(
                Trial.phase == "rating",
                Trial.clip_id.is_not(None),
                Trial.answered_at.is_(None),
                Trial.released.is_(False),
            )
            .group_by(Trial.clip_id)
        ).all()
    )
    per_clip, per_cond = [], {}
    for c, cond, role, item in clips:
        n, total = stats.get(c, (0, 0))
        r = {
            "clip_id": c,
            "condition": cond,
            "role": role,
            "item": item,
            "ratings": n,
            "in_progress": pending.get(c, 0),
            "target": target if role == "test" else None,
            "mean": round(total / n, 2) if n else None,
        }
        per_clip.append(r)
        d = per_cond.setdefault(cond, new_condition_row(cond, role))
        d["clips"] += 1
        d["ratings"] += n
        d["target"] += r["target"] or 0
        d["_sum"] += total
    for d in per_cond.values():
        d["mean"] = round(d.pop("_sum") / d["ratings"], 2) if d["ratings"] else None

    def per_rater(*where, join_clip=False):
        q = select(Rater.rater_id, func.count()).select_from(Rating).join(Rater, Rater.id == Rating.rater_pk)
        if join_clip:
            q = q.join(Clip, Clip.clip_id == Rating.clip_id)
        return dict(s.execute(q.where(*where).group_by(Rater.rater_id)).all())

    return {
        "per_clip": per_clip,
        "per_condition": list(per_cond.values()),
        "answers": per_rater(),
        "fails": per_rater(Clip.role == "catch", study.acr_catch_failed(Rating.rating), join_clip=True),
        "no_video": per_rater(Rating.flags.contains("no_video")),
        "partial_video": per_rater(Rating.flags.contains("partial_video")),
    }
