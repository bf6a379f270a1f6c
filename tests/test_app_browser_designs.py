"""A real browser (Debian chromium, headless) takes a rater through a pairwise and a parallel study against the app
served over HTTP, with the server's full viewing rule (MIN_VIEW 1): the answers it gave appear in the export.
The pairwise page is checked on a phone (A above B, played one after the other) and on a wide screen (side by
side). SAVE_SCREENSHOTS=1 writes docs/img/pairwise_page.png and docs/img/parallel_page.png
(SCREENSHOT_MANIFEST=path/manifest.csv to show real stimuli)."""

import csv
import io
import os
import threading
from pathlib import Path

import pytest
import requests
from helpers.fake_stimuli import write_fake_stimuli
from sqlalchemy import select
from test_app_browser import browser  # noqa: F401  (the fixture)

from rating_app import create_app
from rating_app.store.db import TrialClip, app_engine
from rating_app.store.manifest import load_manifest

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def design_stimuli(tmp_path_factory):
    return os.environ.get("SCREENSHOT_MANIFEST") or write_fake_stimuli(
        tmp_path_factory.mktemp("design_stimuli"), catch_nat=True
    )


def serve(manifest, db_url, design):
    from werkzeug.serving import make_server

    app = create_app(
        manifest=manifest,
        db_url=db_url,
        admin_token="browser-token",
        ratings_per_clip=5,
        clips_per_rater=3,
        design=design,
    )
    server = make_server("127.0.0.1", 0, app, threaded=True)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    return app, server, thread


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
  ended: vids.map(function (v) { return v.ended; }), srcs: vids.map(function (v) { return v.currentSrc; }),
  prefs_disabled: Array.prototype.every.call(document.querySelectorAll('button.pref'),
                                             function (b) { return b.disabled; }),
  submit_disabled: document.getElementById('page-submit').disabled,
  a: box('video-a'), b: box('video-b'),
  fits: document.documentElement.scrollWidth <= window.innerWidth + 1};
"""


def _trial_of(src):
    return int(src.rsplit("/", 3)[1])  # .../trials/ID/clips/A.mp4


def _run_flow(browser, url, design, answer):  # noqa: F811
    """Consent, familiarisation, every trial until the completion code; `answer(state)` answers a rating trial
    and returns (trial id, value). Returns ({trial id: value}, number of familiarisation trials, code)."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as EC
    from selenium.webdriver.support.ui import WebDriverWait

    wait = WebDriverWait(browser, 30)
    browser.get(url + f"/?PROLIFIC_PID={design}pid&STUDY_ID=st1&SESSION_ID=se1")
    browser.find_element(By.ID, "consent").click()
    wait.until(EC.element_to_be_clickable((By.ID, "start"))).click()
    wait.until(EC.visibility_of_element_located((By.ID, "intro")))
    browser.find_element(By.ID, "intro-go").click()
    given, n_training, before_end = {}, 0, 0

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
                before_end += 1
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
    assert before_end >= 1
    return given, n_training, browser.find_element(By.ID, "completion-code").text


def play_page(browser, wait):  # noqa: F811
    """Click every clip of a parallel page in turn and wait until it has played to the end."""
    from selenium.webdriver.common.by import By

    videos = browser.find_elements(By.CSS_SELECTOR, "#page-clips video")
    for i, v in enumerate(videos):
        v.click()
        wait.until(lambda d: d.execute_script(f"return document.querySelectorAll('#page-clips video')[{i}].ended"))


def _export(url, pid):
    r = requests.get(url + "/admin/export.csv", headers={"Authorization": "Bearer browser-token"}, timeout=10)
    assert r.status_code == 200
    return [row for row in csv.DictReader(io.StringIO(r.text)) if row["external_id"] == pid], r


def _shown(app):
    with app_engine(app).connect() as conn:
        rows = conn.execute(select(TrialClip.trial_pk, TrialClip.label, TrialClip.clip_id)).all()
    out = {}
    for t, label, clip in rows:
        out.setdefault(t, {})[label] = clip
    return out


def _screenshot(browser, name):  # noqa: F811
    if os.environ.get("SAVE_SCREENSHOTS") == "1":
        (ROOT / "docs" / "img").mkdir(parents=True, exist_ok=True)
        browser.save_screenshot(str(ROOT / "docs" / "img" / name))


@pytest.mark.parametrize("app_db_url", ["postgres"], indirect=True)
def test_pairwise_flow_in_a_real_browser(design_stimuli, app_db_url, browser):  # noqa: F811
    from selenium.webdriver.common.by import By

    app, server, thread = serve(design_stimuli, app_db_url, "pairwise")
    url = f"http://127.0.0.1:{server.server_port}"
    levels = [2, 1, 0, -1, -2]
    layouts = []
    try:

        def answer(s, wait):
            from selenium.webdriver.support import expected_conditions as EC

            index = int(s["count"].split()[0])
            layouts.append(("phone", s["a"], s["b"]))
            if index == 1:  # the same page on a wide screen: A and B side by side
                browser.set_window_size(1280, 900)
                wide = browser.execute_script(STATE_JS)
                layouts.append(("wide", wide["a"], wide["b"]))
            pref = levels[index % 5]
            btn = wait.until(EC.element_to_be_clickable((By.CSS_SELECTOR, f'button.pref[data-preference="{pref}"]')))
            if index == 1:
                _screenshot(browser, "pairwise_page.png")
                browser.set_window_size(390, 844)
            btn.click()
            return _trial_of(s["srcs"][0]), pref

        given, n_training, code = _run_flow(browser, url, "pairwise", answer)
        rows, resp = _export(url, "pairwisepid")
        shown = _shown(app)
    finally:
        server.shutdown()
        thread.join(5)
        app_engine(app).dispose()
    assert code and n_training >= 1
    assert "pairs.csv" in resp.headers["Content-Disposition"]
    n_catch_pairs = sum(c.role == "catch" and c.condition == "BAD" for c in load_manifest(design_stimuli))
    assert len(given) == 3 + n_catch_pairs
    assert {(row["clip_a"], row["clip_b"]): int(row["preference"]) for row in rows} == {
        (shown[t]["A"], shown[t]["B"]): v for t, v in given.items()
    }
    assert sum(row["role"] == "catch" for row in rows) == n_catch_pairs
    assert all(row["flags"] == "" and row["item"] for row in rows)
    phone = [(a, b) for kind, a, b in layouts if kind == "phone"]
    assert all(b[1] >= a[2] - 1 for a, b in phone), "on a phone B comes below A"
    wide = [(a, b) for kind, a, b in layouts if kind == "wide"]
    assert wide and all(abs(a[1] - b[1]) < 2 and b[0] > a[0] for a, b in wide), "side by side on a wide screen"
    errors = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not errors, errors


@pytest.mark.parametrize("app_db_url", ["postgres"], indirect=True)
def test_parallel_flow_in_a_real_browser(design_stimuli, app_db_url, browser):  # noqa: F811
    from selenium.webdriver.common.by import By

    app, server, thread = serve(design_stimuli, app_db_url, "parallel")
    url = f"http://127.0.0.1:{server.server_port}"
    try:

        def answer(s, wait):
            from selenium.webdriver.support import expected_conditions as EC

            index = int(s["count"].split()[0])
            if index == 1:
                browser.set_window_size(1280, 900)
            play_page(browser, wait)
            sliders = browser.find_elements(By.CSS_SELECTOR, "#page-clips input[type=range]")
            values = {}
            for i, sl in enumerate(sliders):
                assert sl.is_enabled()
                v = (17 * (i + 1) + 7 * index) % 101
                browser.execute_script(
                    "arguments[0].value = arguments[1];arguments[0].dispatchEvent(new Event('input'));", sl, str(v)
                )
                values[sl.get_attribute("data-clip-id")] = v
            btn = wait.until(EC.element_to_be_clickable((By.ID, "page-submit")))
            if index == 1:
                _screenshot(browser, "parallel_page.png")
                browser.set_window_size(390, 844)
            btn.click()
            return _trial_of(s["srcs"][0]), values

        given, n_training, code = _run_flow(browser, url, "parallel", answer)
        rows, resp = _export(url, "parallelpid")
    finally:
        server.shutdown()
        thread.join(5)
        app_engine(app).dispose()
    assert code and n_training >= 1
    n_catch_pages = len({c.item for c in load_manifest(design_stimuli) if c.role == "catch"})
    assert len(given) == 3 + n_catch_pages
    pages = {}
    for row in rows:
        pages.setdefault(row["page_id"], {})[row["clip_id"]] = int(row["rating"])
        assert row["flags"] == "" and 0 <= int(row["rating"]) <= 100
    assert sorted(map(sorted, (p.items() for p in pages.values()))) == sorted(
        map(sorted, (v.items() for v in given.values()))
    )
    assert {p for p in pages} == {f"p{t}" for t in given}
    errors = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert not errors, errors
