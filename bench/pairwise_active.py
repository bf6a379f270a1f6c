"""Votes a pairwise ranking study needs with the app's active pairing against round robin, on three truths; and the
stopping rule's error rate. Pure simulation, no server, but the app's own rule: the pair order comes from
moglow_eval.core.pair_posterior.pick_order (what rating_app/pairing/active.py calls), its balanced share goes to the
least-covered pair (the app's balanced claim), and the mean is refitted as the app refits it.

    nice python bench/pairwise_active.py [--reps 40] [--truths evenly,leaderboard,near-ties] [--skip stop,error]
        [--figure bench/figures/pairwise_active.png]

- The truths (log strengths): `evenly`, 8 systems 0.15 apart (26 Elo); `leaderboard`, the 8 systems of the GENEA
  leaderboard's released realism votes (../shared/data/genea-leaderboard-votes/battles_elo.csv, read there, never
  copied), fitted by pair_posterior.fit under a flat-enough prior (sd 10); `near-ties`, 10 systems 0.25 apart but for
  two pairs 0.02 apart (3.5 Elo: alike for any rater).
- A vote: its outcome drawn from Bradley-Terry with Davidson's ties (ν = --nu; 0.35 gives 15% ties between
  equals), a tie half to each side, as the app counts it.
- round robin: the pair with the fewest votes so far, ties at random (the app's balanced pairing).
- active: pair_posterior.pick_order on the posterior the app holds (the last fit's mean, every vote so far in the
  covariance), with --random-share and the indifference --margin; None: the least-covered pair. The app refits
  whenever a vote came in, at most once a second: --votes-per-second votes between fits (1: before every vote).
- Votes to tau >= 0.9 in --share of replications: the smallest count from which on (checked --checks times a run)
  that share of replications rank the systems at Kendall tau >= 0.9 against the truth; active / round robin, with
  a percentile interval over replications (each scheme's replications resampled, 500 times).
- The stopping rule (`error`): studies run until pair_posterior.settledness at each of --levels (with --width, the Elo
  width too) or --cap votes; how many claimed a wrong order, their median votes and Kendall tau at the stop.
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
sys.path.insert(0, str(ROOT / "tests"))

from helpers.paths import LEADERBOARD  # noqa: E402

from moglow_eval.core import pair_posterior  # noqa: E402
from moglow_eval.core.votes import battle_to_preference  # noqa: E402

VOTES = LEADERBOARD / "battles_elo.csv"
SCHEMES = ("balanced", "active")


def leaderboard_truth(path=VOTES):
    """(system names, log strengths) fitted on the released realism votes."""
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    names = sorted({r["model_a"] for r in rows} | {r["model_b"] for r in rows})
    idx = {n: i for i, n in enumerate(names)}
    pref = [battle_to_preference(r["winner"], r["is_strong"]) for r in rows]
    outcome = [1.0 if p > 0 else 0.0 if p < 0 else 0.5 for p in pref]
    w = pair_posterior.win_counts(
        len(names), [idx[r["model_a"]] for r in rows], [idx[r["model_b"]] for r in rows], outcome
    )
    return names, pair_posterior.fit(w, prior_sd=10.0).mean


# Round robin's votes per replication on each truth (about 1.5x what it needs): active gets --active-cap of them.
MAX_VOTES = {"evenly": 8000, "leaderboard": 19200, "near-ties": 6000}


def truths(which):
    """{name: (log strengths, the near-tie pairs as index pairs)}."""
    out = {}
    if "evenly" in which:
        out["evenly"] = (0.15 * np.arange(8)[::-1], [])
    if "leaderboard" in which:
        out["leaderboard"] = (leaderboard_truth()[1], [])
    if "near-ties" in which:
        steps = np.array([0.25, 0.02, 0.25, 0.25, 0.25, 0.02, 0.25, 0.25, 0.25])
        s = np.r_[0.0, -np.cumsum(steps)]
        out["near-ties"] = (s, [(1, 2), (5, 6)])
    return out


class Study:
    """One simulated study: its votes so far, and the scheme that picks the next pair."""

    def __init__(self, truth, scheme, rng, a):
        self.truth, self.scheme, self.rng, self.a = truth, scheme, rng, a
        k = len(truth)
        self.pr = pair_posterior.pairs(k)
        self.wins = np.zeros((k, k))
        self.post = pair_posterior.fit(self.wins)
        self.since_fit = 0

    @property
    def votes(self):
        return float(self.wins.sum())

    def least_covered(self):
        n = (self.wins + self.wins.T)[self.pr[:, 0], self.pr[:, 1]]
        return int(self.rng.choice(np.flatnonzero(n == n.min())))

    def next_pair(self):
        if self.scheme == "balanced":
            return self.pr[self.least_covered()]
        if self.since_fit >= self.a.votes_per_second:  # the app: refit when votes came in, once a second at most
            self.post, self.since_fit = pair_posterior.fit(self.wins, start=self.post.mean), 0
        held = pair_posterior.with_counts(self.post, self.wins + self.wins.T)
        order = pair_posterior.pick_order(held, self.rng, self.a.random_share, self.a.margin)
        return self.pr[self.least_covered() if order is None else order[0]]

    def vote(self):
        i, j = self.next_pair()
        pi, pj = math.exp(self.truth[i]), math.exp(self.truth[j])
        tie = self.a.nu * math.sqrt(pi * pj)
        u = self.rng.random() * (pi + pj + tie)
        outcome = 1.0 if u < pi else 0.0 if u < pi + pj else 0.5
        self.wins[i, j] += outcome
        self.wins[j, i] += 1.0 - outcome
        self.since_fit += 1
        return i, j

    def tau(self):
        return kendalltau(pair_posterior.fit(self.wins, start=self.post.mean).mean, self.truth).statistic


def run(truth, near, scheme, a, reps, max_votes, step, seed):
    """([reps, checkpoints] Kendall tau every `step` votes, the share of votes on the near-tie pairs)."""
    taus = np.zeros((reps, max_votes // step))
    on_near, total = 0, 0
    near = {tuple(sorted(p)) for p in near}
    for r in range(reps):
        s = Study(truth, scheme, np.random.default_rng([seed, r]), a)
        for c in range(taus.shape[1]):
            for _ in range(step):
                i, j = s.vote()
                on_near += (min(i, j), max(i, j)) in near
                total += 1
            taus[r, c] = s.tau()
    return taus, on_near / total


def share_at(taus, tau=0.9):
    """[checkpoints] the share of replications at Kendall tau >= `tau` (a hair below: tau is a ratio of counts)."""
    return (taus >= tau - 1e-12).mean(axis=0)


def votes_needed(taus, step, share, tau=0.9):
    """The votes from which on at least `share` of replications are at tau >= `tau`; None if never."""
    good = share_at(taus, tau) >= share
    bad_after = np.flatnonzero(~good)
    first = (bad_after[-1] + 2) * step if len(bad_after) else step
    return first if first <= taus.shape[1] * step else None


def ratio_interval(taus, step, share, rng, n_boot=500):
    ratios = []
    for _ in range(n_boot):
        got = [votes_needed(taus[s][rng.integers(len(taus[s]), size=len(taus[s]))], step, share) for s in SCHEMES]
        ratios.append(got[1] / got[0] if all(got) else np.inf)
    return np.percentile(ratios, 2.5, method="lower"), np.percentile(ratios, 97.5, method="higher")


def fixed(a, t0):
    rows, curves = [], {}
    for name, (truth, near) in truths(a.truths.split(",")).items():
        taus, shares, needed = {}, {}, {}
        most = int(MAX_VOTES[name] * a.scale)
        step = most // a.checks
        for scheme in SCHEMES:
            if scheme not in a.schemes:
                taus[scheme], shares[scheme], needed[scheme] = np.zeros((1, 1)), 0.0, None
                continue
            cap = most if scheme == "balanced" else int(most * a.active_cap) // step * step
            taus[scheme], shares[scheme] = run(truth, near, scheme, a, a.reps, cap, step, a.seed)
            needed[scheme] = votes_needed(taus[scheme], step, a.share)
            print(f"{name:12s} {scheme:9s} votes: {needed[scheme]}  near-tie share {shares[scheme]:.3f}  "
                  f"({time.time() - t0:.0f} s)", flush=True)  # fmt: skip
        lo, hi = ratio_interval(taus, step, a.share, np.random.default_rng(a.seed))
        ratio = needed["active"] / needed["balanced"] if all(needed.values()) else float("nan")
        rows.append((name, len(truth), needed["balanced"], needed["active"], ratio, lo, hi, shares))
        curves[name] = (step, {s: share_at(taus[s]) for s in a.schemes.split(",")}, needed)
    print("| truth | systems | round robin | active | active / round robin | 95% interval | votes on near-ties "
          "(round robin, active) |\n|---|---|---|---|---|---|---|")  # fmt: skip
    for name, k, nb, na, ratio, lo, hi, sh in rows:
        near = f"{sh['balanced']:.3f}, {sh['active']:.3f}" if name == "near-ties" else ""
        print(f"| {name} | {k} | {nb} | {na} | {ratio:.2f} | {lo:.2f}-{hi:.2f} | {near} |")
    if a.figure:
        plot(curves, a.figure, a.share)


def plot(curves, path, share):
    """One panel a truth: the share of replications at tau >= 0.9 against the votes so far, each pairing, with the
    line at `share` and where each pairing stays above it (votes_needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(curves), figsize=(4.2 * len(curves), 3.4), squeeze=False)
    for ax, (name, (step, by_scheme, needed)) in zip(axes[0], curves.items()):
        for scheme, good in by_scheme.items():
            line = ax.plot(step * np.arange(1, len(good) + 1), good, label="round robin" if scheme == "balanced"
                           else "active")[0]  # fmt: skip
            if needed.get(scheme):
                ax.axvline(needed[scheme], color=line.get_color(), ls=":", lw=1)
        ax.axhline(share, color="grey", lw=0.8)
        ax.set(title=name, xlabel="votes", ylim=(0, 1.01))
    axes[0][0].set_ylabel("share of replications at Kendall tau >= 0.9")
    axes[0][0].legend(loc="lower right")
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    print(f"figure: {path}")


def run_stopping(truth, scheme, a, reps, level, seed, check=25):
    """Per replication (votes at the stop, every adjacent pair of the claimed order right or tied within the
    margin, reached the cap, Kendall tau at the stop)."""
    out = []
    for r in range(reps):
        s = Study(truth, scheme, np.random.default_rng([seed, 7, r]), a)
        while True:
            for _ in range(check):
                s.vote()
            post = pair_posterior.fit(s.wins, start=s.post.mean)
            st = pair_posterior.settledness(post, level, a.width, a.margin)
            if st["settled"] or s.votes >= a.cap:
                break
        order, tied = st["order"], {tuple(p) for p in st["tied"]}
        wrong = any(truth[x] < truth[y] and (x, y) not in tied for x, y in zip(order[:-1], order[1:]))
        out.append((s.votes, not wrong, s.votes >= a.cap, kendalltau(post.mean, truth).statistic))
    return out


def error_table(a):
    print("| truth | level | width | pairing | stopped | claimed a wrong order | nominal | median votes | mean tau |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, (truth, _) in truths(a.truths.split(",")).items():
        for level in map(float, a.levels.split(",")):
            for scheme in SCHEMES:
                res = run_stopping(truth, scheme, a, a.error_reps, level, a.seed)
                stopped = [x for x in res if not x[2]]
                wrong = sum(not x[1] for x in stopped)
                med = np.median([x[0] for x in stopped] or [0])
                tau = np.mean([x[3] for x in stopped] or [np.nan])
                print(f"| {name} | {level} | {a.width} | {scheme} | {len(stopped)} | {wrong} | {1 - level:.2f} | "
                      f"{med:.0f} | {tau:.3f} |", flush=True)  # fmt: skip


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=100)
    ap.add_argument("--checks", type=int, default=80, help="checkpoints per replication at which tau is computed")
    ap.add_argument("--truths", default="evenly,leaderboard,near-ties")
    ap.add_argument("--scale", type=float, default=1.0, help="x each truth's votes per replication (MAX_VOTES)")
    ap.add_argument("--active-cap", type=float, default=0.75, help="active's votes per replication, x round robin's")
    ap.add_argument("--share", type=float, default=0.9, help="the share of replications at tau >= 0.9")
    ap.add_argument("--random-share", type=float, default=pair_posterior.RANDOM_SHARE, help="as PAIRING_RANDOM")
    ap.add_argument("--margin", type=float, default=pair_posterior.INDIFFERENCE_ELO, help="as PAIRING_INDIFFERENCE")
    ap.add_argument(
        "--votes-per-second",
        type=int,
        default=4,
        help="votes between the app's refits (it refits at most once a second: 4 a second is about 100 raters at "
        "once, each answering every 25 s)",
    )
    ap.add_argument("--nu", type=float, default=0.35, help="Davidson's tie parameter of the simulated raters")
    ap.add_argument("--error-reps", type=int, default=40)
    ap.add_argument("--cap", type=int, default=30000)
    ap.add_argument("--levels", default="0.9,0.95", help="the stopping rule's levels, comma-separated")
    ap.add_argument("--width", type=float, default=None, help="the stopping rule's Elo width (--stop-width)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--schemes", default="balanced,active", help="which schemes to run (a pilot: balanced alone)")
    ap.add_argument("--skip", default="", help="comma-separated parts to skip: fixed, error")
    ap.add_argument("--figure", default=None, help="a PNG of the share at tau >= 0.9 by votes, a panel a truth")
    a = ap.parse_args(argv)
    skip = set(a.skip.split(","))
    print(f"Machine: {platform.processor() or platform.machine()}, load average {os.getloadavg()[0]:.2f}; {vars(a)}")
    t0 = time.time()
    if "fixed" not in skip:
        fixed(a, t0)
    if "error" not in skip:
        error_table(a)
    print(f"({time.time() - t0:.0f} s; load average {os.getloadavg()[0]:.2f})")


if __name__ == "__main__":
    main()
