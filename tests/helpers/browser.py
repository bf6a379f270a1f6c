"""A real browser for the tests (Debian chromium, headless, through chromedriver), what the `live_server` fixture
(tests/conftest.py) last served, the rater's flow through an ACR study, and the page's state as a script reads it
on a page with sound."""

import csv
import io
import os
import shutil

import pytest
import requests

from rating_app.store.db import app_engine
from rating_app.store.manifest import load_manifest

from .paths import ROOT

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"

# [manifest, app] of the study the `live_server` fixture serves now, for a test that reads the app behind the page.
live_server_manifest = []


# How often a wait asks the page again. selenium's default, half a second, was seconds of nothing in every browser
# test: a rater's flow waits some sixty times (a clip's end, the next trial), and each wait lasts to the next poll.
POLL_S = 0.05


def waiting(driver, timeout):
    """selenium's WebDriverWait on `driver` for up to `timeout` seconds, asking every POLL_S."""
    from selenium.webdriver.support.ui import WebDriverWait

    return WebDriverWait(driver, timeout, poll_frequency=POLL_S)


def chrome(tmp_path, window="390,844"):
    """Debian's chromium, headless, through chromedriver, with a window of `window` (width,height)."""
    if not (shutil.which(CHROMIUM) and shutil.which(CHROMEDRIVER)):
        pytest.fail("Debian chromium and chromedriver are needed (apt-get install chromium chromium-driver)")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for arg in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        "--disable-extensions",
        "--disable-dev-shm-usage",
        "--mute-audio",
        f"--window-size={window}",
        f"--user-data-dir={tmp_path / 'chrome-profile'}",
    ):
        opts.add_argument(arg)
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
    driver.set_page_load_timeout(30)
    return driver


# Counts the page's video starts while no answer can be given (every rating, preference and submit button the page
# has disabled), from the page's own `playing` events (caught on the document: media events do not bubble). Set once
# a page load, before the first trial; read as `window.lockedPlays`.
COUNT_LOCKED_PLAYS = """
window.lockedPlays = 0;
document.addEventListener('playing', function () {
  var answers = document.querySelectorAll('button.rate, button.pref, #page-submit');
  if (Array.prototype.every.call(answers, function (b) { return b.disabled; })) window.lockedPlays += 1;
}, true);
"""


def acr_rater_flow(live_server, browser):
    """A rater through an ACR study served at `live_server` (the fixture), in `browser`, every clip played to its
    end: the ratings clicked are the export's, and nothing is flagged but a failed catch trial."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as EC

    wait = waiting(browser, 20)
    browser.get(live_server + "/?PROLIFIC_PID=browserpid1&STUDY_ID=st1&SESSION_ID=se1")
    browser.execute_script(COUNT_LOCKED_PLAYS)
    start = browser.find_element(By.ID, "start")
    assert not start.is_enabled()  # consent first
    browser.find_element(By.ID, "consent").click()
    wait.until(EC.element_to_be_clickable((By.ID, "start"))).click()
    wait.until(EC.visibility_of_element_located((By.ID, "intro")))
    assert "could not possibly be produced by a real person" in browser.find_element(By.ID, "intro").text
    browser.find_element(By.ID, "intro-go").click()

    clicked, n_training = {}, 0
    screenshot = os.environ.get("SAVE_SCREENSHOTS") == "1"
    state_js = (  # the video's src, not its currentSrc, which chromium updates a task later (design_pages.STATE_JS)
        "var vis=['trial','rating-intro','done'].filter(function(id){return !document.getElementById(id).hidden});"
        "var v=document.getElementById('video');"
        "return {section: vis.length ? vis[0] : null,"
        " label: document.getElementById('phase-label').textContent,"
        " count: document.getElementById('trial-count').textContent, ended: v.ended, src: v.src,"
        " disabled: Array.prototype.every.call(document.querySelectorAll('button.rate'),"
        "   function(b){return b.disabled}),"
        " fits: document.documentElement.scrollWidth <= window.innerWidth + 1};"
    )

    def key(s):
        return (s["section"], s["label"], s["count"])

    for _ in range(40):
        wait.until(lambda d: d.execute_script(state_js)["section"])
        s = browser.execute_script(state_js)
        if s["section"] == "done":
            break
        if s["section"] == "rating-intro":
            browser.find_element(By.ID, "rating-go").click()
        else:
            if not s["ended"]:
                assert s["disabled"], "rating buttons must stay disabled until the clip has played to the end"
            assert s["fits"], "no horizontal scrolling on a phone-sized screen"
            if s["label"] == "Example":
                wait.until(EC.element_to_be_clickable((By.ID, "continue"))).click()
                n_training += 1
            else:
                index = int(s["count"].split()[0])
                rating = 1 + index % 5
                btn = wait.until(EC.element_to_be_clickable((By.CSS_SELECTOR, f'button.rate[data-rating="{rating}"]')))
                if screenshot and index == 2:
                    (ROOT / "docs" / "img").mkdir(parents=True, exist_ok=True)
                    browser.save_screenshot(str(ROOT / "docs" / "img" / "rating_page.png"))
                btn.click()
                clicked[int(s["src"].rsplit("/", 2)[1])] = rating  # .../trials/ID/video.mp4
        # the page moves on only once the server has acknowledged the answer
        wait.until(lambda d: d.execute_script(state_js)["section"] and key(d.execute_script(state_js)) != key(s))
    else:
        raise AssertionError("never reached the completion page")
    code = browser.find_element(By.ID, "completion-code").text
    clips = load_manifest(live_server_manifest[0])
    roles = [c.role for c in clips]
    n_catch = sum(c.role == "catch" and c.condition == "BAD" for c in clips)  # acr shows only the bad examples
    assert code and n_training == roles.count("training")
    assert len(clicked) == min(3, roles.count("test")) + n_catch  # 3 test clips + every catch clip
    # Each clip started playing with the rating buttons disabled, as the page's own `playing` events counted: the
    # polls above need not fall inside a 0.8-s clip on a loaded machine.
    assert browser.execute_script("return window.lockedPlays") >= len(clicked)
    errors = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not errors, errors

    r = requests.get(live_server + "/admin/export.csv", headers={"Authorization": "Bearer browser-token"}, timeout=10)
    rows = [row for row in csv.DictReader(io.StringIO(r.text)) if row["external_id"] == "browserpid1"]
    from sqlalchemy import select

    from rating_app.store.db import Trial

    with app_engine(live_server_manifest[1]).connect() as conn:
        clip_of = dict(conn.execute(select(Trial.id, Trial.clip_id)).all())
    assert {row["clip_id"]: int(row["rating"]) for row in rows} == {clip_of[t]: v for t, v in clicked.items()}
    # Watched in full, video fetched: no flag but the failed catch trial's, on every row, where this rater's ratings
    # (1 + index % 5) gave a BAD clip 3 or more (the app's and the report's exclusion, core.study.CATCH_FAIL_AT).
    role = {c.clip_id: (c.role, c.condition) for c in clips}
    failed = any(role[clip_of[t]] == ("catch", "BAD") and v >= 3 for t, v in clicked.items())
    assert {row["flags"] for row in rows} == {"failed_catch" if failed else ""}
    assert all(int(row["watched_ms"]) > 0 for row in rows)
    p = requests.get(
        live_server + "/admin/progress.json", headers={"Authorization": "Bearer browser-token"}, timeout=10
    ).json()
    assert not p["events"], p["events"]  # no failed playback


# What a test reads of the rater's page with sound: the section shown, the trial's count and label, and its videos'
# sound (unmuted, bytes decoded) and ends, in an ACR or a pair trial.
STATE = (
    "var ids=['audio-check','audio-failed','intro','trial','pair','rating-intro','done','error'];"
    "var vis=ids.filter(function(id){return !document.getElementById(id).hidden});"
    "var vs=Array.prototype.slice.call("
    " document.querySelectorAll('#trial:not([hidden]) video, #pair:not([hidden]) video'));"
    "var count=document.querySelector('#pair:not([hidden]) .trial-count')||document.getElementById('trial-count');"
    "return {section: vis.length ? vis[0] : null, count: count.textContent,"
    " label: (document.querySelector('#pair:not([hidden]) .phase-label')||document.getElementById('phase-label'))"
    "   .textContent,"
    " unmuted: vs.every(function(v){return !v.muted}),"
    " decoded: vs.map(function(v){return v.webkitAudioDecodedByteCount||0}),"
    " ended: vs.filter(function(v){return v.src}).map(function(v){return v.ended})};"
)
