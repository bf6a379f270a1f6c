"""pairwise (CONTRACTS §8): two clips of one item from two conditions, labelled A and B, a preference -2..2.

The unit is (item, condition pair), so every pair of conditions of every item reaches its target separately; a
catch unit pairs each bad example of a catch item with that item's NAT clip. The two clips can play at once (side
by side on a wide screen), so the viewing rule counts the longer one. The export is pairs.csv, one row per
answer, A being the clip that rater saw as A.
"""

from __future__ import annotations

from typing import NamedTuple

from sqlalchemy import Integer, cast, func, insert, select
from sqlalchemy.orm import aliased

from moglow_eval.core import study, votes

from ..guard.bodies import int_field
from ..store.db import Clip, Preference, Rater, StudySetting, Trial
from ..store.reasons import parse_answer as parse_reasons
from ..store.rounds import ROUND
from .base import Unit, new_condition_row
from .export_cells import RATER_EXTRA, TAIL, common
from .units import UnitDesign, check_comparable, record_head

# After `role` in pairs.csv: the study's round the vote was stored in, the reasons ticked, the free text.
VOTE_EXTRA = ("round", "reasons", "reason_text")

COLUMNS = (
    "rater_id",
    "item",
    "clip_a",
    "clip_b",
    "condition_a",
    "condition_b",
    "preference",
    "role",
    *VOTE_EXTRA,
    *TAIL,
)


class Vote(NamedTuple):
    """A rating-phase answer: the preference and the reasons given with it (store/reasons.py)."""

    preference: int
    reasons: str  # ids joined by ';'
    reason_text: str


class Pairwise(UnitDesign):
    name = "pairwise"
    answer_field = "preference"
    question = "Which motion looks more natural?"
    export_file = "pairs.csv"
    export_noun = "pairwise answers"
    columns = COLUMNS
    page = "pair"
    takes_reasons = True
    grows = True  # a new condition adds its pairs; every other pair stays as it is
    ranks_conditions = True
    battles = True
    answer_extra = ("reasons", "reason_text")
    default_reasons = votes.REALISM_REASONS
    default_reason_text = votes.FREE_TEXT_MAX
    dashboard = {
        **UnitDesign.dashboard,
        "note": " (two clips, a preference; targets per item and pair of conditions)",
        "units": "comparisons",
        "per_condition": "pair of conditions",
        "mean": "mean preference for the first",
        "per_unit": "comparison",
    }

    # ------------------------------------------------------------------------------------------ the units
    def test_units(self, tests, clips):
        units = {}
        for item, by_cond in sorted(tests.items()):
            conds = check_comparable(self.name, item, by_cond)
            for i, a in enumerate(conds):
                for b in conds[i + 1 :]:
                    key = f"pair:{item}:{a}:{b}"
                    units[key] = Unit(key, "test", item, (by_cond[a][0], by_cond[b][0]))
        return units

    def catch_units(self, item, by_cond, page_size):
        nat = by_cond[study.NATURAL][0]
        return {
            f"catch:{item}:{k}": Unit(f"catch:{item}:{k}", "catch", item, (nat, bad))
            for k, bad in enumerate(by_cond[study.CATCH])
        }

    def item_groups(self, ids):
        """Two clips of the same item where an item has two."""
        ids = list(ids)
        groups = []
        while len(ids) >= 2:
            groups.append((ids.pop(), ids.pop()))
        return groups, ids

    # ----------------------------------------------------------------------------------- a trial, its answer
    def required_ms(self, durations):
        return max(durations, default=0)

    def payload(self, clips):
        if len(clips) != 2:  # a lone familiarisation clip
            return super().payload(clips)
        return {"design": self.name, "a": clips[0], "b": clips[1]}

    def parse_answer(self, body, shown):
        return Vote(int_field(body, "preference", -2, 2), *parse_reasons(body, training=False))

    def store(self, conn, trial, rater_pk, shown, value, watched_ms, now, flags):
        # The round is read in the storing statement itself, so a vote can never miss a round that began before it.
        round_now = select(cast(StudySetting.value, Integer)).where(StudySetting.name == ROUND).scalar_subquery()
        conn.execute(
            insert(Preference).values(
                trial_pk=trial.id,
                rater_pk=rater_pk,
                clip_a=shown[0].clip_id,
                clip_b=shown[1].clip_id,
                preference=value.preference,
                watched_ms=watched_ms,
                submitted_at=now,
                flags=flags,
                round=func.coalesce(round_now, 1),
                reasons=value.reasons,
                reason_text=value.reason_text,
            )
        )

    def stored_answer(self, conn, trial_pk):
        return conn.execute(select(Preference.preference).where(Preference.trial_pk == trial_pk)).scalar()

    # ---------------------------------------------------------------------------------- export, dashboard
    def export_rows(self, s):
        yield from iter_pair_rows(s)

    def signed(self, row, first: str) -> int:
        """A row's preference seen from the pair's first condition (in name order)."""
        return row["preference"] if row["condition_a"] == first else -row["preference"]

    def per_condition(self, units, conditions, rows, target):
        """Per condition pair."""
        per_cond = {}
        for u in units.values():
            name = " vs ".join(sorted(conditions.get(c, "?") for c in u.clips))
            d = per_cond.setdefault(name, new_condition_row(name, u.role))
            d["clips"] += 1
            d["target"] += target if u.role == "test" else 0
        for r in rows:
            pair = sorted((r["condition_a"], r["condition_b"]))
            name = " vs ".join(pair)  # a withdrawn condition's pairs are no longer units, but keep their votes
            d = per_cond.setdefault(name, new_condition_row(name, r["role"]))
            d["ratings"] += 1
            d["_sum"] += self.signed(r, pair[0])
        return per_cond

    def answers(self, rows):
        for r in rows:
            failed = r["role"] == "catch" and pair_failed(r)
            yield r["rater_id"], failed, r["flags"]

    # --------------------------------------------------------------------------------- the simulated crowd
    def simulated_answer(self, rater, ids, shown):
        watched = rater.watched(shown)  # drawn before the answer, so a crowd's answers stay those of its seed
        return rater.prefer(shown[0], shown[1]), watched

    def catch_failed(self, ids, conditions, value):
        return bool(study.pair_catch_failed(conditions[0], conditions[1], value))

    def records(self, head, ids, shown, value, role):
        conds = [c.condition if c else None for c in shown]
        pair = {"clip_a": ids[0], "clip_b": ids[1], "condition_a": conds[0], "condition_b": conds[1]}
        return [
            {
                **record_head(head, role),
                **pair,
                "condition": " vs ".join(sorted(map(str, conds))),
                "preference": value,
            }
        ]


def pair_failed(row) -> bool:
    """A pairwise catch answer that prefers the bad example (either level)."""
    return bool(study.pair_catch_failed(row["condition_a"], row["condition_b"], row["preference"]))


def iter_pair_rows(s):
    """pairs.csv (CONTRACTS §8): one row per answer."""
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
            Preference.round,
            Preference.reasons,
            Preference.reason_text,
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
    for rater_id, item, a, b, cond_a, cond_b, pref, kind, rnd, reasons, text, *rest in s.execute(q):
        row = {
            "item": item,
            "clip_a": a,
            "clip_b": b,
            "condition_a": cond_a,
            "condition_b": cond_b,
            "preference": pref,
            "role": kind,
            "round": rnd or 1,  # a vote stored before rounds belongs to the start
            "reasons": reasons or "",
            "reason_text": text or "",
        }
        row.update(common(rater_id, *rest))
        yield row
