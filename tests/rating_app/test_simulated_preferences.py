"""The simulated crowd's pairwise choices (rating_app/simulate/raters.py): the side follows a Bradley-Terry model of
the clips' qualities (log strength BT_SCALE x quality), the certainty (tie, slightly, clearly) how far that is
from a toss-up, blurred per rater; catch pairs and careless raters as before."""

import math

import numpy as np
import pytest
from scipy.stats import binomtest

from moglow_eval.core import pair_posterior
from rating_app.simulate.raters import BT_SCALE, ClipInfo, bt_probability, make_raters

RATERS = make_raters(100, seed=3, careless=0.0, prefix="bt")


def clip(cid, condition, quality, role="test"):
    return ClipInfo(cid, condition, role, quality=quality)


def answers(qa, qb, per_rater=30):
    a, b = clip("a", "X", qa), clip("b", "Y", qb)
    return np.array([r.prefer(a, b) for r in RATERS for _ in range(per_rater)])


def test_the_side_follows_bradley_terry_on_the_qualities():
    assert bt_probability(4.2, 3.6) == pytest.approx(1 / (1 + math.exp(-BT_SCALE * 0.6)))
    for qa, qb in ((4.2, 3.6), (3.0, 3.0), (2.0, 4.5), (3.5, 3.25)):
        x = answers(qa, qb)
        decisive = x[x != 0]
        wins = int((decisive > 0).sum())
        # among the answers that prefer a clip, A's share is the model's (a 3000-answer crowd; p < 0.001 fails)
        assert binomtest(wins, len(decisive), bt_probability(qa, qb)).pvalue > 1e-3, (qa, qb, wins, len(decisive))


def test_a_fit_on_the_crowd_recovers_the_strengths():
    q = {"NAT": 4.2, "MG": 3.6, "FL": 2.6}
    names = list(q)
    firsts, seconds, outcomes = [], [], []
    for i, j in pair_posterior.pairs(3):
        x = answers(q[names[i]], q[names[j]], per_rater=20)
        firsts += [i] * len(x)
        seconds += [j] * len(x)
        outcomes += [1.0 if v > 0 else 0.0 if v < 0 else 0.5 for v in x]
    decisive = np.array(outcomes) != 0.5
    post = pair_posterior.fit(
        pair_posterior.win_counts(
            3, np.array(firsts)[decisive], np.array(seconds)[decisive], np.array(outcomes)[decisive]
        ),
        prior_sd=100.0,
    )
    want = BT_SCALE * np.array([q[n] for n in names])
    got, sd = post.mean - post.mean[0], np.sqrt(np.diag(post.cov) + post.cov[0, 0] - 2 * post.cov[0])
    assert np.all(np.abs(got - (want - want[0]))[1:] < 4 * sd[1:]), (got, want - want[0], sd)


def test_ties_near_a_toss_up_and_clear_answers_far_from_it():
    even, near, far = answers(3.0, 3.0), answers(3.6, 3.5), answers(4.5, 2.0)
    share = lambda x, levels: float(np.isin(np.abs(x), levels).mean())  # noqa: E731
    assert share(even, [0]) > 0.3 and share(far, [0]) < 0.01
    assert share(far, [2]) > 0.95 and share(even, [2]) < 0.01
    assert share(even, [0]) > share(near, [0]) > share(far, [0])
    # every level occurs somewhere between
    assert set(np.unique(near)) == {-2, -1, 0, 1, 2}


def test_raters_differ_in_how_sure_they_are():
    from scipy.stats import spearmanr

    a, b = clip("a", "X", 3.2), clip("b", "Y", 3.2)
    ties = [np.mean([r.prefer(a, b) == 0 for _ in range(400)]) for r in RATERS[:40]]
    # the noisier a rater, the more often its certainty leaves the tie band of a toss-up
    assert spearmanr([r.noise_sd for r in RATERS[:40]], ties).statistic < -0.6


def test_catch_pairs_and_careless_raters_as_before():
    nat, bad = clip("n", "NAT", 4.2, "catch"), clip("x", "BAD", 1.3, "catch")
    for r in RATERS[:20]:
        assert r.prefer(nat, bad) > 0 and r.prefer(bad, nat) < 0
    careless = make_raters(50, seed=4, careless=1.0, prefix="c")
    x = [r.prefer(nat, bad) for r in careless for _ in range(40)]
    assert set(x) == {-2, -1, 0, 1, 2} and abs(np.mean(x)) < 0.2
