"""moglow_eval.core.pair_posterior (CONTRACTS §8, "Active pairing and the stopping rule") against references: the
posterior mean against analysis.designs.pairwise.preference's independent maximum-likelihood
fit, the covariance against a numerical
Hessian, the Elo scale against the two-condition closed form, the evidence for an order against the exact
Bradley-Terry likelihood ratio, and the stopping rule on simulated studies with known strengths."""

import math

import numpy as np
import pytest
from scipy.special import expit

from analysis.designs.pairwise.preference import fit_bradley_terry
from moglow_eval.core import pair_posterior


def simulate(truth, n, rng, pair=None):
    """A win matrix of `n` votes on random pairs (or always `pair`) with Bradley-Terry outcomes."""
    k = len(truth)
    pr = pair_posterior.pairs(k)
    picks = pr[rng.integers(len(pr), size=n)] if pair is None else np.tile(pair, (n, 1))
    won = rng.random(n) < expit(truth[picks[:, 0]] - truth[picks[:, 1]])
    return pair_posterior.win_counts(k, picks[:, 0], picks[:, 1], won.astype(float))


def test_the_mean_is_the_independent_maximum_likelihood_fit_under_a_flat_prior():
    rng = np.random.default_rng(1)
    truth = rng.normal(0, 1, 6)
    w = simulate(truth, 3000, rng)
    post = pair_posterior.fit(w, prior_sd=1e5)
    pr = pair_posterior.pairs(6)
    counts = np.array([[w[i, j], w[j, i], 0.0] for i, j in pr])
    ref = fit_bradley_terry(counts, [tuple(p) for p in pr], list(range(6)), reference=0, ties=False)
    assert ref["converged"]
    ours = post.mean - post.mean[0]
    assert np.allclose(ours, [ref["strengths"][c] for c in range(6)], atol=1e-6)
    assert post.votes == 3000
    # and it recovers the truth it was drawn from
    assert np.abs(ours - (truth - truth[0])).max() < 0.25


def test_ties_count_half_to_each_side():
    w = pair_posterior.win_counts(3, [0, 0, 1], [1, 2, 2], [0.5, 1.0, 0.0])
    assert w.tolist() == [[0.0, 0.5, 1.0], [0.5, 0.0, 0.0], [0.0, 1.0, 0.0]]
    # two wins and a tie: 2.5 to 0.5
    tie = pair_posterior.fit(pair_posterior.win_counts(2, [0, 0, 0], [1, 1, 1], [1.0, 1.0, 0.5]), prior_sd=1e6)
    assert tie.mean[0] - tie.mean[1] == pytest.approx(math.log(2.5 / 0.5), abs=1e-6)


def test_the_covariance_is_the_inverse_hessian_of_the_log_posterior():
    rng = np.random.default_rng(2)
    w = simulate(np.array([0.5, 0.0, -0.3, -1.0]), 200, rng)
    post = pair_posterior.fit(w)

    def neg_log_post(t):
        d = t[:, None] - t[None, :]
        return (w * np.logaddexp(0, -d)).sum() + 0.5 * (t @ t) / pair_posterior.PRIOR_SD**2

    h, eps, k = np.zeros((4, 4)), 1e-4, 4
    for i in range(k):
        for j in range(k):
            e_i, e_j = np.eye(k)[i] * eps, np.eye(k)[j] * eps
            t = post.mean
            h[i, j] = (
                neg_log_post(t + e_i + e_j)
                - neg_log_post(t + e_i - e_j)
                - neg_log_post(t - e_i + e_j)
                + neg_log_post(t - e_i - e_j)
            ) / (4 * eps**2)
    assert np.allclose(post.cov, np.linalg.inv(h), rtol=1e-4, atol=1e-6)
    # the covariance of the votes' counts at the same mean is the same thing
    assert np.allclose(pair_posterior.covariance(post.mean, w + w.T), post.cov)


def test_the_elo_scale_is_400_log10_odds_with_the_reference_at_1000():
    # two conditions, 30 to 10: the maximum-likelihood log odds is log 3
    post = pair_posterior.fit(np.array([[0.0, 30.0], [10.0, 0.0]]), prior_sd=1e3)
    for ref in (0, 1):
        e, se = pair_posterior.elo(post, ref)
        assert e[0] - e[1] == pytest.approx(400 * math.log10(3), abs=1e-4)
        assert e[ref] == pytest.approx(1000.0)
        # the s.e. is of the difference from the reference: sqrt(1/30 + 1/10) log units, 0 for the reference
        assert se[ref] == pytest.approx(0.0, abs=1e-9)
        assert se[1 - ref] == pytest.approx(pair_posterior.ELO_PER_LOG * math.sqrt(1 / 30 + 1 / 10), rel=1e-4)


def test_the_dashboard_and_the_report_put_one_condition_at_1000():
    # One anchor (issue 63): NAT where it is, else the first by name; the report's default reference is the same.
    import pandas as pd

    from analysis.designs.pairwise.preference import bradley_terry

    assert pair_posterior.elo_reference(["S2", "NAT", "S1"]) == "NAT"
    assert pair_posterior.elo_reference(["S2", "S1"]) == "S1"
    rng = np.random.default_rng(3)
    pairs = [("S1", "S2"), ("S1", "S3"), ("S2", "S3")] * 40
    o = pd.DataFrame([{"rater_id": f"r{k % 7}", "item": "i", "first": a, "second": b, "pref": int(rng.integers(-2, 3))}
                      for k, (a, b) in enumerate(pairs)])  # fmt: skip
    bt = bradley_terry(o, n_boot=5)
    conds = ["S2", "S1", "S3"]
    assert bt["reference"] == pair_posterior.elo_reference(conds) == "S1"


def test_the_evidence_for_two_conditions_is_the_likelihood_ratio_of_their_order(monkeypatch):
    # Bradley-Terry's log likelihood ratio of "A ahead by delta" against "B ahead by delta" is delta x (A's wins -
    # B's wins), whatever delta; the evidence is that ratio over 2 delta, so half the net wins near even odds, plus
    # the floor, ALIKE_FLOOR x the median neighbour gap: with two conditions, their own gap.
    for a_wins, b_wins in ((260, 240), (230, 270), (520, 480), (101, 99)):
        post = pair_posterior.fit(np.array([[0.0, a_wins], [b_wins, 0.0]]), prior_sd=1e3)
        net = abs(a_wins - b_wins) / 2
        assert pair_posterior.evidence(post)[0] == pytest.approx(net * (1 + pair_posterior.ALIKE_FLOOR), rel=0.01)
        with monkeypatch.context() as m:
            m.setattr(pair_posterior, "ALIKE_FLOOR", 0.0)
            assert pair_posterior.evidence(post)[0] == pytest.approx(net, rel=0.01)


def pair_index(k):
    """{(i, j): the pair's index in pair_posterior.pairs(k)}, to read a pair's entry of `evidence` or `tied`."""
    return {tuple(p): n for n, p in enumerate(pair_posterior.pairs(k).tolist())}


def chain_posterior(n_alike, n_step=200):
    """Five conditions, the middle pair alike and the rest 0.5 apart: `n_step` votes on each pair 0.5 apart
    (won as the odds say), `n_alike` split evenly between the alike two."""
    truth = np.array([1.0, 0.5, 0.5, 0.0, -0.5])
    w = np.zeros((5, 5))
    for i, j in ((0, 1), (2, 3), (3, 4)):
        w[i, j], w[j, i] = n_step * expit(truth[i] - truth[j]), n_step * expit(truth[j] - truth[i])
    w[1, 2] = w[2, 1] = n_alike / 2
    return pair_posterior.fit(w)


def test_an_alike_pair_stops_drawing_votes_at_about_three_times_a_neighbours(monkeypatch):
    # Every vote counts as evidence of at least half the median neighbour gap (0.25 here), so the alike pair's
    # evidence stays below a neighbouring pair's while it has fewer than about (0.5 + 0.25) / 0.25 = 3 times that
    # pair's 200 votes, and is above it after.
    at = pair_index(5)
    assert np.argmin(pair_posterior.evidence(chain_posterior(200))) == at[(1, 2)]
    for n, below in ((500, True), (700, False), (2000, False)):
        e = pair_posterior.evidence(chain_posterior(n))
        assert (e[at[(1, 2)]] < min(e[at[(0, 1)]], e[at[(3, 4)]])) == below
    # without the floor it would go on drawing votes: its |d| stays near 0 however many it has
    monkeypatch.setattr(pair_posterior, "ALIKE_FLOOR", 0.0)
    assert np.argmin(pair_posterior.evidence(chain_posterior(8000))) == at[(1, 2)]


def test_at_the_same_p_of_order_the_pair_with_fewer_votes_is_asked_first():
    # Both pairs' orders hold with the same probability (z = 1.5); the sequential test asks about the one whose
    # estimate rests on fewer votes, where a z-score would see no difference.
    k, w = 4, np.zeros((4, 4))
    for (i, j), n in (((0, 1), 100), ((2, 3), 1600)):
        d = 1.5 / math.sqrt(n / 4)  # z = d / sd, sd = 1 / sqrt(n p (1 - p)) at p about 1/2
        w[i, j], w[j, i] = n * expit(d), n * expit(-d)
    post = pair_posterior.fit(w, prior_sd=1e3)
    at = pair_index(k)
    z = [(post.mean[x] - post.mean[y]) / math.sqrt(post.cov[x, x] + post.cov[y, y] - 2 * post.cov[x, y])
         for x, y in ((0, 1), (2, 3))]  # fmt: skip
    assert z[0] == pytest.approx(z[1], rel=0.02)
    e = pair_posterior.evidence(post)
    assert e[at[(0, 1)]] < e[at[(2, 3)]] / 3


def test_a_pair_one_condition_wins_every_time_is_not_asked_again():
    # A beat B in all 30 votes; B against C is 15 to 15. At the fitted odds A over B's information p (1 - p) would
    # vanish and its order look the less certain; at even odds, where the evidence weighs it, it is the clear one.
    post = pair_posterior.fit(np.array([[0.0, 30.0, 0.0], [0.0, 0.0, 15.0], [0.0, 15.0, 0.0]]))
    e = pair_posterior.evidence(post)
    assert np.argmin(e) == 2 and e[0] > 10  # pairs(3): (0, 1), (0, 2), (1, 2)


def test_the_pair_the_order_is_least_sure_of_is_asked_first():
    rng = np.random.default_rng(3)
    truth = np.array([1.0, 0.3, 0.25, -0.4, -1.5])
    post = pair_posterior.fit(simulate(truth, 150, rng))
    i, j = pair_posterior.pairs(5)[np.argmin(pair_posterior.evidence(post))]
    assert {i, j} == {1, 2}  # the closest adjacent pair
    for seed in range(10):  # and the app's order of pairs starts there
        assert pair_posterior.pick_order(post, np.random.default_rng(seed), 0.0)[0] == np.argmin(
            pair_posterior.evidence(post)
        )


def test_held_votes_move_the_next_choice_on():
    w = simulate(np.array([0.4, 0.0, -0.4]), 60, np.random.default_rng(4))
    post = pair_posterior.fit(w)
    first = np.argmin(pair_posterior.evidence(post))
    assert np.allclose(pair_posterior.with_counts(post, w + w.T).cov, post.cov)
    i, j = pair_posterior.pairs(3)[first]
    held = w + w.T
    held[i, j] += 200  # many slots of that pair given out, not yet answered
    held[j, i] += 200
    assert np.argmin(pair_posterior.evidence(pair_posterior.with_counts(post, held))) != first


def test_with_no_votes_every_pair_is_as_likely_to_be_asked_first():
    post = pair_posterior.fit(np.zeros((4, 4)))
    firsts = {int(pair_posterior.pick_order(post, np.random.default_rng(s), 0.0)[0]) for s in range(60)}
    assert firsts == set(range(6))


def run_study(truth, level, rng, cap=4000, check=20, width=None):
    """Votes on the least-voted pair until the rule says settled (or the cap): (stopped, every pair right)."""
    k = len(truth)
    pr = pair_posterior.pairs(k)
    w = np.zeros((k, k))
    post = pair_posterior.fit(w)
    while w.sum() < cap:
        for _ in range(check):
            n = (w + w.T)[pr[:, 0], pr[:, 1]]
            i, j = pr[rng.choice(np.flatnonzero(n == n.min()))]
            w[(i, j) if rng.random() < expit(truth[i] - truth[j]) else (j, i)] += 1
        post = pair_posterior.fit(w, start=post.mean)
        if pair_posterior.settledness(post, level, width)["settled"]:
            return True, bool((np.argsort(-post.mean) == np.argsort(-truth)).all()), w.sum()
    return False, None, w.sum()


def test_the_stopping_rule_on_simulated_strengths_errs_no_more_than_its_level():
    rng = np.random.default_rng(5)
    truth = np.array([0.6, 0.3, 0.0, -0.3])
    runs = [run_study(truth, 0.9, rng) for _ in range(60)]
    stopped = [r for r in runs if r[0]]
    assert len(stopped) == 60  # 0.3 apart: every study settles well before the cap
    wrong = sum(not r[1] for r in stopped)
    # nominal 10%: 6 of 60 expected at most; 12 would be beyond any sampling noise (binomial p < 0.01)
    assert wrong <= 11, wrong
    # a stricter level costs more votes
    strict = [run_study(truth, 0.99, np.random.default_rng([5, i]))[2] for i in range(10)]
    assert np.median(strict) > np.median([r[2] for r in stopped])


def test_not_settled_from_nothing_and_the_width_rule():
    s = pair_posterior.settledness(pair_posterior.fit(np.zeros((4, 4))), 0.95)
    assert not s["settled"] and s["weakest"] == 0.5 and s["needed"] == pytest.approx(1 - 0.05 / 3)
    # two equal conditions never separate, but many votes make their intervals narrow
    w = np.array([[0.0, 5000.0], [5000.0, 0.0]])
    post = pair_posterior.fit(w)
    assert not pair_posterior.settledness(post, 0.95)["settled"]
    s = pair_posterior.settledness(post, 0.95, width=50.0)
    assert s["narrow"] and s["settled"] and not s["separated"] and s["widest"] < 50.0
    assert not pair_posterior.settledness(post, 0.95, width=s["widest"] / 2)["settled"]


# ------------------------------------------------------------------ the indifference zone (issue 55 item 8)
MARGIN = 25.0  # Elo


def near_tie_posterior(n_tie=3000):
    """Four conditions 0.5 apart, but the middle two alike: `n_tie` votes between them split evenly."""
    rng = np.random.default_rng(6)
    w = simulate(np.array([1.0, 0.5, 0.5, -0.5]), 2000, rng)
    w[1, 2] += n_tie / 2
    w[2, 1] += n_tie / 2
    return pair_posterior.fit(w)


def test_a_pair_confidently_within_the_margin_is_tied_and_gets_no_active_vote():
    post = near_tie_posterior()
    at = pair_index(4)
    tied = pair_posterior.tied(post, MARGIN)
    assert tied[at[(1, 2)]] and tied.sum() == 1
    assert not pair_posterior.tied(post, 0.0).any()  # no margin, no tie
    e = pair_posterior.evidence(post, MARGIN)
    assert e[at[(1, 2)]] == np.inf and np.isfinite(np.delete(e, at[(1, 2)])).all()
    # without the margin, it is the weakest while its votes are well under three times its neighbours' (the floor):
    # with 100 more, about 435 against their 330
    assert np.argmin(pair_posterior.evidence(near_tie_posterior(n_tie=100))) == at[(1, 2)]
    for seed in range(20):  # the app's order of pairs to try: the tied pair last, whatever the draw
        order = pair_posterior.pick_order(post, np.random.default_rng(seed), 0.0, MARGIN)
        assert order[-1] == at[(1, 2)]
    assert pair_posterior.pick_order(post, np.random.default_rng(0), 1.0) is None  # the balanced share


def test_a_tied_adjacent_pair_counts_as_settled():
    post = near_tie_posterior()
    s = pair_posterior.settledness(post, 0.95, margin_elo=MARGIN)
    assert s["settled"] and s["tied"] in ([(1, 2)], [(2, 1)])
    assert not pair_posterior.settledness(post, 0.95)["settled"]  # without the margin, never
    few = near_tie_posterior(n_tie=40)  # too few votes to be confident the two are alike
    assert not pair_posterior.settledness(few, 0.95, margin_elo=MARGIN)["settled"]
