"""Active pairing and the stopping rule of a pairwise study (CONTRACTS §8, "Active pairing and the stopping rule").

`--pairing active`: a test slot gets a unit of the pair of conditions whose next vote tells most about the ranking
(moglow_eval.core.ranking.gains under the Bradley-Terry posterior of the test votes so far), except for a share
of slots (PAIRING_RANDOM) that keep the balanced rule, so a wrong model cannot starve a pair. It only chooses
among the units the balanced rule could give this slot: the same claim (least-covered first, short of its target,
not had by this rater, its Cover row locked and checked again) over the chosen pair's units; when none of the best
pairs has one, the balanced claim over all units. Sides, catch slots, the plan, expiry and the targets are
untouched.

`--stop-when settled`: a new session is refused (409, as a full study) once the ranking is settled
(ranking.settledness at STOP_LEVEL, or every Elo interval narrower than STOP_WIDTH) or the test votes reached
STOP_MAX_VOTES; sessions already started finish.

Each worker keeps its own `Ranking`: the posterior mean of the last fit, refitted when the votes changed, at most
every REFRESH_S seconds (a GET next) or at once (a new session, so the stop is decided on every vote in); and
the votes per pair (answered and held, from the Cover rows at the last refresh, plus the slots this worker gave
since), whose covariance lets a slot given now count before its answer, so concurrent raters spread over pairs.
"""

from __future__ import annotations

import threading
import time

import numpy as np
from sqlalchemy import case, func, select
from sqlalchemy.orm import aliased

from moglow_eval.core import ranking

from ..store.db import Clip, Cover, Preference, Trial
from .assign import claim

REFRESH_S = 1.0
TRIES = 3  # pairs tried in gain order before the balanced claim


class Ranking:
    """The ranking state of one worker (module docstring)."""

    def __init__(self, units, clips, cfg):
        self.units = units  # what it was built on: a new round or a withdrawal gives the worker new units
        tests = {k: u for k, u in units.items() if u.role == "test"}
        self.conds = sorted({clips[c].condition for u in tests.values() for c in u.clips})
        idx = {c: i for i, c in enumerate(self.conds)}
        k = len(self.conds)
        self.pr = ranking.pairs(k)
        at = {tuple(p): n for n, p in enumerate(self.pr.tolist())}
        self.pair_of = {key: at[tuple(sorted(idx[clips[c].condition] for c in u.clips))] for key, u in tests.items()}
        self.keys_of = [sorted(key for key, p in self.pair_of.items() if p == n) for n in range(len(self.pr))]
        self.cfg = cfg
        self.lock = threading.Lock()
        self.post = ranking.fit(np.zeros((k, k)))
        self.counts = np.zeros((k, k))
        self.votes = 0
        self.top_id = None
        self.checked = -float("inf")

    # -------------------------------------------------------------------------------------- the posterior
    def refresh(self, conn, now: bool = False) -> None:
        """Refit when the votes changed: at most every REFRESH_S seconds, or at once with `now`."""
        t = time.monotonic()
        if not now and t - self.checked < REFRESH_S:
            return
        top = conn.execute(select(func.max(Preference.id))).scalar()
        self.checked = t
        if top == self.top_id:
            return
        wins, votes = self._wins(conn)
        counts = self._counts(conn)
        with self.lock:
            self.post = ranking.fit(wins, start=self.post.mean)
            self.counts, self.votes, self.top_id = counts, votes, top

    def _wins(self, conn):
        """The win matrix of the answered test votes (ties half to each side) and their number."""
        ca, cb = aliased(Clip), aliased(Clip)
        sign = case((Preference.preference > 0, 1), (Preference.preference < 0, -1), else_=0)
        q = (
            select(ca.condition, cb.condition, sign, func.count())
            .join(Trial, Trial.id == Preference.trial_pk)
            .join(ca, ca.clip_id == Preference.clip_a)
            .join(cb, cb.clip_id == Preference.clip_b)
            .where(Trial.kind == "test")
            .group_by(ca.condition, cb.condition, sign)
        )
        idx = {c: i for i, c in enumerate(self.conds)}
        w, votes = np.zeros((len(idx), len(idx))), 0
        for a, b, s, n in conn.execute(q):
            if a in idx and b in idx:
                w[idx[a], idx[b]] += n * (1.0 if s > 0 else 0.0 if s < 0 else 0.5)
                w[idx[b], idx[a]] += n * (0.0 if s > 0 else 1.0 if s < 0 else 0.5)
                votes += n
        return w, votes

    def _counts(self, conn):
        """Votes per pair of conditions, answered or held, from the test units' Cover rows."""
        k = len(self.conds)
        n = np.zeros((k, k))
        for key, answered, held in conn.execute(select(Cover.key, Cover.answered, Cover.held)):
            p = self.pair_of.get(key)
            if p is not None:
                i, j = self.pr[p]
                n[i, j] += answered + held
                n[j, i] += answered + held
        return n

    def posterior(self):
        with self.lock:
            return ranking.with_counts(self.post, self.counts)

    # -------------------------------------------------------------------------------------------- pairing
    def pick(self, conn, rng, rater_pk: int, units, target: int, wait: bool):
        """A test unit of the most informative pair this slot can have, or None (then the balanced claim)."""
        if rng.random() < self.cfg["PAIRING_RANDOM"]:
            return None
        self.refresh(conn)
        g = ranking.gains(self.posterior())
        noise = np.array([rng.random() for _ in g]) * 1e-9  # ties at random
        had = select(Trial.unit).where(Trial.rater_pk == rater_pk, Trial.unit.is_not(None))
        for p in np.argsort(-(g + noise))[:TRIES]:
            key = claim(conn, self.keys_of[p], had, target, wait) if self.keys_of[p] else None
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
            post, votes = self.post, self.votes
        s = ranking.settledness(post, cfg["STOP_LEVEL"], cfg["STOP_WIDTH"] or None)
        elo, se = ranking.elo(post)
        cap = cfg["STOP_MAX_VOTES"]
        return {
            "pairing": cfg["PAIRING"],
            "stop_when": cfg["STOP_WHEN"],
            "level": cfg["STOP_LEVEL"],
            "order": [self.conds[i] for i in s["order"]],
            "elo": {c: round(float(e), 1) for c, e in zip(self.conds, elo)},
            "elo_se": {c: round(float(e), 1) for c, e in zip(self.conds, se)},
            "weakest_separation": round(s["weakest"], 4),
            "separation_needed": round(s["needed"], 4),
            "widest_interval": round(s["widest"], 1),
            "width": cfg["STOP_WIDTH"] or None,
            "votes": votes,
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


def of_app(app):
    """The app's Ranking, or None when the study neither pairs actively nor stops when settled."""
    return app.extensions["rating_app"].get("ranking")


def for_units(ext, units):
    """The worker's Ranking over `units` (rounds.current_units), rebuilt when the study gained or withdrew a
    condition since it was built (the new condition's pairs then count from its first vote); None when the study
    neither pairs actively nor stops when settled."""
    r = ext.get("ranking")
    if r is not None and r.units is not units:
        with _rebuild_lock:
            r = ext["ranking"]
            if r.units is not units:
                r = ext["ranking"] = Ranking(units, ext["clips"], r.cfg)
    return r


_rebuild_lock = threading.Lock()
