"""The rater's page of a pairwise or parallel study in a real browser (tests/rating_app/test_browser_designs.py and
test_browser_reasons.py): the app served over HTTP in a design, the page's state as a script reads it, a rater
through the whole flow, and what the export and the database then hold."""

import contextlib
import csv
import io
import os

import requests
from sqlalchemy import select

from rating_app import create_app
from rating_app.store.db import TrialClip, app_engine

from .paths import ROOT
from .servers import in_thread


@contextlib.contextmanager
def serve(manifest, db_url, design):
    """The app in `design` on `manifest` and `db_url`, served from a thread (helpers.servers.in_thread): yields
    (app, its URL)."""
    app = create_app(
        manifest=manifest,
        db_url=db_url,
        admin_token="browser-token",
        ratings_per_clip=5,
        clips_per_rater=3,
        design=design,
    )
    with in_thread(app) as url:
        yield app, url


# A video's `src` (the address the page set, in the same task as the trial's label and count), never `currentSrc`:
# chromium updates currentSrc in a later task of its own, so under load a state read in between named the trial
# before (seen once: the first rated pair taken for the last example, absent from the export).
STATE_JS = """
var vis = ['pair', 'page', 'rating-intro', 'intro', 'done'].filter(function (id) {
  return !document.getElementById(id).hidden; });
var sec = vis.length ? vis[0] : null;
var vids = sec ? Array.prototype.slice.call(document.querySelectorAll('#' + sec + ' video')) : [];
var box = function (id) {
  var r = document.getElementById(id).getBoundingClientRect(); return [r.left, r.top, r.bottom]; };
return {section: sec,
  label: sec ? (document.querySelector('#' + sec + ' .phase-label') || {}).textContent : null,
  count: sec ? (document.querySelector('#' + sec + ' .trial-count') || {}).textContent : null,
  ended: vids.map(function (v) { return v.ended; }), srcs: vids.map(function (v) { return v.src; }),
  prefs_disabled: Array.prototype.every.call(document.querySelectorAll('button.pref'),
                                             function (b) { return b.disabled; }),
  submit_disabled: document.getElementById('page-submit').disabled,
  a: box('video-a'), b: box('video-b'),
  fits: document.documentElement.scrollWidth <= window.innerWidth + 1};
"""


def trial_of(src):
    return int(src.rsplit("/", 3)[1])  # .../trials/ID/clips/A.mp4


def run_flow(browser, url, design, answer):
    """Consent, familiarisation, every trial until the completion code; `answer(state)` answers a rating trial
    and returns (trial id, value). Returns ({trial id: value}, number of familiarisation trials, code)."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as EC

    from .browser import COUNT_LOCKED_PLAYS, waiting

    wait = waiting(browser, 30)
    browser.get(url + f"/?PROLIFIC_PID={design}pid&STUDY_ID=st1&SESSION_ID=se1")
    browser.execute_script(COUNT_LOCKED_PLAYS)
    browser.find_element(By.ID, "consent").click()
    wait.until(EC.element_to_be_clickable((By.ID, "start"))).click()
    wait.until(EC.visibility_of_element_located((By.ID, "intro")))
    browser.find_element(By.ID, "intro-go").click()
    given, n_training = {}, 0

    def key(s):
        return (s["section"], s["label"], s["count"])

    for _ in range(60):
        wait.until(lambda d: d.execute_script(STATE_JS)["section"] not in (None, "intro"))
        s = browser.execute_script(STATE_JS)
        if s["section"] == "done":
            break
        if s["section"] == "rating-intro":
            browser.find_element(By.ID, "rating-go").click()
        else:
            assert s["fits"], "no horizontal scrolling on a phone-sized screen"
            if not all(s["ended"]):
                assert s["prefs_disabled"] and s["submit_disabled"], "no answer before every clip has ended"
            if s["label"].startswith("Example"):
                n_training += 1
                if s["section"] == "pair":
                    wait.until(EC.element_to_be_clickable((By.ID, "pair-continue"))).click()
                else:
                    play_page(browser, wait)
                    wait.until(EC.element_to_be_clickable((By.ID, "page-submit"))).click()
            else:
                trial_id, value = answer(s, wait)
                given[trial_id] = value
        wait.until(lambda d: key(d.execute_script(STATE_JS)) != key(s))
    else:
        raise AssertionError("never reached the completion page")
    # Every answered trial's clips started with no answer possible, as the page's `playing` events counted (a poll
    # above need not fall inside a 0.8-s clip on a loaded machine).
    assert browser.execute_script("return window.lockedPlays") >= len(given)
    return given, n_training, browser.find_element(By.ID, "completion-code").text


def play_page(browser, wait):
    """Click every clip of a parallel page in turn and wait until it has played to the end."""
    from selenium.webdriver.common.by import By

    videos = browser.find_elements(By.CSS_SELECTOR, "#page-clips video")
    for i, v in enumerate(videos):
        v.click()
        wait.until(lambda d: d.execute_script(f"return document.querySelectorAll('#page-clips video')[{i}].ended"))


def rater_export(url, pid):
    """The export's rows of rater `pid` (their external id), and the response."""
    r = requests.get(url + "/admin/export.csv", headers={"Authorization": "Bearer browser-token"}, timeout=10)
    assert r.status_code == 200
    return [row for row in csv.DictReader(io.StringIO(r.text)) if row["external_id"] == pid], r


def shown_clips(app):
    """{trial pk: {label: clip id}}: the clips each trial showed, as the database holds them."""
    with app_engine(app).connect() as conn:
        rows = conn.execute(select(TrialClip.trial_pk, TrialClip.label, TrialClip.clip_id)).all()
    out = {}
    for t, label, clip in rows:
        out.setdefault(t, {})[label] = clip
    return out


def screenshot(browser, name):
    """With SAVE_SCREENSHOTS=1, the page as docs/img/`name`."""
    if os.environ.get("SAVE_SCREENSHOTS") == "1":
        (ROOT / "docs" / "img").mkdir(parents=True, exist_ok=True)
        browser.save_screenshot(str(ROOT / "docs" / "img" / name))
