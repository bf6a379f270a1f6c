"""Catch trials from a pool (issue 37, item 2): each rater gets CATCH_PER_RATER catch units, least-covered first,
so a catch unit reaches about the same share of raters as a test unit, and the clips two sessions share do not
point at the catch trials. Many sessions at the production settings, in every design, on SQLite and PostgreSQL."""

import collections
import itertools

import pytest
from helpers.fake_stimuli import write_fake_stimuli
from helpers.tiers import only_when_slow
from test_app_designs import shown, value_for

from moglow_eval.core import study
from rating_app.designs import build_units, get
from rating_app.operations.health import catch_pool_warning
from rating_app.store.manifest import load_manifest

pytestmark = pytest.mark.full  # the full tier: crowds drawing from catch pools

# The production settings of docs/hosting.md: 30 of 90 test units per rater (pairwise: 30 items x 3 pairs;
# parallel: 30 pages, 10 per rater), 20 answers per unit; 12 catch items with 4 per rater give catch units the same
# third of raters.
# Every design of moglow_eval.core.study.DESIGNS: one missing here fails the parametrised test (docs/ARCHITECTURE.md).
# The matched-against-mismatched designs: 30 items x 3 systems, a unit each, 30 per rater.
PRODUCTION = {"acr": 30, "pairwise": 30, "parallel": 10, "appropriateness": 30, "dyadic": 30, "semantic": 30}
TARGET, CATCH_ITEMS, CATCH_PER_RATER = 20, 12, 4


@pytest.fixture(scope="module")
def pool_stimuli(tmp_path_factory):
    """3 conditions x 30 items, 12 catch items (BAD + NAT, MG, FL), 3 training clips."""
    return write_fake_stimuli(
        tmp_path_factory.mktemp("pool_stimuli"),
        n_items=30,
        n_catch=CATCH_ITEMS,
        n_frames=4,
        metrics=False,
        catch_nat=True,
        mismatched=True,  # served only by the matched-against-mismatched designs
    )


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


@pytest.mark.parametrize("design", study.DESIGNS)
@pytest.mark.parametrize("n_sessions", [pytest.param(60, marks=pytest.mark.slow), 24])
def test_catch_units_recur_like_test_units(make, pool_stimuli, design, n_sessions, monkeypatch, request):  # noqa: F811
    """60 sessions (--run-slow: the whole acr study) and a 24-session short variant for CI."""
    if design != "acr" and request.node.callspec.params["app_db_url"] == "sqlite":
        only_when_slow(request, "the short variant runs every design on PostgreSQL and acr on SQLite too")
    catch_recurrence(make, pool_stimuli, design, n_sessions, monkeypatch)


def catch_recurrence(make, stimuli, design, n_sessions, monkeypatch):
    """`n_sessions` sessions of `design` on `stimuli`, checked by check_recurrence_tells_nothing."""
    per_rater = PRODUCTION[design]
    monkeypatch.setenv("RATING_CATCH_PER_RATER", str(CATCH_PER_RATER))  # as gunicorn's settings come
    app = make(stimuli, design, ratings_per_clip=TARGET, clips_per_rater=per_rater, check_files=False)
    sessions = run_sessions(app, n_sessions)
    check_recurrence_tells_nothing(sessions, per_rater)


def test_a_pool_too_small_is_a_warning_and_the_cap_keeps_every_rater_equal(make, pool_stimuli, tmp_path, caplog):  # noqa: F811
    """2 catch items, 4 per rater asked: each rater gets both (the cap), and the app warns, once, on /healthz and
    the dashboard, that catch units then reach every rater while a test unit reaches a third."""
    small = write_fake_stimuli(tmp_path / "small", n_items=3, n_catch=2, n_frames=4, metrics=False)
    app = make(small, "acr", ratings_per_clip=5, clips_per_rater=3, catch_per_rater=4)
    c = app.test_client()
    sessions = run_sessions(app, 2, at_once=2)
    assert [sum(k == "catch" for k, _ in s) for s in sessions] == [2, 2]
    warned = c.get("/healthz").json["warnings"]
    assert len(warned) == 1 and "catch pool too small" in warned[0] and "100%" in warned[0], warned
    assert sum("catch pool too small" in r.getMessage() for r in caplog.records) == 1
    page = c.get("/admin", headers={"Authorization": "Bearer test-admin-token"}).get_data(as_text=True)
    assert 'id="warnings"' in page and "catch pool too small" in page
    # the production pool, in every design: no warning
    clips = load_manifest(pool_stimuli)
    for design, per_rater in PRODUCTION.items():
        served = get(design).serving_clips(clips)  # as the app serves them: the mismatched clips in their designs
        units = build_units(design, served)
        assert catch_pool_warning(design, served, units, per_rater, CATCH_PER_RATER) is None
        assert catch_pool_warning(design, served, units, per_rater, 12) is not None  # every catch unit to everyone
