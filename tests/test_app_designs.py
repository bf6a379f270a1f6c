"""Pairwise and parallel studies through the JSON API (CONTRACTS §8): the flow, the units and their balance (also
under concurrent sessions), catch trials and their failures, the viewing rule, idempotency, bad input, the design
stored with the study, export and dashboard. Each test runs on SQLite and on PostgreSQL."""

import collections
import csv
import datetime as dt
import io
import itertools
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from helpers.concurrent_raters import cover_mismatches, run_raters
from helpers.fake_stimuli import write_fake_stimuli
from sqlalchemy import update
from test_app_api import TOKEN_HDR, idle

from moglow_eval.core import study
from rating_app import create_app
from rating_app.store.db import Trial, app_engine, utcnow
from rating_app.store.manifest import AppError, load_manifest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def stimuli(tmp_path_factory):
    return write_fake_stimuli(tmp_path_factory.mktemp("design_stimuli"), catch_nat=True)


@pytest.fixture(scope="module")
def big_stimuli(tmp_path_factory):
    """3 conditions x 30 items, 4 catch items (BAD + NAT, MG, FL), 3 training clips."""
    return write_fake_stimuli(
        tmp_path_factory.mktemp("big_stimuli"),
        n_items=30,
        n_catch=4,
        n_frames=4,
        metrics=False,
        catch_nat=True,
        mismatched=True,  # served only by the matched-against-mismatched designs
    )


def clips_of(manifest):
    return {c.clip_id: c for c in load_manifest(manifest)}


def shown(t):
    return [t] if "clip_id" in t else [t["a"], t["b"]] if "a" in t else t["clips"]


def value_for(t, pref=1, rating=lambda i, c: 40 + i):
    if "clip_id" in t:  # acr
        return {"rating": None if t["phase"] == "training" else 3}
    if t["phase"] == "training":
        return {"preference": None} if "a" in t else {"ratings": None}
    if "a" in t:
        return {"preference": pref(t) if callable(pref) else pref}
    return {"ratings": {c["clip_id"]: rating(i, c) for i, c in enumerate(t["clips"])}}


def post(c, token, t, **value):
    body = value or value_for(t)
    return c.post(f"/api/sessions/{token}/ratings", json={"trial_id": t["trial_id"], "watched_ms": 900, **body})


def complete(c, token, **answer):
    seen = []
    for _ in range(400):
        r = c.get(f"/api/sessions/{token}/next")
        assert r.status_code == 200, r.json
        if r.json.get("done"):
            return seen, r.json
        t = r.json["trial"]
        for x in shown(t):
            assert c.get(x["video_url"]).status_code == 200
        seen.append(t)
        r = post(c, token, t, **value_for(t, **answer))
        assert r.status_code == 201, r.json
    raise AssertionError("session never ended")


def start(c, **body):
    r = c.post("/api/sessions", json=body)
    assert r.status_code == 201, r.json
    return r.json["session"]


def export(c):
    r = c.get("/admin/export.csv", headers=TOKEN_HDR)
    assert r.status_code == 200
    return list(csv.DictReader(io.StringIO(r.data.decode()))), r


# ------------------------------------------------------------------------------------------------- pairwise
def test_pairwise_flow_units_catch_and_export(make, stimuli):
    clips = clips_of(stimuli)
    app = make(stimuli, "pairwise", ratings_per_clip=1)
    c = app.test_client()
    r = c.post("/api/sessions", json={"external_id": "P1", "session_id": "S1"})
    assert r.status_code == 201 and r.json["design"] == "pairwise"
    token = r.json["session"]
    trials, done = complete(c, token, pref=lambda t: 2 if clips[t["a"]["clip_id"]].condition == "NAT" else -1)
    assert done["done"] and done["completion_code"]
    rating = [t for t in trials if t["phase"] == "rating"]
    for t in trials:
        assert t["design"] == "pairwise" and set(t) == {"trial_id", "design", "phase", "index", "of", "a", "b"}
        assert t["a"]["label"] == "A" and t["b"]["label"] == "B"
        assert t["a"]["video_url"].endswith(f"/trials/{t['trial_id']}/clips/A.mp4")
        assert clips[t["a"]["clip_id"]].role == clips[t["b"]["clip_id"]].role
    units = collections.Counter()
    for t in rating:
        a, b = clips[t["a"]["clip_id"]], clips[t["b"]["clip_id"]]
        assert a.item == b.item and a.condition != b.condition  # two conditions of the same item
        units[(a.item, *sorted((a.condition, b.condition)))] += 1
    items = {x.item for x in clips.values() if x.role == "test"}
    want = {(i, *p) for i in items for p in itertools.combinations(sorted(["NAT", "MG", "FL"]), 2)}
    catch = {(x.item, "BAD", "NAT") for x in clips.values() if x.role == "catch"}
    assert set(units) == want | catch and set(units.values()) == {1}  # every pair once, every catch pair
    rows, resp = export(c)
    assert "pairs.csv" in resp.headers["Content-Disposition"]
    assert len(rows) == len(rating)
    by_pair = {(row["clip_a"], row["clip_b"]): row for row in rows}
    for t in rating:
        row = by_pair[(t["a"]["clip_id"], t["b"]["clip_id"])]
        a = clips[t["a"]["clip_id"]]
        assert int(row["preference"]) == (2 if a.condition == "NAT" else -1)
        assert (row["condition_a"], row["condition_b"]) == (a.condition, clips[t["b"]["clip_id"]].condition)
        assert row["item"] == a.item and row["role"] == a.role and row["external_id"] == "P1"
        assert int(row["trial_index"]) == t["index"] and row["submitted_at"].endswith("Z") and row["flags"] == ""
    # A/B sides are drawn per trial: NAT is shown as A in some pairs and as B in others
    sides = collections.Counter(
        clips[t["a"]["clip_id"]].condition == "NAT"
        for t in rating
        if "NAT" in {clips[x["clip_id"]].condition for x in shown(t)}
    )
    assert sides[True] and sides[False]
    assert c.post("/api/sessions", json={}).status_code == 409  # every unit has its target


def test_pairwise_catch_failures_on_the_dashboard(make, stimuli):
    clips = clips_of(stimuli)
    app = make(stimuli, "pairwise", ratings_per_clip=4)
    c = app.test_client()

    def prefer_bad(level):
        def pref(t):
            a = clips[t["a"]["clip_id"]].condition
            if "BAD" not in (a, clips[t["b"]["clip_id"]].condition):
                return 0
            return level if a == "BAD" else -level

        return pref

    outcomes = {}
    for name, pref in (
        ("clearly", prefer_bad(2)),
        ("slightly", prefer_bad(1)),
        ("none", prefer_bad(0)),
        ("good", prefer_bad(-2)),
    ):
        token = start(c, external_id=name)
        complete(c, token, pref=pref)
        outcomes[name] = token
    p = c.get("/admin/progress.json", headers=TOKEN_HDR).json
    assert p["design"] == "pairwise"
    fails = {r["external_id"]: r["catch_failures"] for r in p["raters"]}
    n_catch = sum(x.condition == "BAD" for x in clips.values())
    assert fails == {"clearly": n_catch, "slightly": n_catch, "none": 0, "good": 0}
    assert p["raters_failed_catch"] == 2
    page = c.get("/admin", headers=TOKEN_HDR).data.decode()
    assert "Design: <strong>pairwise</strong>" in page and "pairs.csv" in page


def test_pairwise_bad_input_and_training(make, stimuli):
    app = make(stimuli, "pairwise")
    c = app.test_client()
    token = start(c)
    t = c.get(f"/api/sessions/{token}/next").json["trial"]
    assert t["phase"] == "training"
    assert post(c, token, t, preference=1).status_code == 400  # familiarisation: null only
    assert post(c, token, t, preference=None).status_code == 201
    while t["phase"] == "training":
        t = c.get(f"/api/sessions/{token}/next").json["trial"]
        if t["phase"] == "training":
            assert post(c, token, t, preference=None).status_code == 201
    for body, needle in (
        ({"preference": 3}, "between -2 and 2"),
        ({"preference": 1.5}, "integer"),
        ({"preference": "1"}, "integer"),
        ({"preference": True}, "integer"),
        ({"rating": 3}, "unknown field"),
        ({"ratings": {}}, "unknown field"),
        ({}, "preference"),
    ):
        r = (
            post(c, token, t, **body)
            if body
            else c.post(f"/api/sessions/{token}/ratings", json={"trial_id": t["trial_id"]})
        )
        assert r.status_code == 400 and needle in r.json["error"], (body, r.json)
    assert post(c, token, t, preference=-2).status_code == 201
    again = post(c, token, t, preference=2)  # a repeat: stored once, not changed
    assert again.status_code == 200 and again.json["preference"] == -2
    rows, _ = export(c)
    assert len(rows) == 1 and rows[0]["preference"] == "-2"


@pytest.mark.parametrize("design", ["pairwise", "parallel"])
def test_viewing_rule_counts_every_clip(make, stimuli, design):
    """pairwise: both clips can play at once (the longer one's time); parallel: one after another (the sum)."""
    clips = clips_of(stimuli)
    dur = next(iter(clips.values())).duration_ms
    need = dur - 250 if design == "pairwise" else None
    if True:
        app = make(stimuli, design, min_view=1)
        c = app.test_client()
        token = start(c)
        t = c.get(f"/api/sessions/{token}/next").json["trial"]
        r = post(c, token, t)
        assert r.status_code == 425 and r.json["too_early"], r.json
        n = len(shown(t))
        want = need if need is not None else n * dur - 250
        assert want - 300 < r.json["retry_after_ms"] <= want
        with app_engine(app).begin() as conn:
            conn.execute(
                update(Trial)
                .where(Trial.id == t["trial_id"])
                .values(served_at=utcnow() - dt.timedelta(milliseconds=want + 50))
            )
        assert post(c, token, t).status_code == 201
        p = c.get("/admin/progress.json", headers=TOKEN_HDR).json
        assert p["raters"][-1]["early_answers"] == 1 and "too_fast" in p["raters"][-1]["flags"]


# ------------------------------------------------------------------------------------------------- parallel
def test_parallel_pages_catch_and_export(make, stimuli):
    clips = clips_of(stimuli)
    app = make(stimuli, "parallel", ratings_per_clip=2)
    c = app.test_client()
    orders = []

    def rating(i, x):
        return {"NAT": 80, "MG": 60, "FL": 30, "BAD": 90}[clips[x["clip_id"]].condition]  # fails each catch

    for k in range(2):
        token = start(c, external_id=f"R{k}")
        trials, done = complete(c, token, rating=rating)
        for t in trials:
            assert t["design"] == "parallel" and [x["label"] for x in t["clips"]] == list("ABCDEFGH"[: len(t["clips"])])
            assert len({clips[x["clip_id"]].item for x in t["clips"]}) == 1 or t["phase"] == "training"
        pages = [t for t in trials if t["phase"] == "rating"]
        tests = [t for t in pages if clips[t["clips"][0]["clip_id"]].role == "test"]
        catches = [t for t in pages if clips[t["clips"][0]["clip_id"]].role == "catch"]
        assert len(tests) == 4 and len(catches) == 2
        assert all(sorted(clips[x["clip_id"]].condition for x in t["clips"]) == ["FL", "MG", "NAT"] for t in tests)
        # A catch page is as large as a test page (NAT, BAD and filler conditions), so its size tells nothing.
        assert all(sorted(clips[x["clip_id"]].condition for x in t["clips"]) == ["BAD", "FL", "NAT"] for t in catches)
        orders += [tuple(clips[x["clip_id"]].condition for x in t["clips"]) for t in tests]
    assert len(set(orders)) > 1  # page order drawn per trial
    assert c.post("/api/sessions", json={}).status_code == 409
    rows, resp = export(c)
    assert "ratings.csv" in resp.headers["Content-Disposition"]
    assert len(rows) == 2 * (4 * 3 + 2 * 3)
    assert list(rows[0])[:7] == ["rater_id", "page_id", "item", "clip_id", "condition", "rating", "role"]
    per_page = collections.Counter(row["page_id"] for row in rows)
    assert set(per_page.values()) == {3} and len(per_page) == 12
    assert all(int(row["rating"]) == rating(0, row) for row in rows)
    p = c.get("/admin/progress.json", headers=TOKEN_HDR).json
    assert [r["catch_failures"] for r in p["raters"]] == [2, 2] and p["full"]


def test_parallel_bad_input(make, stimuli):
    app = make(stimuli, "parallel")
    c = app.test_client()
    token = start(c)
    t = c.get(f"/api/sessions/{token}/next").json["trial"]
    while t["phase"] == "training":
        assert post(c, token, t, ratings=None).status_code == 201
        t = c.get(f"/api/sessions/{token}/next").json["trial"]
    ids = [x["clip_id"] for x in t["clips"]]
    full = {i: 50 for i in ids}
    for ratings, needle in (
        ([50] * len(ids), "object"),
        ({**full, ids[0]: 101}, "between 0 and 100"),
        ({**full, ids[0]: -1}, "between 0 and 100"),
        ({**full, ids[0]: 5.5}, "integer"),
        ({k: v for k, v in full.items() if k != ids[0]}, "every clip"),
        ({**full, "0123456789abcdef": 3}, "every clip"),
        (None, "ratings"),
    ):
        r = post(c, token, t, ratings=ratings)
        assert r.status_code == 400 and needle in r.json["error"], (ratings, r.json)
    assert post(c, token, t, rating=3).status_code == 400
    assert post(c, token, t, ratings=full).status_code == 201
    again = post(c, token, t, ratings={i: 0 for i in ids})
    assert again.status_code == 200 and again.json["ratings"] == full
    rows, _ = export(c)
    assert len(rows) == len(ids) and {int(r["rating"]) for r in rows} == {50}


# ------------------------------------------------------------------------------------------------- balance
# Per design, on big_stimuli: its test units and a rater's share of them. The balance tests run every design of
# moglow_eval.core.study.DESIGNS, so a design missing here fails them (docs/ARCHITECTURE.md, "A test design").
BALANCE = {
    "acr": (90, 30),
    "pairwise": (90, 30),
    "parallel": (30, 10),
    "appropriateness": (90, 30),  # a unit is an item and a system: its clip for this item against its mismatched one
    "dyadic": (90, 30),
    "semantic": (90, 30),
}


@pytest.mark.parametrize("design", study.DESIGNS)
@pytest.mark.full  # the full tier: crowds through every design
def test_targets_reached_exactly_with_fewest_raters(make, big_stimuli, design):
    units, per_rater = BALANCE[design]
    clips = clips_of(big_stimuli)
    target = 2
    app = make(big_stimuli, design, ratings_per_clip=target, clips_per_rater=per_rater)
    c = app.test_client()
    raters = 0
    while True:
        r = c.post("/api/sessions", json={})
        if r.status_code == 409:
            break
        complete(c, r.json["session"])
        raters += 1
    assert raters == units * target // per_rater
    check_exact(c, clips, design, units, target)
    assert cover_mismatches(app_engine(app)) == {}


def unit_counts(rows, clips, design):
    if design == "acr":
        return collections.Counter(r["clip_id"] for r in rows if r["role"] == "test")
    if design == "pairwise" or design in study.MISMATCH_COLUMN:  # matched/mismatched: (item, condition, condition)
        return collections.Counter(
            (r["item"], *sorted((r["condition_a"], r["condition_b"]))) for r in rows if r["role"] == "test"
        )
    pages = {}
    for r in rows:
        if r["role"] == "test":
            pages.setdefault(r["page_id"], r["item"])
    return collections.Counter(pages.values())


def check_exact(c, clips, design, units, target):
    rows, _ = export(c)
    counts = unit_counts(rows, clips, design)
    assert len(counts) == units and set(counts.values()) == {target}, collections.Counter(counts.values())


@pytest.mark.full  # the full tier: concurrent crowds
@pytest.mark.parametrize("design", study.DESIGNS)
def test_targets_exact_under_concurrent_sessions(make, big_stimuli, design):
    units = BALANCE[design][0]
    clips = clips_of(big_stimuli)
    target = 3
    app = make(big_stimuli, design, ratings_per_clip=target, clips_per_rater=7)
    errors = run_raters(app, post)
    assert not errors, errors[:3]
    check_exact(app.test_client(), clips, design, units, target)
    assert cover_mismatches(app_engine(app)) == {}


def test_an_idle_session_gives_its_pair_back(make, stimuli):
    app = make(stimuli, "pairwise", ratings_per_clip=1)
    c = app.test_client()
    clips = clips_of(stimuli)
    ghost = start(c)
    t = c.get(f"/api/sessions/{ghost}/next").json["trial"]
    while t["phase"] == "training" or clips[t["a"]["clip_id"]].role == "catch":
        assert post(c, ghost, t).status_code == 201
        t = c.get(f"/api/sessions/{ghost}/next").json["trial"]
    held = {t["a"]["clip_id"], t["b"]["clip_id"]}
    trials, _ = complete(c, start(c))
    assert held not in [{x["a"]["clip_id"], x["b"]["clip_id"]} for x in trials]
    r = c.post("/api/sessions", json={})
    assert r.status_code == 409 and "for now" in r.json["error"]
    idle(app, ghost)
    assert post(c, ghost, t).status_code == 410
    assert cover_mismatches(app_engine(app)) == {}  # the expiry gave the held pair back
    trials, _ = complete(c, start(c))
    assert held in [{x["a"]["clip_id"], x["b"]["clip_id"]} for x in trials]


# ------------------------------------------------------------------------------------------------- the study's design
def test_a_database_holds_one_design(make, stimuli, app_db_url, tmp_path):
    make(stimuli, "pairwise")
    with pytest.raises(AppError, match="holds a pairwise study; it cannot be served as parallel"):
        make(stimuli, "parallel")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "rating_app",
            "serve",
            "--manifest",
            str(stimuli),
            "--db",
            app_db_url,
            "--design",
            "acr",
            "--port",
            "1",
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
    )
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "holds a pairwise study" in r.stderr, r.stderr
    make(stimuli, "pairwise")  # the same design again: fine


def test_design_setting_and_manifest_errors(tmp_path, app_db_url, stimuli):
    with pytest.raises(AppError, match="study_design: 'mushra' must be one of acr, pairwise, parallel"):
        create_app(manifest=stimuli, db_url=app_db_url, design="mushra")
    # no NAT on catch items
    old = write_fake_stimuli(tmp_path / "old", n_items=2, n_catch=1, n_training=1, metrics=False)
    with pytest.raises(AppError, match="catch item 'bad00' has no NAT clip"):
        create_app(manifest=old, db_url=app_db_url, design="pairwise")
    one = write_fake_stimuli(tmp_path / "one", n_items=2, conditions=("NAT",), n_catch=0, n_training=1, metrics=False)
    with pytest.raises(AppError, match="one condition only"):
        create_app(manifest=one, db_url=app_db_url, design="parallel")
    nine = write_fake_stimuli(
        tmp_path / "nine",
        n_items=1,
        conditions=tuple(f"C{i}" for i in range(9)),
        n_catch=0,
        n_training=1,
        metrics=False,
    )
    with pytest.raises(AppError, match="at most 8"):
        create_app(manifest=nine, db_url=app_db_url, design="parallel")


def test_acr_never_serves_the_nat_reference_of_a_catch_item(make, stimuli):
    clips = clips_of(stimuli)
    app = make(stimuli, "acr", ratings_per_clip=1)
    c = app.test_client()
    token = start(c)
    served = set()
    for _ in range(100):
        j = c.get(f"/api/sessions/{token}/next").json
        if j.get("done"):
            break
        t = j["trial"]
        served.add(t["clip_id"])
        r = c.post(
            f"/api/sessions/{token}/ratings",
            json={"trial_id": t["trial_id"], "rating": None if t["phase"] == "training" else 2},
        )
        assert r.status_code == 201
    refs = {i for i, x in clips.items() if x.role == "catch" and x.condition == "NAT"}
    bads = {i for i, x in clips.items() if x.role == "catch" and x.condition == "BAD"}
    assert refs and not served & refs and bads <= served


# ------------------------------------------------------------------------------------------------- simulated crowd
@pytest.mark.full  # the full tier: a crowd per design
@pytest.mark.parametrize("design", ["pairwise", "parallel"])
def test_simulated_crowd_answers_each_design_as_the_page_does(stimuli, app_db_url, tmp_path, design):
    """The crowd fetches every clip, waits as the server requires (10% here) and answers the design; what it
    was acknowledged is what the export holds, careless raters fail catch trials and attentive ones never do."""
    from werkzeug.serving import make_server

    from rating_app.simulate import run_simulation

    # 2 test units per rater, so that many raters (half of them careless) take part before the study is full
    app = create_app(
        manifest=stimuli,
        db_url=app_db_url,
        admin_token="test-admin-token",
        ratings_per_clip=6,
        clips_per_rater=2,
        min_view=0.1,
        sessions_per_client=0,
        design=design,
    )
    server = make_server("127.0.0.1", 0, app, threaded=True)
    th = threading.Thread(target=server.serve_forever, daemon=True)
    th.start()
    url = f"http://127.0.0.1:{server.server_port}"
    try:
        other = "parallel" if design == "pairwise" else "pairwise"
        with pytest.raises(AppError, match=f"--design {other}: the server at .* runs a {design} study"):
            run_simulation(url, 2, design=other, manifest=stimuli, progress=False)
        summary = run_simulation(
            url, 40, seed=5, careless=0.5, manifest=stimuli, concurrency=4, progress=False, design=design, timeout_s=300
        )
        c = app.test_client()
        rows, _ = export(c)
        p = c.get("/admin/progress.json", headers=TOKEN_HDR).json
    finally:
        server.shutdown()
        th.join(5)
        app_engine(app).dispose()
    assert summary["errors"] == [] and summary["study_full"]
    key = (
        ("rater_id", "clip_a", "clip_b", "preference")
        if design == "pairwise"
        else ("rater_id", "page_id", "clip_id", "rating")
    )
    acked = collections.Counter(tuple(str(r[k]) for k in key) for r in summary["ratings"])
    assert acked == collections.Counter(tuple(r[k] for k in key) for r in rows) and max(acked.values()) == 1
    failed = {r["rater_id"] for r in p["raters"] if r["catch_failures"]}
    # Every video fetched, none too early; the excluded raters' rows carry their flag (issue 55 item 1).
    assert all(r["flags"] == ("failed_catch" if r["rater_id"] in failed else "") for r in rows)
    assert failed and failed == set(summary["failed_catch_raters"]) and failed <= set(summary["careless_raters"])
    # the report excludes exactly the raters the dashboard lists as failing a catch trial
    from analysis.designs.pairwise import preference as pairwise
    from analysis.designs.parallel import mushra as parallel

    f = tmp_path / "export.csv"
    with open(f, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    loaded = pairwise.load_pairs(f) if design == "pairwise" else parallel.load_pages(f)
    assert set((pairwise if design == "pairwise" else parallel).failed_raters(loaded)) == failed


@pytest.mark.parametrize("design", ["pairwise", "parallel"])
def test_cli_export_writes_the_design_file(make, stimuli, app_db_url, tmp_path, design):
    app = make(stimuli, design, ratings_per_clip=1)
    c = app.test_client()
    complete(c, start(c))
    want, _ = export(c)
    out = tmp_path / "export.csv"
    r = subprocess.run(
        [sys.executable, "-m", "rating_app", "export", "--db", app_db_url, "--out", str(out)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    with open(out, newline="") as fh:
        got = list(csv.DictReader(fh))
    assert got == want and len(got) > 0
    assert ("preference" in got[0]) == (design == "pairwise") and ("page_id" in got[0]) == (design == "parallel")
    noun = "pairwise answers" if design == "pairwise" else "clip ratings of parallel pages"
    assert f"{len(got)} {noun} -> {out}" in r.stderr, r.stderr  # not "N ratings" for pairs


# ------------------------------------------------------------------------------------------- cost per call
# The most SQL statements each hot call may send for a rating trial, by database (catch slots included: they
# run the test slots' queries too). Under 200 raters the CPU per statement is what sets the tail latency
# (bench/RESULTS.md, issue 13); this guards the count, never a time.
HOT_CALL_LIMITS = {
    "postgresql": {"next": 7, "video": 2, "answer": 6},
    "sqlite": {"next": 9, "video": 4, "answer": 7},  # its BEGINs are statements too (db.make_engine)
}


@pytest.mark.parametrize("design", ["acr", "pairwise", "parallel"])
def test_hot_calls_send_few_statements(make, big_stimuli, design):
    from sqlalchemy import event

    app = make(big_stimuli, design, ratings_per_clip=5)
    engine = app_engine(app)
    sent = []
    event.listen(engine, "before_cursor_execute", lambda *a: sent.append(a[2]))
    c = app.test_client()
    most = collections.Counter()

    def count(kind, resp):
        most[kind] = max(most[kind], len(sent))
        sent.clear()
        return resp

    token = start(c)
    for _ in range(12):
        sent.clear()
        t = count("next", c.get(f"/api/sessions/{token}/next")).json["trial"]
        for x in shown(t):
            assert count("video", c.get(x["video_url"])).status_code == 200
        assert count("answer", post(c, token, t)).status_code == 201
    limits = dict(HOT_CALL_LIMITS[engine.dialect.name])
    limits["next"] -= design == "acr"  # no clips of a unit to insert
    assert all(most[k] <= limits[k] for k in limits), (dict(most), limits)
    assert min(most.values()) > 0  # the listener saw the calls
