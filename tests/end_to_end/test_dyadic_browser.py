"""Issue 52 end to end: a two-person study from a conversation in Seamless Interaction's layout that the test writes
(tests/helpers/seamless_fixtures.py: SMPL-H through a synthetic body model, invalid frames, two WAV tracks, word
times), cut into `listening` items (dyadic) or `keyword` items (semantic), rendered with both people and captions,
served in the dyadic or semantic design to Debian's chromium. The rater passes the sound check and answers a pair;
the two videos the page played are then read back from the app: two figures, the interlocutor in one colour and the
same in both, the captions on (the keyword highlighted in semantic), both voices heard at -23 LUFS. A small crowd
then fills the study through the API and the report of the export is the design's."""

import csv
import io

import numpy as np
import pytest
import requests
from helpers import figure_pixels, seamless_fixtures
from helpers.browser import STATE, chrome
from helpers.design_client import complete
from helpers.servers import in_thread
from helpers.sound_check import pass_sound_check, sample_of
from helpers.voices import decoded_audio, ffmpeg_loudness, voice_energy

from analysis.designs import Options
from analysis.report import build_report
from moglow_eval.core import colours
from rating_app import create_app
from rating_app.store.db import app_engine

pytestmark = pytest.mark.browser


@pytest.fixture(params=["dyadic", "semantic"])
def built(request):
    """The design's shared two-person set (tests/conftest.py, made once a run)."""
    out, _, sources = request.getfixturevalue(f"{request.param}_set")
    return request.param, out, sources


def study_app(out, design, db, **settings):
    """The app on the set in `out`, a fresh SQLite database `db`, two answers a unit, no limit per address."""
    return create_app(manifest=out / "manifest.csv", db_url=f"sqlite:///{db}", admin_token="browser-token",
                      design=design, ratings_per_clip=2, sessions_per_client=0, **settings)  # fmt: skip


@pytest.fixture
def served(built, tmp_path):
    design, out, sources = built
    app = study_app(out, design, tmp_path / "r.sqlite", clips_per_rater=3, min_view=0.5)
    with in_thread(app) as url:
        yield design, app, url, sources


LAYOUT = """
var box = function (id) { var r = document.getElementById(id).getBoundingClientRect();
  return [r.left, r.top, r.width, r.height]; };
return {a: box('video-a'), b: box('video-b'), view: [window.innerWidth, window.innerHeight],
  fits: document.documentElement.scrollWidth <= window.innerWidth + 1,
  hint: document.querySelector('#pair .turn-hint').getBoundingClientRect().height > 0};
"""


def wide_layout(browser):
    """The pair on screen as a desktop (1280x900), a phone held upright (390x844) and turned (844x390) show it: each
    video in the wide frame's shape (3:1: the manifest's size), one above the other; on the desktop both on the
    screen at once and large, on the upright phone as wide as the screen, nothing wider than it, and a word to turn
    it; on the turned phone each nearly as high as the screen."""
    for window, phone in (((1280, 900), False), ((390, 844), True), ((844, 390), None)):
        browser.set_window_size(*window)
        s = browser.execute_script(LAYOUT)
        (ax, ay, aw, ah), (bx, by, bw, bh), (vw, vh) = s["a"], s["b"], s["view"]
        assert abs(aw / ah - 3) < 0.05 and abs(bw / bh - 3) < 0.05, s  # the wide frame, neither cut nor padded
        assert by >= ay + ah and abs(ax - bx) < 1 and aw == bw, s  # A above B, alike
        assert s["fits"] and ax >= 0 and ax + aw <= vw, s
        assert s["hint"] == bool(phone), s
        if phone is None:  # the phone turned sideways: each video nearly the screen's height, scrolled to in turn
            assert ah >= 0.75 * vh, s
        elif phone:
            assert aw >= 0.85 * vw, s  # as wide as the screen
        else:
            assert by + bh <= vh and aw >= 0.6 * vw, s  # both on the screen at once, and large
    browser.set_window_size(1280, 900)


def answer_a_pair(browser, wait, url, app):
    """Consent, the sound check, the introduction, then pairs until the first test pair is answered; returns the
    URLs of that pair's two videos. The first pair's layout is checked on a desktop and a phone (wide_layout)."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as EC

    browser.get(url + "/?PROLIFIC_PID=dyadpid1")
    browser.find_element(By.ID, "consent").click()
    wait.until(EC.element_to_be_clickable((By.ID, "start"))).click()
    pass_sound_check(browser, wait, app)
    wait.until(EC.visibility_of_element_located((By.ID, "intro")))
    browser.find_element(By.ID, "intro-go").click()
    looked = False
    for _ in range(12):
        wait.until(lambda d: d.execute_script(STATE)["section"] in ("pair", "rating-intro"))
        s = browser.execute_script(STATE)
        if s["section"] == "rating-intro":
            browser.find_element(By.ID, "rating-go").click()
            wait.until(lambda d: d.execute_script(STATE)["section"] != "rating-intro")
            continue
        assert s["unmuted"]
        if s["label"] == "Example" and not looked:
            wide_layout(browser)
            looked = True
        srcs = [browser.find_element(By.ID, v).get_attribute("src") for v in ("video-a", "video-b")]
        browser.find_element(By.ID, "video-a").click()  # with sound nothing plays by itself: a tap
        wait.until(lambda d: all(d.execute_script(STATE)["ended"]))
        assert all(n > 0 for n in browser.execute_script(STATE)["decoded"])  # their sound was decoded
        if s["label"] == "Example":
            wait.until(EC.element_to_be_clickable((By.ID, "pair-continue"))).click()
        else:
            wait.until(EC.element_to_be_clickable((By.CSS_SELECTOR, "button.pref[data-preference='1']"))).click()
            return srcs
        key = (s["section"], s["label"], s["count"])
        wait.until(lambda d: (lambda t: (t["section"], t["label"], t["count"]) != key)(d.execute_script(STATE)))
    raise AssertionError("never reached a test pair")


def test_a_two_person_study_in_a_real_browser(served, tmp_path):
    from helpers.browser import waiting
    from selenium.webdriver.common.by import By

    design, app, url, sources = served
    browser = chrome(tmp_path, "1280,900")
    try:
        if design == "dyadic":  # the welcome names the interlocutor's colour, from the study (study.json)
            browser.get(url + "/?PROLIFIC_PID=dyadpid0")
            named = browser.find_element(By.CSS_SELECTOR, ".interlocutor-colour").text
            swatch = browser.find_element(By.CSS_SELECTOR, ".swatch rect").value_of_css_property("fill")
            assert swatch == "rgb(102, 153, 112)", swatch  # rendering.raster.PARTNER_COLOUR, the default
            assert "grey" not in browser.find_element(By.ID, "welcome").text
        srcs = answer_a_pair(browser, waiting(browser, 90), url, app)
        cookies = {c["name"]: c["value"] for c in browser.get_cookies()}
        errors = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
        assert not errors, errors
    finally:
        browser.quit()
    videos = []
    for k, src in enumerate(srcs):  # the bytes the page was sent, read back
        r = requests.get(src, cookies=cookies, timeout=30)
        assert r.status_code == 200, (src, r.status_code)
        (tmp_path / f"{k}.mp4").write_bytes(r.content)
        videos.append(tmp_path / f"{k}.mp4")
    assert videos[0].stat().st_size == videos[1].stat().st_size  # one size: the bytes tell nothing
    frames = [figure_pixels.decode(v)[0] for v in videos]
    means = []
    for t in range(0, len(frames[0]), 10):
        pa, pb = (figure_pixels.partner(f[t]) for f in frames)
        assert figure_pixels.agent(frames[0][t]).sum() > 60 and pa.sum() > 60, t  # two figures
        both = pa & pb
        means.append([frames[0][t][both].mean(0), frames[1][t][both].mean(0)])
    # The interlocutor's one colour, the same in both videos: averaged over the clip, as one lossy frame's mean can
    # stray by a few levels where the encoder spent its bits elsewhere.
    means = np.asarray(means)
    assert abs(means[:, 0].mean(0) - means[:, 1].mean(0)).max() < 4, means
    # The page's words are true: the colour it names is the colour the videos draw the interlocutor in.
    if design == "dyadic":
        drawn = colours.colour_name(means.mean((0, 1)) / 255)
        assert named == drawn == "green", (named, drawn)
    # The captions are on while words are said (the same in both videos: their rows alike).
    text = [figure_pixels.caption_text(f).sum() for f in frames[0]]
    assert max(text) > 40, max(text)
    if design == "semantic":
        assert max(figure_pixels.highlight(f).sum() for f in frames[0]) > 20  # the keyword highlighted
    sounds = [decoded_audio(v)[:, 0] for v in videos]
    assert (sounds[0] == sounds[1]).all()  # the same sound in both
    assert abs(ffmpeg_loudness(videos[0]) - (-23.0)) <= 1.0
    voices = [voice_energy(sounds[0], f0) for f0 in seamless_fixtures.VOICE_HZ]
    noise = voice_energy(0 * sounds[0] + 1e-3, seamless_fixtures.VOICE_HZ[0])
    assert max(voices) > 100 * max(noise, 1e-12) and min(voices) > 0  # both people's voices are in the mix


def test_the_crowd_fills_it_and_the_report_is_the_designs(built, tmp_path):
    """API raters (no viewing wait) pass the sound check (the sample's digits from audio_check.csv) and answer every
    pair, preferring the matched motion; the export names the design's mismatch column and the report is the
    design's."""
    design, out, _ = built
    app = study_app(out, design, tmp_path / "crowd.sqlite", min_view=0)
    client = app.test_client()
    digits = audio_check_answers(out / "manifest.csv")
    with open(out / "manifest.csv", newline="") as f:
        worse = {r["clip_id"] for r in csv.DictReader(f) if r["condition"] == "BAD" or r["motion_item"]}

    def prefer(trial):  # the matched motion over the mismatched, the real one over the broken catch clip
        return -1 if trial["a"]["clip_id"] in worse else 1

    n = 0
    for _ in range(40):
        r = client.post("/api/sessions", json={})
        if r.status_code == 409:
            break
        token = r.json["session"]
        assert client.get(f"/api/sessions/{token}/audio-check.wav").status_code == 200  # its sample is drawn
        answer = digits[sample_of(app, token)]
        assert client.post(f"/api/sessions/{token}/audio-check", json={"answer": answer}).json == {"passed": True}
        complete(client, token, pref=prefer)
        n += 1
    assert n >= 2
    export = client.get("/admin/export.csv", headers={"Authorization": "Bearer browser-token"})
    assert export.status_code == 200
    text = export.get_data(as_text=True)
    app_engine(app).dispose()
    rows = list(csv.DictReader(io.StringIO(text)))
    column = {"dyadic": "mismatched_interlocutor", "semantic": "mismatched_utterance"}[design]
    assert rows and column in rows[0] and "mismatched_item" not in rows[0]
    (tmp_path / "pairs.csv").write_text(text)
    options = Options(n_boot=50, metrics_path=str(out / "metrics.csv"))
    stats = build_report(tmp_path / "pairs.csv", tmp_path / "report", options, quiet=True)
    assert stats["design"] == design and stats["mas"]
    assert all(v["mas"] == 1.0 for v in stats["mas"].values())  # every answer preferred the matched motion
    # The build's gesture measures stand beside the crowd's result, each with its rank agreement.
    measures = stats["measures"]
    assert measures["score"] == {"dyadic": "MAS", "semantic": "alignment score"}[design]
    agreed = {r["measure"]: r for r in measures["agreement"]}
    assert {"fgd", "hellinger_speed_hands", "diversity"} <= set(agreed), sorted(agreed)
    assert {r["system"] for r in measures["values"]} >= set(stats["mas"])
    assert "Kendall's tau-b" in stats["methods"]
    assert "Objective measures and how far each agrees with people" in (tmp_path / "report" / "report.html").read_text()


def audio_check_answers(manifest):
    """{sample stem: digits} of the set's audio_check.csv (beside the manifest)."""
    path = manifest.parent / "audio_check.csv"
    with open(path, newline="") as f:
        return {row["file"].split("/")[1][:-4]: row["answer"] for row in csv.DictReader(f)}
