"""Votes a pairwise ranking study needs, balanced against active pairing, with and without the stopping rule; and
the stopping rule's error rate against its nominal level. Pure simulation against moglow_eval.core.ranking, no app.

    nice python bench/pairwise_active.py [--reps 100] [--max-votes 40000] [--error-reps 150] [--skip fixed,stop,error]

The truth: Bradley-Terry log strengths of the 8 systems of the GENEA leaderboard's released realism votes
(../shared/data/genea-leaderboard-votes/battles_elo.csv, read there, never copied; ties half to each side),
fitted with ranking.fit under a flat-enough prior (sd 10). Each simulated vote goes to the pair the scheme
picks and its winner is drawn from those strengths.
- balanced: the pair with the fewest votes so far, ties at random (what the app's least-covered rule does);
- active: with probability --random-share a pair at random, else the pair of highest ranking.gains, the mean
  refitted as the app refits it (ranking.refit_due) and the covariance from the votes so far (ranking.with_counts).
The votes needed: the smallest count from which on (checked every --step votes) at least 95% of replications rank
the systems at Kendall tau >= 0.9 against the truth's order; the spread: the quantiles over replications of
each one's first count at tau >= 0.9 for good. With the stopping rule: votes at the stop and the share of stopped
studies at tau >= 0.9 and with every pair in the truth's order.
The error table: studies stopped by the rule (separation only) on known strengths, the share that order some pair
wrongly, against 1 - level.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
from scipy.stats import kendalltau

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from moglow_eval.core import ranking  # noqa: E402
from moglow_eval.core.votes import battle_to_preference  # noqa: E402

VOTES = ROOT.parent / "shared" / "data" / "genea-leaderboard-votes" / "battles_elo.csv"


def leaderboard_truth(path=VOTES):
    """(system names, log strengths) fitted on the released realism votes."""
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    names = sorted({r["model_a"] for r in rows} | {r["model_b"] for r in rows})
    idx = {n: i for i, n in enumerate(names)}
    pref = [battle_to_preference(r["winner"], r["is_strong"]) for r in rows]
    outcome = [1.0 if p > 0 else 0.0 if p < 0 else 0.5 for p in pref]
    w = ranking.win_matrix(len(names), [idx[r["model_a"]] for r in rows], [idx[r["model_b"]] for r in rows], outcome)
    return names, ranking.fit(w, prior_sd=10.0).mean


class Study:
    """One simulated study: its votes so far and the scheme that picks the next pair."""

    def __init__(self, truth, scheme, rng, random_share=0.2):
        self.truth, self.scheme, self.rng, self.share = truth, scheme, rng, random_share
        k = len(truth)
        self.pr = ranking.pairs(k)
        self.wins = np.zeros((k, k))
        self.post = ranking.fit(self.wins)
        self.at_fit = 0.0

    @property
    def votes(self):
        return float(self.wins.sum())

    def current(self):
        """The posterior as the app holds it: the last fit's mean, the covariance of every vote so far."""
        if ranking.refit_due(self.at_fit, self.votes):
            self.post, self.at_fit = ranking.fit(self.wins, start=self.post.mean), self.votes
        return ranking.with_counts(self.post, self.wins + self.wins.T)

    def next_pair(self):
        n = (self.wins + self.wins.T)[self.pr[:, 0], self.pr[:, 1]]
        if self.scheme == "balanced":
            best = np.flatnonzero(n == n.min())
        elif self.rng.random() < self.share:
            best = np.arange(len(self.pr))
        else:
            g = ranking.gains(self.current())
            best = np.flatnonzero(g >= g.max() - 1e-12)
        return self.pr[self.rng.choice(best)]

    def vote(self):
        i, j = self.next_pair()
        won = self.rng.random() < 1.0 / (1.0 + math.exp(self.truth[j] - self.truth[i]))
        self.wins[(i, j) if won else (j, i)] += 1.0

    def order_tau(self):
        """Kendall tau of the current mean's order against the truth's."""
        post = ranking.fit(self.wins, start=self.post.mean)
        return kendalltau(post.mean, self.truth).statistic, post


def run_fixed(truth, scheme, reps, max_votes, step, seed, share):
    """[reps, checkpoints] Kendall tau at every `step` votes."""
    taus = np.zeros((reps, max_votes // step))
    for r in range(reps):
        s = Study(truth, scheme, np.random.default_rng([seed, r]), share)
        for c in range(taus.shape[1]):
            for _ in range(step):
                s.vote()
            taus[r, c] = s.order_tau()[0]
    return taus


def votes_needed(taus, step, tau=0.9, share=0.95):
    """(votes from which on >= `share` of replications are at `tau`, per-replication first votes at tau for good)."""
    ok = taus >= tau - 1e-12
    good = ok.mean(axis=0) >= share
    bad_after = np.flatnonzero(~good)
    first_all = (bad_after[-1] + 2) * step if len(bad_after) else step
    per_rep = []
    for row in ok:
        misses = np.flatnonzero(~row)
        per_rep.append((misses[-1] + 2) * step if len(misses) else step)
    return (first_all if first_all <= taus.shape[1] * step else None), np.array(per_rep)


def ratio_interval(taus, step, rng, n_boot=500):
    """A percentile interval of active / balanced votes needed, replications resampled in each scheme."""
    ratios = []
    for _ in range(n_boot):
        got = []
        for scheme in ("active", "balanced"):
            t = taus[scheme]
            got.append(votes_needed(t[rng.integers(len(t), size=len(t))], step)[0])
        if all(got):
            ratios.append(got[0] / got[1])
    return np.percentile(ratios, 2.5), np.percentile(ratios, 97.5)


def run_stopping(truth, scheme, reps, cap, seed, share, level, width=None, check=25):
    """Per replication (votes at the stop, tau there, every pair right): the rule checked every `check` votes."""
    out = []
    right = np.argsort(-truth)
    for r in range(reps):
        s = Study(truth, scheme, np.random.default_rng([seed, 7, r]), share)
        while True:
            for _ in range(check):
                s.vote()
            tau, post = s.order_tau()
            if ranking.settledness(post, level, width)["settled"] or s.votes >= cap:
                break
        order = np.argsort(-post.mean, kind="stable")
        out.append((s.votes, tau, bool((order == right).all()), s.votes >= cap))
    return out


def error_table(truths, reps, cap, seed, share, levels):
    rows = []
    for label, truth in truths.items():
        for level in levels:
            for scheme in ("balanced", "active"):
                res = run_stopping(truth, scheme, reps, cap, seed, share, level)
                stopped = [x for x in res if not x[3]]
                wrong = sum(not x[2] for x in stopped)
                rows.append((label, level, scheme, len(stopped), wrong, np.median([x[0] for x in stopped] or [0])))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=100)
    ap.add_argument("--max-votes", type=int, default=40000)
    ap.add_argument("--step", type=int, default=1000)
    ap.add_argument("--error-reps", type=int, default=150)
    ap.add_argument("--cap", type=int, default=30000)
    ap.add_argument("--stop-reps", type=int, default=60)
    ap.add_argument("--width", type=float, default=50.0, help="the stopping rule's Elo width in the stop runs")
    ap.add_argument("--random-share", type=float, default=0.2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--skip", default="", help="comma-separated parts to skip: fixed, stop, error")
    a = ap.parse_args(argv)
    skip = set(a.skip.split(","))
    names, truth = leaderboard_truth()
    elo = ranking.ELO_PER_LOG * (truth - truth.mean()) + ranking.ELO_ANCHOR
    print(f"truth (Elo): {', '.join(f'{n} {e:.0f}' for n, e in sorted(zip(names, elo), key=lambda x: -x[1]))}")
    print(f"Machine: {platform.processor() or platform.machine()}, load average {os.getloadavg()[0]:.2f}")
    t0 = time.time()
    if "fixed" not in skip:
        needed, taus = {}, {}
        for scheme in ("balanced", "active"):
            taus[scheme] = run_fixed(truth, scheme, a.reps, a.max_votes, a.step, a.seed, a.random_share)
            n95, per_rep = votes_needed(taus[scheme], a.step)
            needed[scheme] = n95
            q = np.percentile(per_rep, [5, 25, 50, 75, 95])
            print(
                f"{scheme:9s} votes to tau>=0.9 in 95% of {a.reps} reps: {n95}; per replication "
                f"5/25/50/75/95%: {' / '.join(f'{x:.0f}' for x in q)}  ({time.time() - t0:.0f} s)"
            )
        if needed["balanced"] and needed["active"]:
            lo, hi = ratio_interval(taus, a.step, np.random.default_rng(a.seed))
            print(
                f"active / balanced: {needed['active'] / needed['balanced']:.2f} (bootstrap over replications, "
                f"95%: {lo:.2f}-{hi:.2f})"
            )
    if "stop" not in skip:
        for scheme in ("balanced", "active"):
            res = run_stopping(truth, scheme, a.stop_reps, a.cap, a.seed, a.random_share, 0.95, a.width)
            v = np.array([x[0] for x in res])
            print(
                f"{scheme:9s} stop (level 0.95, width {a.width}, cap {a.cap}): votes median {np.median(v):.0f}, 5-95% "
                f"{np.percentile(v, 5):.0f}-{np.percentile(v, 95):.0f}; "
                f"at tau>=0.9 {np.mean([x[1] >= 0.9 for x in res]):.3f}, "
                f"every pair right {np.mean([x[2] for x in res]):.3f}, at the cap {np.mean([x[3] for x in res]):.3f}"
                f"  ({time.time() - t0:.0f} s)"
            )
    if "error" not in skip:
        k = len(truth)
        truths = {"8 evenly 0.3 apart": 0.3 * np.arange(k)[::-1], "8 evenly 0.2 apart": 0.2 * np.arange(k)[::-1]}
        print(
            "| strengths | level | scheme | studies stopped | ordered some pair wrongly | share | nominal "
            "| median votes |"
        )
        for label, level, scheme, n, wrong, med in error_table(
            truths, a.error_reps, a.cap, a.seed, a.random_share, (0.9, 0.95)
        ):
            share = wrong / n if n else float("nan")
            print(f"| {label} | {level} | {scheme} | {n} | {wrong} | {share:.3f} | {1 - level:.2f} | {med:.0f} |")
        print(f"({time.time() - t0:.0f} s)")


if __name__ == "__main__":
    main()
