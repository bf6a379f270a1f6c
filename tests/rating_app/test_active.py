"""Active pairing and the stopping rule of a pairwise study (CONTRACTS §8), on SQLite and PostgreSQL.

`--pairing active` only chooses among the units the balanced rule allows, so the pairwise checks that
test_app_designs.py and test_catch_pool.py run (helpers/design_checks.py and catch_pool.py: the flow, every unit
and catch pair, the sides drawn per trial, catch failures, bad input, an idle session's pair given back, exact
targets alone and under concurrent sessions, catch units recurring like test units) run here again with it on;
then what it changes: the votes go to the pairs the ranking is unsure of. `--stop-when settled` closes the study
to new raters, never to started ones."""

import collections

import pytest
from helpers.api_client import TOKEN_HDR
from helpers.catch_pool import SESSIONS, catch_recurrence
from helpers.concurrent_raters import cover_mismatches
from helpers.design_checks import (
    an_idle_session_gives_its_pair_back,
    pairwise_bad_input_and_training,
    pairwise_catch_failures_on_the_dashboard,
    pairwise_flow_units_catch_and_export,
    targets_exact_under_concurrent_sessions,
    targets_reached_exactly_with_fewest_raters,
)
from helpers.design_client import complete, export, post, start

from rating_app import AppError, create_app
from rating_app.pairing import active
from rating_app.store.db import app_engine


@pytest.fixture
def active_make(make, monkeypatch):
    """`make` with --pairing active, the posterior refitted at every call (not at most once a second)."""
    monkeypatch.setattr(active, "REFRESH_S", 0.0)
    return lambda manifest, design, **kw: make(manifest, design, **{"pairing": "active", **kw})


# ------------------------------------------------------------------------------------ the rules it keeps
def test_flow_units_catch_sides_and_export(active_make, stimuli):
    pairwise_flow_units_catch_and_export(active_make, stimuli)


def test_catch_failures_on_the_dashboard(active_make, stimuli):
    pairwise_catch_failures_on_the_dashboard(active_make, stimuli)


def test_bad_input_and_training(active_make, stimuli):
    pairwise_bad_input_and_training(active_make, stimuli)


def test_an_idle_session_gives_its_pair_back(active_make, stimuli):
    an_idle_session_gives_its_pair_back(active_make, stimuli)


@pytest.mark.full  # the full tier: crowds, as in the modules these checks come from
def test_targets_reached_exactly_with_fewest_raters(active_make, big_stimuli):
    targets_reached_exactly_with_fewest_raters(active_make, big_stimuli, "pairwise")


@pytest.mark.full  # the full tier: crowds, as in the modules these checks come from
def test_targets_exact_under_concurrent_sessions(active_make, big_stimuli):
    targets_exact_under_concurrent_sessions(active_make, big_stimuli, "pairwise")


@pytest.mark.full  # the full tier: crowds, as in the modules these checks come from
def test_catch_units_recur_like_test_units(active_make, pool_stimuli, monkeypatch):
    catch_recurrence(active_make, pool_stimuli, "pairwise", SESSIONS, monkeypatch)


# ---------------------------------------------------------------------------------- what it changes
def conditions(app, t):
    clips = app.extensions["rating_app"]["clips"]
    return clips[t["a"]["clip_id"]].condition, clips[t["b"]["clip_id"]].condition


def crowd(app, n_raters, prefer):
    """`n_raters` sessions one after another, each answering prefer(condition A, condition B, i); the number
    of test votes per pair of conditions, and the status of the last new session."""
    c = app.test_client()
    votes, i = collections.Counter(), 0
    for _ in range(n_raters):
        r = c.post("/api/sessions", json={})
        if r.status_code != 201:
            return votes, r
        token = r.json["session"]
        while not (r := c.get(f"/api/sessions/{token}/next")).json.get("done"):
            t = r.json["trial"]
            value = None
            if t["phase"] == "rating":
                a, b = conditions(app, t)
                value, i = prefer(a, b, i), i + 1
                if "BAD" not in (a, b):
                    votes[" vs ".join(sorted((a, b)))] += 1
            assert post(c, token, t, preference=value).status_code == 201
    return votes, r


RANK = {"NAT": 3, "MG": 2, "FL": 1, "BAD": 0}


def nat_clearly_mg_fl_a_toss_up(a, b, i):
    """NAT always clearly best; MG against FL each way in turn (so that pair stays uncertain)."""
    if "NAT" in (a, b) or "BAD" in (a, b):
        return 2 if RANK[a] > RANK[b] else -2
    return 1 if i % 2 else -1


@pytest.mark.parametrize("pairing", ["active", "balanced"])
def test_active_pairing_spends_the_votes_on_the_uncertain_pair(make, big_stimuli, monkeypatch, pairing):
    monkeypatch.setattr(active, "REFRESH_S", 0.0)
    app = make(big_stimuli, "pairwise", ratings_per_clip=20, clips_per_rater=15, pairing=pairing)
    votes, _ = crowd(app, 12, nat_clearly_mg_fl_a_toss_up)
    assert sum(votes.values()) == 12 * 15
    if pairing == "balanced":  # least-covered first: every pair alike
        assert max(votes.values()) - min(votes.values()) <= 1, votes
    else:  # the toss-up pair gets most; the pair of the two ends (NAT, FL) only the random share's
        assert votes["FL vs MG"] > 2 * votes["FL vs NAT"] and votes["FL vs MG"] > votes["MG vs NAT"], votes
    assert cover_mismatches(app_engine(app)) == {}


# ---------------------------------------------------------------------------------- the stopping rule
def test_a_settled_ranking_closes_the_study_to_new_raters_only(make, big_stimuli, monkeypatch):
    monkeypatch.setattr(active, "REFRESH_S", 0.0)
    app = make(big_stimuli, "pairwise", ratings_per_clip=20, clips_per_rater=6, stop_when="settled")
    c = app.test_client()
    early = start(c)  # started before the stop: it may finish
    votes, refused = crowd(app, 30, lambda a, b, i: 2 if RANK[a] > RANK[b] else -2)
    assert refused.status_code == 409 and refused.json["closed"] and refused.json["full"], refused.json
    assert "ranking is settled" in refused.json["error"]
    p = c.get("/admin/progress.json", headers=TOKEN_HDR).json["ranking"]
    assert p["closed"] and p["settled"] and p["order"] == ["NAT", "MG", "FL"]
    # one Elo anchor with the report's (issue 63): the reference at 1000, the others below it as they lost
    assert p["elo_anchor"] == "NAT" and p["elo"]["NAT"] == 1000.0 and p["elo"]["FL"] < p["elo"]["MG"] < 1000.0
    assert p["weakest_separation"] >= p["separation_needed"] == pytest.approx(1 - 0.05 / 2)
    assert p["votes"] == sum(votes.values()) < 20 * 90  # long before the targets
    trials, done = complete(
        c, early, pref=lambda t: 2 if RANK[conditions(app, t)[0]] > RANK[conditions(app, t)[1]] else -2
    )
    assert done["done"] and trials
    page = c.get("/admin", headers=TOKEN_HDR).get_data(as_text=True)
    assert "closed to new raters" in page and 'id="ranking"' in page and '<strong id="elo-anchor">NAT</strong>' in page


def toss_up(a, b, i):
    """Each way in turn on a test pair; the NAT clip of a catch pair, always."""
    if "BAD" in (a, b):
        return 2 if RANK[a] > RANK[b] else -2
    return 1 if i % 2 else -1


def test_the_vote_cap_closes_the_study(make, stimuli):
    app = make(stimuli, "pairwise", ratings_per_clip=20, stop_when="settled", stop_max_votes=5)
    # A toss-up, never settled, from raters who pass their catch trials (so every test vote is trusted and counts).
    votes, refused = crowd(app, 30, toss_up)
    assert refused.status_code == 409 and "all the votes" in refused.json["error"]
    p = app.test_client().get("/admin/progress.json", headers=TOKEN_HDR).json["ranking"]
    assert p["closed"] and not p["settled"] and p["votes"] == sum(votes.values()) >= 5 == p["max_votes"]


def test_the_defaults_change_nothing_and_bad_settings_stop_the_start(make, stimuli, app_db_url):
    app = make(stimuli, "pairwise")
    assert app.config["PAIRING"] == "balanced" and app.config["STOP_WHEN"] == "never"
    assert "ranking" not in app.extensions["rating_app"]
    assert "ranking" not in app.test_client().get("/admin/progress.json", headers=TOKEN_HDR).json
    for kw, needle in (
        ({"design": "acr", "pairing": "active"}, "pairing: active needs the pairwise design, not acr"),
        ({"design": "parallel", "stop_when": "settled"}, "stop_when: settled needs the pairwise design"),
        ({"design": "pairwise", "pairing": "smart"}, "pairing: 'smart' must be one of balanced, active"),
        ({"design": "pairwise", "stop_level": "1"}, "stop_level"),
        ({"design": "pairwise", "pairing_random": "1.5"}, "pairing_random"),
        ({"design": "pairwise", "stop_max_votes": "-1"}, "stop_max_votes"),
    ):
        with pytest.raises(AppError, match=needle) as e:
            create_app(manifest=stimuli, db_url=app_db_url, **kw)
        assert "\n" not in str(e.value)


# ---------------------------------------------------------------------------------- only trusted votes
def bot(a, b, i):
    """A bot (issue 55, failure 1): prefers the bad example of every catch pair, votes a fixed order elsewhere."""
    if "BAD" in (a, b):
        return 2 if a == "BAD" else -2
    return 2 if RANK[a] > RANK[b] else -2


def test_raters_who_failed_catch_trials_neither_close_the_study_nor_move_its_pairs(make, big_stimuli, monkeypatch):
    monkeypatch.setattr(active, "REFRESH_S", 0.0)
    app = make(big_stimuli, "pairwise", ratings_per_clip=20, clips_per_rater=12, pairing="active", stop_when="settled")
    votes, last = crowd(app, 2, bot)  # two whole bot sessions, each failing its catch trials
    assert sum(votes.values()) == 24 and last.json["done"]
    c = app.test_client()
    assert c.post("/api/sessions", json={}).status_code == 201  # the study stays open to the next rater
    p = c.get("/admin/progress.json", headers=TOKEN_HDR).json
    k = p["ranking"]
    assert not k["settled"] and not k["closed"]
    assert k["votes"] == 0 and k["votes_excluded"] == 24 and k["raters_excluded"] == 2
    assert set(k["elo"].values()) == {1000.0}  # the posterior the pairs are chosen from has not moved
    ranking = active.of_app(app)
    assert not ranking.post.mean.any() and not ranking.counts.any()
    assert p["raters_excluded"] == 2 and [r["excluded"] for r in p["raters"]] == [True, True, False]
    # The bots' votes are kept, every one flagged.
    rows = export(c)[0]
    assert len(rows) >= 24 and all("failed_catch" in r["flags"].split(";") for r in rows)
    page = c.get("/admin", headers=TOKEN_HDR).get_data(as_text=True)
    assert "24 more from 2 excluded raters" in page


def test_a_trusted_rater_still_settles_the_study_beside_flagged_ones(make, big_stimuli, monkeypatch):
    monkeypatch.setattr(active, "REFRESH_S", 0.0)
    app = make(big_stimuli, "pairwise", ratings_per_clip=20, clips_per_rater=6, stop_when="settled")
    # Two bots that fail their catch trials and vote the order upside down.
    crowd(app, 2, lambda a, b, i: bot(a, b, i) if "BAD" in (a, b) else -bot(a, b, i))
    _, refused = crowd(app, 30, lambda a, b, i: 2 if RANK[a] > RANK[b] else -2)
    assert refused.status_code == 409
    k = app.test_client().get("/admin/progress.json", headers=TOKEN_HDR).json["ranking"]
    assert k["order"] == ["NAT", "MG", "FL"] and k["raters_excluded"] == 2


# ---------------------------------------------------------------------------------- the indifference zone
def nat_best_mg_fl_alike(a, b, i):
    """NAT clearly best (and the catch pairs passed); MG and FL alike: no preference between them."""
    if "NAT" in (a, b) or "BAD" in (a, b):
        return 2 if RANK[a] > RANK[b] else -2
    return 0


@pytest.mark.full  # crowds until settled: the full tier
# The control without a margin on SQLite only: which database holds the votes is the app's concern, tested above.
@pytest.mark.parametrize(
    "margin, app_db_url", [(200.0, "sqlite"), (200.0, "postgres"), (0.0, "sqlite")], indirect=["app_db_url"]
)
def test_conditions_alike_are_tied_and_settle_the_study(make, big_stimuli, monkeypatch, margin, app_db_url):
    monkeypatch.setattr(active, "REFRESH_S", 0.0)
    app = make(big_stimuli, "pairwise", ratings_per_clip=20, clips_per_rater=15, pairing="active",
               stop_when="settled", pairing_indifference=margin, stop_max_votes=240)  # fmt: skip
    votes, refused = crowd(app, 30, nat_best_mg_fl_alike)
    k = app.test_client().get("/admin/progress.json", headers=TOKEN_HDR).json["ranking"]
    assert refused.status_code == 409 and k["closed"] and k["order"][0] == "NAT"
    if margin:  # settled with MG and FL tied, long before the cap
        assert k["settled"] and sorted(k["tied"][0]) == ["FL", "MG"] and k["indifference"] == margin
        assert k["votes"] < 240
    else:  # no margin: an order of two alike conditions never settles; only the cap closes the study
        assert not k["settled"] and k["tied"] == [] and k["votes"] >= 240
