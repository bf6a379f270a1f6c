"""A Bradley-Terry ranking of conditions that grows vote by vote: its posterior, which pair of conditions to ask
about next, and whether the ranking is settled (CONTRACTS §8, "Active pairing and the stopping rule").

Votes come as a win matrix W (W[i, j]: the votes for condition i over condition j, a tie counting half to each
side). The model is Bradley-Terry, P(i over j) = 1 / (1 + exp(theta_j - theta_i)), with an independent normal
prior N(0, PRIOR_SD^2) on each log strength theta, weak enough that a few dozen votes outweigh it but proper, so
that the posterior exists from zero votes on. The posterior is approximated by a normal distribution at its mode
(Laplace): mean = the MAP log strengths, covariance = the inverse of the negative log posterior's Hessian.

From it:
- `evidence`: how strongly the votes so far back each pair's order, (|d| + kappa) / v, with d the posterior mean of the
  difference of the pair's log strengths, v its posterior variance at even odds, and kappa a floor (below); a slot
  goes to the pair whose order has the weakest evidence. Why |d| / v: were the difference either +delta or -delta,
  the log likelihood ratio of the two, given an estimate d of variance v, would be 2 delta d / v, whatever delta is.
  So voting where |d| / v is least runs Wald's sequential probability ratio test (Wald 1945) on every pair at once,
  each pair drawing votes until its evidence matches the others' (the indifference-zone view of ranking and
  selection, Bechhofer 1954). For two conditions near even odds it is close to half their net wins (the
  Bradley-Terry log likelihood ratio of +delta against -delta is exactly delta times the net wins). A pair whose
  order happens to look clear early stops drawing votes: that is what saves votes when every neighbour is equally
  hard. Every pair, not the neighbours alone: Kendall's tau counts each discordant pair, and the same tests on the
  true neighbours alone needed 0.9-1.0 of round robin's votes, a wrong neighbour taking its own neighbours along
  (bench/notes/2026-11-28-pairwise-active-neighbours-only.md).
  The variance is taken at even odds, where the two orders meet and the test's two hypotheses are told apart
  (a vote's Fisher information p (1 - p) at p = 1/2): at the fitted odds, a pair that one condition wins every time
  would look ever less certain, its information vanishing as p -> 1. The prior stays in the variance: without it,
  every pair with a vote or two would look as open as one never asked about (evenly spaced conditions needed 0.63 of
  round robin's votes, not 0.57, on the same replications).
  The floor, kappa = ALIKE_FLOOR x the median gap between neighbours in the posterior-mean order, is for two
  conditions that are alike. The evidence of a real difference grows with a pair's votes n, but that of two alike
  conditions only with sqrt(n), so without a floor they drew 45% of the votes of a study with two such pairs among
  ten conditions, for an order no budget settles and Kendall's tau forgives. With it every vote counts as evidence
  of at least a difference kappa: an alike pair stops drawing votes at about (gap + kappa) / kappa = three times
  what a typical neighbouring pair draws (32% of that study's votes; more of its replications reached tau >= 0.9
  at most budgets, on two seeds), while pairs a typical gap apart are as before (evenly spaced conditions and the
  leaderboard's strengths unchanged within the noise). The floor scales with the conditions' own spread, so it
  needs no setting; at no votes it is 0.
  P(order) itself (the z-score d / sqrt(v)) and the expected drop of the order entropy from one vote (after ASAP,
  Mikhailiuk et al. 2020, the rule until 2026-11-28) keep asking about a pair while its estimate sits near zero,
  however many votes it had: the entropy spent 0.72 of round robin's votes on evenly spaced conditions, where the
  evidence spends about 0.6 (bench/RESULTS.md pairwise-active).
- `settledness`: every adjacent pair in the posterior-mean order separated, P(order right) at least
  1 - (1 - level) / (k - 1) each (a Bonferroni split of the error over the k - 1 adjacent pairs: if every adjacent
  pair of the estimated order is right, the whole order is), or every condition's Elo interval narrower than a
  width (each condition's interval about the mean condition). Elo = 400 log10 of the odds (the GENEA leaderboard's
  scale, Nagy et al. 2025), the reference condition at 1000 (`elo_reference`), on the dashboard and in the report.
- The indifference zone: a pair whose Elo difference is within a margin (the app's PAIRING_INDIFFERENCE) with high
  probability is tied (`tied`, `within`): no more active votes, and settled for the stopping rule.
  Without it, two conditions that are truly alike keep drawing votes for an order no number of votes settles.
- `pick_order`: the order in which the app tries pairs for a slot, the one function the app and the benchmark
  both call.

Pure numpy/scipy, no database: the app (rating_app/pairing/active.py) counts the votes and calls this; the benchmark
(bench/pairwise_active.py) simulates studies against it.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from . import study

PRIOR_SD = 2.0  # log strengths: two systems a prior sd apart win 88% of their votes; a few dozen votes outweigh it
ELO_PER_LOG = 400.0 / math.log(10.0)  # Elo points per unit of log strength (400 log10 odds)
ELO_ANCHOR = 1000.0  # the Elo of the reference condition (elo_reference)
# The indifference zone: two conditions whose Elo difference is, with probability TIE_CONFIDENCE, smaller than a
# margin are tied. Their order is no longer worth a vote (evidence), and the stopping rule takes them as settled. Off
# by default: a margin also stops the votes on pairs truly that close, whose order Kendall's tau still counts (the
# leaderboard's close neighbours needed far more votes with one; bench/RESULTS.md pairwise-active). A study that
# need not order conditions closer than some Elo difference sets it to that.
INDIFFERENCE_ELO = 0.0
TIE_CONFIDENCE = 0.95
# The share of active slots that keep the balanced rule (the app's PAIRING_RANDOM), so that a wrong model cannot
# starve a pair. The evidence never starves one by itself (every other pair's grows until a neglected pair's is
# the weakest again), so a tenth is enough; a fifth cost evenly spaced conditions about 0.05 of round robin's votes.
RANDOM_SHARE = 0.1
# The evidence's floor, as a share of the median gap between neighbouring conditions (module docstring): an alike pair
# draws at most about (1 + ALIKE_FLOOR) / ALIKE_FLOOR times a typical neighbouring pair's votes. A quarter or a whole
# gap helped near-ties less, or cost evenly spaced conditions votes
# (bench/notes/2026-11-28-pairwise-active-evidence-no-floor.md).
ALIKE_FLOOR = 0.5


@dataclass(frozen=True)
class Posterior:
    """The Laplace posterior of k log strengths: `mean` [k] (the MAP), `cov` [k, k], from `votes` votes; and
    `cov_even`, the covariance the same votes would give at even odds, which `evidence` weighs."""

    mean: np.ndarray
    cov: np.ndarray
    votes: float
    cov_even: np.ndarray


def _special():
    """scipy.special, imported at its first use, not with this module: every worker of the rating app imports the
    module for its settings' defaults, and scipy would add about a third of a second to each one's start."""
    from scipy import special

    return special


def win_counts(k: int, firsts, seconds, outcomes) -> np.ndarray:
    """W [k, k] from votes on (first, second) condition indices with outcomes 1 (the first won), 0 (the second
    won) or 0.5 (a tie, half to each side)."""
    w = np.zeros((k, k))
    o = np.asarray(outcomes, float)
    np.add.at(w, (np.asarray(firsts, int), np.asarray(seconds, int)), o)
    np.add.at(w, (np.asarray(seconds, int), np.asarray(firsts, int)), 1.0 - o)
    return w


def fit(wins, prior_sd: float = PRIOR_SD, start=None, tol: float = 1e-9) -> Posterior:
    """The Laplace posterior from a win matrix (`start`: log strengths to start Newton from, e.g. the last fit's).

    The negative log posterior is strictly convex (the prior adds 1/prior_sd^2 to every eigenvalue), so plain
    Newton steps from the last fit converge in a few iterations; a step is halved where it would not lower it."""
    w = np.asarray(wins, float)
    k = len(w)
    n = w + w.T
    theta = np.zeros(k) if start is None else np.asarray(start, float).copy()
    prec = 1.0 / prior_sd**2

    def objective(t):
        d = t[:, None] - t[None, :]
        return -(w * -np.logaddexp(0.0, -d)).sum() + 0.5 * prec * (t @ t)

    f = objective(theta)
    for _ in range(100):
        p = _special().expit(theta[:, None] - theta[None, :])
        grad = -(w - n * p).sum(axis=1) + prec * theta
        hess = _laplacian(n * p * (1.0 - p)) + prec * np.eye(k)
        step = np.linalg.solve(hess, grad)
        t = 1.0
        while t > 1e-6:
            new = theta - t * step
            f_new = objective(new)
            if f_new <= f + 1e-12 * abs(f):
                break
            t /= 2
        theta, f = new, f_new
        if np.max(np.abs(step)) * t < tol:
            break
    return Posterior(theta, covariance(theta, n, prior_sd), float(w.sum()), covariance(np.zeros(k), n, prior_sd))


def covariance(mean, counts, prior_sd: float = PRIOR_SD) -> np.ndarray:
    """The Laplace covariance at log strengths `mean` after `counts` votes (a symmetric [k, k] matrix of votes per
    pair): what it is before their outcomes are known, so that votes asked for but not yet in (slots held by raters
    now watching) already count for the choice of the next pair."""
    mean = np.asarray(mean, float)
    p = _special().expit(mean[:, None] - mean[None, :])
    return np.linalg.inv(_laplacian(np.asarray(counts, float) * p * (1.0 - p)) + np.eye(len(mean)) / prior_sd**2)


def with_counts(post: Posterior, counts, prior_sd: float = PRIOR_SD) -> Posterior:
    """`post`'s mean with the covariance of `counts` votes (covariance): between two fits, each vote asked for
    shrinks its pair's uncertainty at once, so the next choice moves on to another pair."""
    counts = np.asarray(counts, float)
    even = covariance(np.zeros(len(post.mean)), counts, prior_sd)
    return Posterior(post.mean, covariance(post.mean, counts, prior_sd), float(np.triu(counts, 1).sum()), even)


def _laplacian(weights: np.ndarray) -> np.ndarray:
    """The graph Laplacian of symmetric pair weights: what the BT log-likelihood's Hessian is made of."""
    weights = weights - np.diag(np.diag(weights))
    return np.diag(weights.sum(axis=1)) - weights


@functools.lru_cache(maxsize=64)
def pairs(k: int) -> np.ndarray:
    """Every pair (i, j), i < j, as rows of an int array [k (k - 1) / 2, 2] (in this order everywhere)."""
    i, j = np.triu_indices(k, 1)
    out = np.stack([i, j], axis=1)
    out.flags.writeable = False
    return out


def _difference_var(cov: np.ndarray, a, b) -> np.ndarray:
    """Var(theta_a - theta_b) under covariance `cov`, for pairs of condition indices `a`, `b` (arrays)."""
    return cov[a, a] + cov[b, b] - 2 * cov[a, b]


def within(post: Posterior, a, b, margin_elo: float) -> np.ndarray:
    """P(|theta_a - theta_b| < the margin) for pairs of condition indices `a`, `b` (arrays) under the posterior."""
    a, b = np.asarray(a), np.asarray(b)
    m = margin_elo / ELO_PER_LOG
    d = post.mean[a] - post.mean[b]
    sd = np.sqrt(np.maximum(_difference_var(post.cov, a, b), 1e-300))
    return _special().ndtr((m - d) / sd) - _special().ndtr((-m - d) / sd)


def tied(post: Posterior, margin_elo: float, confidence: float = TIE_CONFIDENCE) -> np.ndarray:
    """[P] in the order of `pairs(k)`: whether each pair is tied, its difference within `margin_elo` with
    probability at least `confidence` (none without a margin)."""
    pr = pairs(len(post.mean))
    if not margin_elo or margin_elo <= 0:
        return np.zeros(len(pr), bool)
    return within(post, pr[:, 0], pr[:, 1], margin_elo) >= confidence


def evidence(post: Posterior, margin_elo: float = 0.0) -> np.ndarray:
    """[P] in the order of `pairs(k)`: the weight of evidence for each pair's order, (|d| + kappa) / v (module
    docstring); inf for a pair tied within the indifference margin (`tied`), whose order needs no more votes."""
    pr = pairs(len(post.mean))
    a, b = pr[:, 0], pr[:, 1]
    var = _difference_var(post.cov_even, a, b)
    gaps = np.diff(np.sort(post.mean))
    kappa = ALIKE_FLOOR * float(np.median(gaps)) if len(gaps) else 0.0
    weight = (np.abs(post.mean[a] - post.mean[b]) + kappa) / np.maximum(var, 1e-300)
    return np.where(tied(post, margin_elo), np.inf, weight)


def pick_order(post: Posterior, rng, random_share: float, margin_elo: float = 0.0):
    """The pairs (indices into `pairs(k)`) in the order active pairing tries them for a slot, weakest evidence
    first, ties broken at random; or None for the `random_share` of slots that keep the balanced rule (the least-covered
    unit), so that a wrong model cannot starve a pair. `rng`: anything with .random() (random.Random or a numpy
    Generator). The app (rating_app/pairing/active.py) and the benchmark (bench/pairwise_active.py) both call it."""
    if rng.random() < random_share:
        return None
    e = evidence(post, margin_elo)
    draw = np.array([rng.random() for _ in e])
    return np.lexsort((draw, e))  # by evidence, equal evidence (none yet, or tied) in a random order


def elo_reference(conds) -> str:
    """The condition at ELO_ANCHOR, the same on the dashboard and in the report: the reference (NAT) where the
    study has one, else the first condition in name order. A reference keeps its 1000 as systems join a growing
    study, where the mean condition's would move with every newcomer."""
    conds = sorted(conds)
    return study.NATURAL if study.NATURAL in conds else conds[0]


def elo(post: Posterior, reference: int) -> tuple[np.ndarray, np.ndarray]:
    """(Elo of each condition, its standard error): 400 log10 odds, condition `reference` (an index; see
    elo_reference) at ELO_ANCHOR, as the report's ranking puts it; a standard error is of the
    difference from the reference (the reference's own is 0), as the report's intervals are."""
    k = len(post.mean)
    to_ref = np.eye(k)
    to_ref[:, reference] -= 1.0
    sd = np.sqrt(np.maximum(np.diag(to_ref @ post.cov @ to_ref.T), 0.0))
    return ELO_ANCHOR + ELO_PER_LOG * (post.mean - post.mean[reference]), ELO_PER_LOG * sd


def _centred_se(post: Posterior) -> np.ndarray:
    """Each condition's Elo standard error about the mean condition: the stopping rule's interval width, which
    asks how precisely every condition is placed, whichever one is the anchor."""
    k = len(post.mean)
    centre = np.eye(k) - 1.0 / k
    return ELO_PER_LOG * np.sqrt(np.maximum(np.diag(centre @ post.cov @ centre), 0.0))


def settledness(post: Posterior, level: float, width: float | None = None, margin_elo: float = 0.0) -> dict:
    """How far the ranking is from settled (module docstring). With an indifference margin, an adjacent pair whose
    difference lies within it with the probability a pair needs is tied, and settled as it is.

    -> {"order": condition indices best first, "weakest": the lowest P(order right) of an adjacent pair not
    tied, "needed": the P each adjacent pair needs, "tied": [(i, j)] adjacent pairs tied, "widest": the widest
    Elo interval at `level` (points), "width", "separated", "narrow", "settled"}."""
    k = len(post.mean)
    order = np.argsort(-post.mean, kind="stable")
    if k < 2:
        return {"order": order.tolist(), "weakest": 1.0, "needed": level, "tied": [], "widest": 0.0, "width": width,
                "separated": True, "narrow": True, "settled": True}  # fmt: skip
    a, b = order[:-1], order[1:]
    var = _difference_var(post.cov, a, b)
    needed = 1.0 - (1.0 - level) / (k - 1)
    is_tied = within(post, a, b, margin_elo) >= needed if margin_elo and margin_elo > 0 else np.zeros(k - 1, bool)
    sep = _special().ndtr((post.mean[a] - post.mean[b]) / np.sqrt(var))
    weakest = float(sep[~is_tied].min()) if (~is_tied).any() else 1.0
    se = _centred_se(post)
    widest = float(2.0 * _special().ndtri(1.0 - (1.0 - level) / 2.0) * se.max())
    separated = weakest >= needed
    narrow = width is not None and width > 0 and widest <= width
    return {
        "order": order.tolist(),
        "weakest": weakest,
        "needed": needed,
        "tied": [(int(x), int(y)) for x, y, t in zip(a, b, is_tied) if t],
        "widest": widest,
        "width": width,
        "separated": bool(separated),
        "narrow": bool(narrow),
        "settled": bool(separated or narrow),
    }
