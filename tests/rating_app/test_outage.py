"""Faults a real study meets (issue 37, item 5). PostgreSQL restarted in the middle of a study under 30 raters
answering through gunicorn: answers sent meanwhile get a retryable 503, never a 500; the raters (the simulated
crowd, and the real page in chromium) retry by themselves; no acknowledged answer is lost or stored twice. And what
a full disk does on SQLite: a clear 503 to the rater, the database readable and usable afterwards.

The PostgreSQL server is a throwaway cluster made here with initdb and started and stopped with pg_ctl, on a free
port and a socket folder of its own, never the shared server."""

import collections
import contextlib
import csv
import io
import re
import threading
import time

import pytest
import requests
from helpers.concurrent_raters import cover_mismatches
from helpers.crowd_records import DESIGNS
from helpers.fake_stimuli import write_fake_stimuli
from helpers.pg_server import Cluster, ServerError
from helpers.servers import crowd_env, in_thread, start_gunicorn

from moglow_eval.core.ports import free_port
from rating_app.simulate import run_simulation
from rating_app.store.db import make_engine

pytestmark = pytest.mark.full  # the full tier: a PostgreSQL of its own, killed and restarted


@pytest.fixture
def cluster():
    try:
        c = Cluster()
        c.start()
    except ServerError as e:
        pytest.fail(str(e))
    yield c
    c.remove()


@pytest.mark.parametrize("design", ["acr"])  # the crash tests of test_app_load run every design
def test_postgres_restart_under_30_raters(cluster, app_stimuli, tmp_path, design):
    key, rows_of, per_rater, _unit = DESIGNS[design]
    stimuli = app_stimuli if design == "acr" else write_fake_stimuli(tmp_path / "stimuli", catch_nat=True)
    raters, port = 30, free_port()
    env = crowd_env(stimuli, cluster.url, "outage-token", STUDY_DESIGN=design)
    log = open(tmp_path / "gunicorn.log", "w")
    acks = [0]
    proc = start_gunicorn(port, env, log)
    summary, outage = {}, {}
    probe = requests.post(f"http://127.0.0.1:{port}/api/sessions", json={}, timeout=10).json()["session"]

    def crowd():
        summary.update(
            run_simulation(
                f"http://127.0.0.1:{port}",
                raters,
                seed=5,
                careless=0.1,
                manifest=stimuli,
                concurrency=raters,
                think_s=0.05,
                timeout_s=150,
                progress=False,
                on_ack=lambda rec: acks.__setitem__(0, acks[0] + 1),
            )
        )

    sim = threading.Thread(target=crowd)
    try:
        sim.start()
        while acks[0] < raters * per_rater // 3 and sim.is_alive():
            time.sleep(0.01)
        outage["acked_before"] = acks[0]
        cluster.stop("fast")  # the database goes away in the middle of the study ...
        r = requests.post(f"http://127.0.0.1:{port}/api/sessions/{probe}/ratings", json={"trial_id": 1}, timeout=30)
        outage["probe"] = (r.status_code, r.headers.get("Retry-After"), r.json())
        time.sleep(3)
        cluster.start()  # ... and comes back
        sim.join(180)
        assert not sim.is_alive(), "the crowd did not finish in time"
    finally:
        proc.terminate()
        proc.wait(15)
        log.close()
    text = (tmp_path / "gunicorn.log").read_text()
    assert 0 < outage["acked_before"] < summary["n_ratings"]
    status, retry_after, body = outage["probe"]
    assert status == 503 and retry_after and body["retryable"] is True and "retry" in body["error"], outage
    assert summary["errors"] == [], summary["errors"][:3]
    assert summary["n_raters_completed"] == raters
    # answers sent during the outage got the retryable 503, and nothing was a 500
    assert re.search(r"database error on POST /api/sessions/\S+/ratings", text), text[-3000:]
    assert "unhandled error" not in text and "Traceback" not in text, text[-3000:]
    acked = collections.Counter(tuple(r[k] for k in key) for r in summary["ratings"])
    engine = make_engine(cluster.url)
    try:
        from sqlalchemy.orm import Session

        with Session(engine) as s:
            stored = collections.Counter(tuple(r[k] for k in key) for r in rows_of(s))
        assert cover_mismatches(engine) == {}
    finally:
        engine.dispose()
    assert max(stored.values()) == 1 and len(acked) == raters * per_rater
    assert stored == acked  # nothing acknowledged is lost, nothing stored twice


PAGE_JS = """
var vis = ['intro', 'trial', 'rating-intro', 'done', 'error'].filter(function (id) {
  return !document.getElementById(id).hidden; });
var v = document.getElementById('video');
return {section: vis.length ? vis[0] : null, label: document.getElementById('phase-label').textContent,
  count: document.getElementById('trial-count').textContent, ended: v.ended,
  retrying: !document.getElementById('retrying').hidden};
"""


@pytest.mark.browser
def test_the_page_retries_an_answer_through_a_database_restart(cluster, app_stimuli, browser):
    """The real page in chromium: the database stops as the rater answers, stays away 10 s and comes back; the page
    says it is retrying, sends the answer by itself once the server is back and goes on; the answer is stored once."""
    from helpers.browser import waiting
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as EC

    from rating_app import create_app

    app = create_app(manifest=app_stimuli, db_url=cluster.url, admin_token="outage-token", clips_per_rater=2)
    with in_thread(app) as url:
        wait = waiting(browser, 30)
        state = lambda: browser.execute_script(PAGE_JS)  # noqa: E731
        browser.get(url + "/?PROLIFIC_PID=outage1&SESSION_ID=se1")
        browser.find_element(By.ID, "consent").click()
        wait.until(EC.element_to_be_clickable((By.ID, "start"))).click()
        outage_done = False
        for _ in range(40):
            wait.until(lambda d: state()["section"])
            s = state()
            assert s["section"] != "error", browser.find_element(By.ID, "error-msg").text
            if s["section"] == "done":
                break
            if s["section"] in ("intro", "rating-intro"):
                browser.find_element(By.ID, "intro-go" if s["section"] == "intro" else "rating-go").click()
                wait.until(lambda d, s=s: state()["section"] != s["section"])
                continue
            wait.until(lambda d: state()["ended"])
            if s["label"] == "Example":
                browser.find_element(By.ID, "continue").click()
            else:
                button = wait.until(EC.element_to_be_clickable((By.CSS_SELECTOR, 'button.rate[data-rating="2"]')))
                if not outage_done:
                    cluster.stop("fast")
                    button.click()
                    waiting(browser, 15).until(lambda d: state()["retrying"])
                    time.sleep(10)  # longer than the page's old retries lasted
                    assert state()["count"] == s["count"] and state()["section"] == "trial"
                    cluster.start()
                    outage_done = True
                else:
                    button.click()
            waiting(browser, 60).until(
                lambda d, s=s: (state()["section"], state()["count"]) != (s["section"], s["count"])
            )
        else:
            raise AssertionError("never reached the completion page")
        assert outage_done and not state()["retrying"]
        r = requests.get(url + "/admin/export.csv", headers={"Authorization": "Bearer outage-token"}, timeout=10)
        rows = list(csv.DictReader(io.StringIO(r.text)))
        assert len(rows) == 4 and {row["rating"] for row in rows} == {"2"}  # 2 test + 2 catch, each once
        assert len({row["clip_id"] for row in rows}) == 4


def export_rows(c):
    r = c.get("/admin/export.csv", headers={"Authorization": "Bearer test-admin-token"})
    assert r.status_code == 200
    return list(csv.DictReader(io.StringIO(r.get_data(as_text=True))))


@pytest.mark.parametrize("app_db_url", ["sqlite"], indirect=True)
def test_a_full_disk_on_sqlite_is_a_clear_error_and_the_database_stays_readable(make_app, app_db_url):
    """A full disk, simulated honestly within SQLite: every connection of the app gets `PRAGMA max_page_count` set to
    the database's present size, so the first write that needs a new page fails with SQLITE_FULL, the error SQLite
    gives for a full disk too (no tmpfs or loop device here to fill a real one). Raters keep answering until that
    happens: the call that hits it gets a 503 that says the disk is full and that earlier answers are saved; the
    database stays readable (export, integrity check) and, once there is room again, the same call goes through
    and nothing is stored twice."""
    import sqlite3

    from sqlalchemy import event

    from rating_app.store.db import app_engine

    app = make_app(min_view=0, ratings_per_clip=50, sessions_per_client=0)
    c = app.test_client()
    tokens = [c.post("/api/sessions", json={}).json["session"] for _ in range(8)]
    engine = app_engine(app)

    def limit(dbapi_conn, _record):
        cur = dbapi_conn.cursor()
        pages = cur.execute("PRAGMA page_count").fetchone()[0]
        cur.execute(f"PRAGMA max_page_count = {pages}")
        cur.close()

    event.listen(engine, "connect", limit)
    engine.dispose()  # every connection from now on has the limit
    acked, refused = set(), None
    for _ in range(40):
        for token in tokens:
            r = c.get(f"/api/sessions/{token}/next")
            if r.status_code == 200 and "trial" in r.json:
                t = r.json["trial"]
                body = {"trial_id": t["trial_id"], "rating": None if t["phase"] == "training" else 4}
                call = ("post", f"/api/sessions/{token}/ratings", body)
                r = c.post(call[1], json=body)
                if r.status_code == 201 and t["phase"] == "rating":
                    acked.add((token, t["clip_id"]))
            else:
                call = ("get", f"/api/sessions/{token}/next", None)
            if r.status_code >= 500:
                refused = (call, r)
                break
            assert r.status_code in (200, 201), r.json
        if refused:
            break
    assert refused is not None, "the database never filled up"
    (method, path, body), r = refused
    assert r.status_code == 503 and r.headers["Retry-After"] and r.json["retryable"] is True
    assert "disk is full" in r.json["error"] and "saved" in r.json["error"], r.json
    # still readable while full: the export holds every acknowledged answer, and the file is sound
    rows = export_rows(c)
    assert len(rows) == len(acked) > 0
    path_db = app_db_url.removeprefix("sqlite:///")
    with contextlib.closing(sqlite3.connect(path_db)) as db:
        assert db.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    # room again: the refused call goes through, and is stored once
    event.remove(engine, "connect", limit)
    engine.dispose()
    again = c.post(path, json=body) if method == "post" else c.get(path)
    assert again.status_code in (200, 201), again.json
    if method == "post":
        assert c.post(path, json=body).status_code == 200  # a repeat: stored once
    rows = list(
        csv.DictReader(
            io.StringIO(
                c.get("/admin/export.csv", headers={"Authorization": "Bearer test-admin-token"}).get_data(as_text=True)
            )
        )
    )
    assert len(rows) in (len(acked), len(acked) + 1) and len({(r["rater_id"], r["clip_id"]) for r in rows}) == len(rows)
