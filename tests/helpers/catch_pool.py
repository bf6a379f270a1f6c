"""Catch units drawn from a pool at the production settings: many sessions interleaved as a crowd's overlap, and
the check that a catch unit recurs like a test unit. Run by tests/rating_app/test_catch_pool.py in every design
and by tests/rating_app/test_active.py with active pairing."""

import collections
import itertools

from .design_client import shown, value_for

# The production settings of docs/hosting.md: 30 of 90 test units per rater (pairwise: 30 items x 3 pairs;
# parallel: 30 pages, 10 per rater), 20 answers per unit; 12 catch items with 4 per rater give catch units the same
# third of raters.
# Every design of moglow_eval.core.study.DESIGNS: one missing here fails the parametrised test (docs/ARCHITECTURE.md).
# The matched-against-mismatched designs: 30 items x 3 systems, a unit each, 30 per rater.
PRODUCTION = {"acr": 30, "pairwise": 30, "parallel": 10, "appropriateness": 30, "dyadic": 30, "semantic": 30}
TARGET, CATCH_ITEMS, CATCH_PER_RATER = 20, 12, 4
# Sessions a recurrence check runs: two rounds of six interleaved. Each catch unit then reaches 4 of the 12 raters, as
# each test unit does, when least-covered-first holds; drawn at random, a catch unit's reach would fall outside 1.5x of
# the test units' share (3 to 6 raters) with a chance of 1 in 4, so one of the 12 would in nearly every run. 24 sessions
# gave the same shares (the whole acr study is 60: `catch_recurrence(..., 60, ...)` by hand).
SESSIONS = 12


def run_sessions(app, n_sessions, at_once=6):
    """Each session's rating trials as [(kind, clip ids)], `at_once` sessions interleaved trial by trial, as a
    crowd's sessions overlap; kind is catch when a clip of the trial has role catch."""
    roles = {i: c.role for i, c in app.extensions["rating_app"]["clips"].items()}
    c = app.test_client()
    out = []
    for start in range(0, n_sessions, at_once):
        tokens = []
        for _ in range(min(at_once, n_sessions - start)):
            r = c.post("/api/sessions", json={})
            assert r.status_code == 201, r.json
            tokens.append(r.json["session"])
        seen = {t: [] for t in tokens}
        live = list(tokens)
        while live:
            for token in list(live):
                r = c.get(f"/api/sessions/{token}/next")
                assert r.status_code == 200, r.json
                if r.json.get("done"):
                    live.remove(token)
                    continue
                t = r.json["trial"]
                if t["phase"] == "rating":
                    ids = tuple(x["clip_id"] for x in shown(t))
                    kind = "catch" if any(roles[i] == "catch" for i in ids) else "test"
                    seen[token].append((kind, ids))
                r = c.post(f"/api/sessions/{token}/ratings", json={"trial_id": t["trial_id"], **value_for(t)})
                assert r.status_code == 201, r.json
        out += seen.values()
    return out


def check_recurrence_tells_nothing(sessions, per_rater):
    n = len(sessions)
    # every rater sees the same number of catch trials
    per_session = collections.Counter(sum(k == "catch" for k, _ in s) for s in sessions)
    assert per_session == {CATCH_PER_RATER: n}, per_session
    # the share of raters each unit reaches: every catch unit within 1.5x of the mean test unit's
    reach = {"test": collections.Counter(), "catch": collections.Counter()}
    for s in sessions:
        for kind, ids in s:
            reach[kind][ids if len(ids) == 1 else frozenset(ids)] += 1
    test_share = sum(reach["test"].values()) / len(reach["test"]) / n
    assert len(reach["catch"]) == CATCH_ITEMS
    for unit, k in reach["catch"].items():
        assert test_share / 1.5 <= k / n <= test_share * 1.5, (k / n, test_share)
    # among the clips two sessions share, catch clips are no more frequent than among the clips a session sees
    clips = [{(kind, i) for kind, ids in s for i in ids} for s in sessions]
    seen_share = sum(sum(k == "catch" for k, _ in c) / len(c) for c in clips) / n
    shared = collections.Counter()
    for a, b in itertools.combinations(clips, 2):
        for kind, _ in a & b:
            shared[kind] += 1
    shared_share = shared["catch"] / (shared["catch"] + shared["test"])
    assert shared_share <= seen_share * 1.2 + 0.02, (shared_share, seen_share)
    return test_share, shared_share, seen_share


def catch_recurrence(make, stimuli, design, n_sessions, monkeypatch):
    """`n_sessions` sessions of `design` on `stimuli`, checked by check_recurrence_tells_nothing."""
    per_rater = PRODUCTION[design]
    monkeypatch.setenv("RATING_CATCH_PER_RATER", str(CATCH_PER_RATER))  # as gunicorn's settings come
    app = make(stimuli, design, ratings_per_clip=TARGET, clips_per_rater=per_rater, check_files=False)
    sessions = run_sessions(app, n_sessions)
    check_recurrence_tells_nothing(sessions, per_rater)
