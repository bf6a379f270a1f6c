"""An answer counts as watched only when the whole video was sent to the session (issue 37, item 3): the byte
ranges served must cover the file; a 1-byte fetch, half the file or a HEAD request leave the answer flagged
(`partial_video`, `no_video`), on the dashboard and in the export. Through the API in every design on SQLite and
PostgreSQL, and with the real page in a real browser (replays from its cache and a reload included)."""

import csv
import io

import pytest
from helpers.api_client import TOKEN_HDR
from helpers.design_client import shown, value_for
from helpers.flags import video_flags

from rating_app.store.db import app_engine


def fetch_full(c, url, size):
    r = c.get(url)
    assert r.status_code == 200 and len(r.data) == size


def fetch_one_byte(c, url, size):
    r = c.get(url, headers={"Range": "bytes=0-0"})
    assert r.status_code == 206 and len(r.data) == 1


def fetch_head(c, url, size):
    r = c.head(url)
    assert r.status_code == 200 and r.headers["Content-Length"] == str(size)


def fetch_half(c, url, size):
    r = c.get(url, headers={"Range": f"bytes=0-{size // 2 - 1}"})
    assert r.status_code == 206 and len(r.data) == size // 2


def fetch_two_halves(c, url, size):  # in reverse order and overlapping: the distinct ranges still cover the file
    assert c.get(url, headers={"Range": f"bytes={size // 2 - 10}-"}).status_code == 206
    assert c.get(url, headers={"Range": f"bytes=0-{size // 2}"}).status_code == 206


def fetch_nothing(c, url, size):
    pass


# what a rating trial's clips get, and the flags its answer must carry
CASES = [
    (fetch_one_byte, "partial_video"),
    (fetch_full, ""),
    (fetch_head, "no_video"),
    (fetch_half, "partial_video"),
    (fetch_two_halves, ""),
    (fetch_nothing, "no_video"),
]


@pytest.mark.parametrize("design", ["acr", "pairwise", "parallel"])
def test_only_a_whole_video_counts_as_fetched(make, stimuli, design):
    app = make(stimuli, design, ratings_per_clip=3)
    sizes = {c.clip_id: c.video.stat().st_size for c in app.extensions["rating_app"]["clips"].values()}
    c = app.test_client()
    token = c.post("/api/sessions", json={"external_id": "fetcher"}).json["session"]
    want, n = {}, 0
    while True:
        j = c.get(f"/api/sessions/{token}/next").json
        if j.get("done"):
            break
        t = j["trial"]
        fetch, flags = CASES[n % len(CASES)] if t["phase"] == "rating" else (fetch_full, "")
        for x in shown(t):
            fetch(c, x["video_url"], sizes[x["clip_id"]])
        if t["phase"] == "rating":
            want[t["trial_id"]] = flags
            n += 1
        r = c.post(f"/api/sessions/{token}/ratings", json={"trial_id": t["trial_id"], **value_for(t)})
        assert r.status_code == 201, r.json
    assert n >= len(CASES)
    rows = list(csv.DictReader(io.StringIO(c.get("/admin/export.csv", headers=TOKEN_HDR).get_data(as_text=True))))
    if design == "parallel":  # a page's flags are on each of its rows
        got = {}
        for row in rows:
            got.setdefault(int(row["page_id"][1:]), set()).add(video_flags(row["flags"]))
        assert got == {t: {f} for t, f in want.items()}
    else:
        assert sorted(video_flags(row["flags"]) for row in rows) == sorted(want.values())
    p = c.get("/admin/progress.json", headers=TOKEN_HDR).json
    (rater,) = p["raters"]
    assert rater["flags"] == ["no_video", "partial_video"]
    assert rater["ratings_partial_video"] == sum(f == "partial_video" for f in want.values())
    page = c.get("/admin", headers=TOKEN_HDR).get_data(as_text=True)
    assert "only part of the video fetched" in page


def test_a_range_request_records_its_bytes_once_covered(make, stimuli):
    """The stored ranges are merged; once the file is covered, later requests (replays) write nothing."""
    from sqlalchemy import event, select

    from rating_app.store.db import Trial

    app = make(stimuli, "acr", ratings_per_clip=3)
    c = app.test_client()
    token = c.post("/api/sessions", json={}).json["session"]
    t = c.get(f"/api/sessions/{token}/next").json["trial"]
    size = app.extensions["rating_app"]["clips"][t["clip_id"]].video.stat().st_size
    for rng in ("bytes=100-199", "bytes=0-49", "bytes=150-299", "bytes=50-99"):
        assert c.get(t["video_url"], headers={"Range": rng}).status_code == 206
    engine = app_engine(app)
    with engine.connect() as conn:
        assert conn.execute(select(Trial.video_ranges).where(Trial.id == t["trial_id"])).scalar() == "0-300"
    assert c.get(t["video_url"], headers={"Range": "bytes=300-"}).status_code == 206
    with engine.connect() as conn:
        assert conn.execute(select(Trial.video_ranges).where(Trial.id == t["trial_id"])).scalar() == f"0-{size}"
    writes = []
    event.listen(engine, "before_cursor_execute", lambda *a: writes.append(a[2]) if "UPDATE" in a[2] else None)
    assert c.get(t["video_url"]).status_code == 200
    assert writes == []


PAGE_JS = """
var vis = ['intro', 'trial', 'rating-intro', 'done'].filter(function (id) {
  return !document.getElementById(id).hidden; });
var v = document.getElementById('video');
return {section: vis.length ? vis[0] : null, label: document.getElementById('phase-label').textContent,
  count: document.getElementById('trial-count').textContent, ended: v.ended, time: v.currentTime};
"""

COUNT_PLAYS = """
window.plays = 0;
var v = document.getElementById('video');
if (!v.countsPlays) { v.countsPlays = true; v.addEventListener('play', function () { window.plays += 1; }); }
"""


@pytest.mark.browser
@pytest.mark.parametrize("app_db_url", ["sqlite"], indirect=True)
def test_the_page_is_never_flagged_with_replays_and_a_reload(app_stimuli, app_db_url, browser):
    """The real page in chromium: every rating trial is replayed once (from the browser's cache), and the page is
    reloaded in the middle of one trial (it resumes the same trial and plays it again); no answer is flagged."""
    import requests
    from helpers.browser import waiting
    from helpers.servers import in_thread
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as EC

    from rating_app import create_app

    app = create_app(manifest=app_stimuli, db_url=app_db_url, admin_token="browser-token", clips_per_rater=3)
    with in_thread(app) as url:
        wait = waiting(browser, 30)
        browser.get(url + "/?PROLIFIC_PID=replayer&SESSION_ID=se1")
        browser.find_element(By.ID, "consent").click()
        wait.until(EC.element_to_be_clickable((By.ID, "start"))).click()
        replays = reloads = 0
        for _ in range(60):
            wait.until(lambda d: d.execute_script(PAGE_JS)["section"])
            s = browser.execute_script(PAGE_JS)
            if s["section"] == "done":
                break
            if s["section"] in ("intro", "rating-intro"):
                browser.find_element(By.ID, "intro-go" if s["section"] == "intro" else "rating-go").click()
                wait.until(lambda d, s=s: d.execute_script(PAGE_JS)["section"] != s["section"])
                continue
            wait.until(lambda d: d.execute_script(PAGE_JS)["ended"])
            if s["label"] == "Example":
                browser.find_element(By.ID, "continue").click()
            elif reloads == 0 and s["count"].startswith("2 "):
                browser.refresh()  # the same trial again, its video from the browser's cache
                reloads += 1
                continue
            else:
                # The replay counted by its `play` event, which stays counted: a moment of the replay's not being
                # ended (0.8 s) can pass unseen between two polls on a loaded machine.
                browser.execute_script(COUNT_PLAYS)
                browser.find_element(By.ID, "replay").click()
                wait.until(lambda d: d.execute_script("return window.plays") > 0)
                wait.until(lambda d: d.execute_script(PAGE_JS)["ended"])
                replays += 1
                wait.until(EC.element_to_be_clickable((By.CSS_SELECTOR, 'button.rate[data-rating="4"]'))).click()
            wait.until(
                lambda d, s=s: (
                    (d.execute_script(PAGE_JS)["section"], d.execute_script(PAGE_JS)["count"])
                    != (s["section"], s["count"])
                )
            )
        else:
            raise AssertionError("never reached the completion page")
        r = requests.get(url + "/admin/export.csv", headers={"Authorization": "Bearer browser-token"}, timeout=10)
        rows = list(csv.DictReader(io.StringIO(r.text)))
        assert reloads == 1 and replays == len(rows) >= 4
        assert [video_flags(row["flags"]) for row in rows] == [""] * len(rows)
