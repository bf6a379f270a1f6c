"""Catch trials from a pool (issue 37, item 2): each rater gets CATCH_PER_RATER catch units, least-covered first,
so a catch unit reaches about the same share of raters as a test unit, and the clips two sessions share do not
point at the catch trials. Many sessions at the production settings, in every design, on SQLite and PostgreSQL."""

import pytest
from helpers.catch_pool import CATCH_PER_RATER, PRODUCTION, SESSIONS, catch_recurrence, run_sessions
from helpers.fake_stimuli import write_fake_stimuli

from moglow_eval.core import study
from rating_app.designs import build_units, get
from rating_app.operations.health import catch_pool_warning
from rating_app.store.manifest import load_manifest

pytestmark = pytest.mark.full  # the full tier: crowds drawing from catch pools


# Every design on PostgreSQL, and acr on SQLite too: which database holds the answers is the app's concern.
DESIGN_DATABASES = [(d, "postgres") for d in study.DESIGNS] + [("acr", "sqlite")]


@pytest.mark.parametrize("design, app_db_url", DESIGN_DATABASES, indirect=["app_db_url"])
def test_catch_units_recur_like_test_units(make, pool_stimuli, design, app_db_url, monkeypatch):
    """SESSIONS sessions of every design (helpers/catch_pool.py says why that many)."""
    catch_recurrence(make, pool_stimuli, design, SESSIONS, monkeypatch)


def test_a_pool_too_small_is_a_warning_and_the_cap_keeps_every_rater_equal(make, pool_stimuli, tmp_path, caplog):
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
