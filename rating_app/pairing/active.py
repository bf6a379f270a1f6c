"""Active pairing and the stopping rule of a pairwise study (CONTRACTS §8, "Active pairing and the stopping rule").

`--pairing active`: a test slot gets a unit of the pair of conditions whose order the votes so far back least
(moglow_eval.core.pair_posterior.pick_order: the weakest evidence under the Bradley-Terry posterior of the test votes so
far, a sequential probability ratio test on every pair at once; pairs tied within PAIRING_INDIFFERENCE Elo left
out), except for a share of slots (PAIRING_RANDOM) that keep the balanced rule, so a wrong model cannot starve a
pair. It only chooses among the units the balanced rule could give this slot: the same claim (least-covered first,
short of its target, not had by this rater, its Cover row locked and checked again) over the chosen pair's units;
when none of the best pairs has one, the balanced claim over all units. Sides, catch slots, the plan, expiry and the
targets are untouched.

`--stop-when settled`: a new session is refused (409, as a full study) once the ranking is settled
(pair_posterior.settledness at STOP_LEVEL, or every Elo interval narrower than STOP_WIDTH) or the test votes reached
STOP_MAX_VOTES; sessions already started finish.

Only trusted votes move the ranking: the votes of a rater whom the exclusion rule excludes (failed catch trials,
moglow_eval.core.study.excluded_raters, the report's rule too) are kept and exported with their flag, and enter
neither the posterior that picks the pairs, nor the stop, nor the dashboard's figures. A rater who fails a catch
trial after some test votes loses them at the next refit, which reads every vote again.

Each worker keeps its own `ActivePairing`: the posterior mean of the last fit, refitted when the votes changed, at most
every REFRESH_S seconds (a GET next) or at once (a new session, so the stop is decided on every vote in); and
the votes per pair (the trusted answered ones at the last refresh, the held slots from the Cover rows, plus the
slots this worker gave since), whose covariance lets a slot given now count before its answer, so concurrent
raters spread over pairs.
"""

from __future__ import annotations

import threading
import time

import numpy as np
from sqlalchemy import bindparam, case, func, select
from sqlalchemy.orm import aliased

from moglow_eval.core import pair_posterior, study

from ..store.db import Clip, Cover, Preference, Trial
from .assign import claim

REFRESH_S = 1.0
TRIES = 3  # pairs tried in pick_order's order before the balanced claim

# The refit's queries, built once: a statement built per call costs more CPU in SQLAlchemy's construction and cache
# key than its execution does, and a refit runs at every vote when REFRESH_S is 0.
_A, _B = aliased(Clip), aliased(Clip)  # a vote's two clips
_SIDE = case((Preference.preference > 0, 1), (Preference.preference < 0, -1), else_=0)


def _votes(kind, *columns):
    return (
        select(*columns)
        .join(Trial, Trial.id == Preference.trial_pk)
        .join(_A, _A.clip_id == Preference.clip_a)
        .join(_B, _B.clip_id == Preference.clip_b)
        .where(Trial.kind == kind)
    )


_LAST_VOTE = select(func.max(Preference.id))
_HELD = select(Cover.key, Cover.held).where(Cover.held > 0)
_CATCH_VOTES = _votes("catch", Preference.rater_pk, _A.condition, _B.condition, Preference.preference)
# The test votes per pair of conditions and side, each group flagged when its votes are of excluded raters.
_PAIR_KEYS = (_A.condition, _B.condition, _SIDE, Preference.rater_pk.in_(bindparam("excluded", expanding=True)))
_TEST_WINS = _votes("test", func.count(), *_PAIR_KEYS).group_by(*_PAIR_KEYS)


class ActivePairing:
    """Active pairing's state in one worker: the posterior of the trusted test votes, the counts behind it, and the
    stopping rule (module docstring)."""

    def __init__(self, units, clips, cfg):
        self.units = units  # what it was built on: a new round or a withdrawal gives the worker new units
        tests = {k: u for k, u in units.items() if u.role == "test"}
        self.conds = sorted({clips[c].condition for u in tests.values() for c in u.clips})
        idx = {c: i for i, c in enumerate(self.conds)}
        k = len(self.conds)
        self.pr = pair_posterior.pairs(k)
        at = {tuple(p): n for n, p in enumerate(self.pr.tolist())}
        self.pair_of = {key: at[tuple(sorted(idx[clips[c].condition] for c in u.clips))] for key, u in tests.items()}
        self.keys_of = [sorted(key for key, p in self.pair_of.items() if p == n) for n in range(len(self.pr))]
        self.cfg = cfg
        self.lock = threading.Lock()
        self.post = pair_posterior.fit(np.zeros((k, k)))
        self.counts = np.zeros((k, k))
        self.votes = 0
        self.untrusted = (0, 0)  # (test votes, raters) left out by the exclusion rule
        self.top_id = None
        self.checked = -float("inf")

    # -------------------------------------------------------------------------------------- the posterior
    def refresh(self, conn, now: bool = False) -> None:
        """Refit when the votes changed: at most every REFRESH_S seconds, or at once with `now`."""
        t = time.monotonic()
        if not now and t - self.checked < REFRESH_S:
            return
        top = conn.execute(_LAST_VOTE).scalar()
        self.checked = t
        if top == self.top_id:
            return
        excluded = excluded_raters(conn)
        wins, votes, left_out = self._wins(conn, excluded)
        counts = wins + wins.T + self._held(conn)
        with self.lock:
            self.post = pair_posterior.fit(wins, start=self.post.mean)
            self.counts, self.votes, self.top_id = counts, votes, top
            self.untrusted = (left_out, len(excluded))

    def _wins(self, conn, excluded):
        """(the win matrix of the trusted answered test votes (ties half to each side), their number, the number
        of test votes of the `excluded` raters)."""
        idx = {c: i for i, c in enumerate(self.conds)}
        w, votes, untrusted = np.zeros((len(idx), len(idx))), 0, 0
        for n, a, b, s, flagged in conn.execute(_TEST_WINS, {"excluded": excluded}):
            if flagged:
                untrusted += n
            elif a in idx and b in idx:
                w[idx[a], idx[b]] += n * (1.0 if s > 0 else 0.0 if s < 0 else 0.5)
                w[idx[b], idx[a]] += n * (0.0 if s > 0 else 1.0 if s < 0 else 0.5)
                votes += n
        return w, votes, untrusted

    def _held(self, conn):
        """Slots held now (served, not yet answered) per pair of conditions, from the test units' Cover rows."""
        k = len(self.conds)
        n = np.zeros((k, k))
        for key, held in conn.execute(_HELD):
            p = self.pair_of.get(key)
            if p is not None:
                i, j = self.pr[p]
                n[i, j] += held
                n[j, i] += held
        return n

    def posterior(self):
        with self.lock:
            return pair_posterior.with_counts(self.post, self.counts)

    # -------------------------------------------------------------------------------------------- pairing
    def pick(self, conn, rng, rater_pk: int, units, target: int, wait: bool):
        """A test unit of the pair with the weakest evidence this slot can have, or None (then the balanced claim)."""
        self.refresh(conn)
        order = pair_posterior.pick_order(
            self.posterior(), rng, self.cfg["PAIRING_RANDOM"], self.cfg["PAIRING_INDIFFERENCE"]
        )
        if order is None:
            return None
        for p in order[:TRIES]:
            key = claim(conn, self.keys_of[p], "unit", rater_pk, target, wait) if self.keys_of[p] else None
            if key is not None:
                i, j = self.pr[p]
                with self.lock:  # counts at once, before the next fit: the next slot moves on
                    self.counts[i, j] += 1
                    self.counts[j, i] += 1
                return units[key]
        return None

    # ------------------------------------------------------------------------------------------- stopping
    def status(self) -> dict:
        """How far the study is from its stop (the dashboard's "ranking"; CONTRACTS §8)."""
        cfg = self.cfg
        with self.lock:
            post, votes, (left_out, n_excluded) = self.post, self.votes, self.untrusted
        s = pair_posterior.settledness(post, cfg["STOP_LEVEL"], cfg["STOP_WIDTH"] or None, cfg["PAIRING_INDIFFERENCE"])
        anchor = pair_posterior.elo_reference(self.conds)
        elo, se = pair_posterior.elo(post, self.conds.index(anchor))
        cap = cfg["STOP_MAX_VOTES"]
        return {
            "pairing": cfg["PAIRING"],
            "stop_when": cfg["STOP_WHEN"],
            "level": cfg["STOP_LEVEL"],
            "order": [self.conds[i] for i in s["order"]],
            "elo_anchor": anchor,  # the condition at 1000, as in the report
            "elo": {c: round(float(e), 1) for c, e in zip(self.conds, elo)},
            "elo_se": {c: round(float(e), 1) for c, e in zip(self.conds, se)},
            "weakest_separation": round(s["weakest"], 4),
            "indifference": cfg["PAIRING_INDIFFERENCE"] or None,
            "tied": [[self.conds[i], self.conds[j]] for i, j in s["tied"]],
            "separation_needed": round(s["needed"], 4),
            "widest_interval": round(s["widest"], 1),
            "width": cfg["STOP_WIDTH"] or None,
            "votes": votes,
            "votes_excluded": left_out,
            "raters_excluded": n_excluded,
            "max_votes": cap or None,
            "settled": s["settled"],
            "closed": cfg["STOP_WHEN"] == "settled" and (s["settled"] or bool(cap and votes >= cap)),
        }

    def closed(self, conn) -> str | None:
        """Why a new session is refused now, or None (always None unless STOP_WHEN is settled)."""
        if self.cfg["STOP_WHEN"] != "settled":
            return None
        self.refresh(conn, now=True)
        st = self.status()
        if not st["closed"]:
            return None
        why = "the ranking is settled" if st["settled"] else "it has all the votes it was to collect"
        return f"study closed: {why}. Thank you for your interest"


def excluded_raters(conn) -> list[int]:
    """The rater pks the exclusion rule (moglow_eval.core.study.excluded_raters) excludes, from their catch votes."""
    return study.excluded_raters((r, study.pair_catch_failed(a, b, p)) for r, a, b, p in conn.execute(_CATCH_VOTES))


def of_app(app):
    """The app's ActivePairing, or None when the study neither pairs actively nor stops when settled."""
    return app.extensions["rating_app"].get("ranking")


def for_units(ext, units):
    """The worker's ActivePairing over `units` (rounds.current_units), rebuilt when the study gained or withdrew a
    condition since it was built (the new condition's pairs then count from its first vote); None when the study
    neither pairs actively nor stops when settled."""
    r = ext.get("ranking")
    if r is not None and r.units is not units:
        with _rebuild_lock:
            r = ext["ranking"]
            if r.units is not units:
                r = ext["ranking"] = ActivePairing(units, ext["clips"], r.cfg)
    return r


_rebuild_lock = threading.Lock()
