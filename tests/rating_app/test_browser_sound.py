"""A study with sound in a real browser (issue 32): Debian's chromium plays the page on a phone-sized and a desktop
window. The rater passes the sound check, watches an example and answers a trial whose videos play unmuted,
started by a tap, with their audio decoded. SAVE_SCREENSHOTS=1 writes docs/img/sound_check_*.png and
docs/img/sound_trial_*.png."""

import os

import pytest
from helpers.browser import STATE, chrome
from helpers.own_study_data import NO_GESTURE_MEASURES, make_study
from helpers.paths import ROOT
from helpers.sound_check import pass_sound_check

from generation.make_stimuli import main as make_stimuli
from rating_app import create_app

pytestmark = pytest.mark.browser
IMG = ROOT / "docs" / "img"  # SAVE_SCREENSHOTS=1 writes the pages there


@pytest.fixture(scope="module")
def sound_study(tmp_path_factory):
    root = tmp_path_factory.mktemp("browser_sound")
    study = make_study(root / "in", n_items=3, n_catch=1, audio=True, extra_toml=NO_GESTURE_MEASURES)
    # 2-s clips: the browser plays them in real time
    study.write_text(
        study.read_text().replace("n_training = 1", 'n_training = 1\nlength_s = 2\ndesign = "appropriateness"')
    )
    assert make_stimuli(["--study", str(study), "--out", str(root / "out"), "--size", "96", "--quiet"]) == 0
    return root / "out" / "manifest.csv"


@pytest.fixture
def served(request, sound_study, tmp_path):
    from helpers.servers import in_thread

    design = request.param
    app = create_app(
        manifest=sound_study,
        db_url=f"sqlite:///{tmp_path / 'r.sqlite'}",
        admin_token="browser-token",
        design=design,
        ratings_per_clip=3,
        clips_per_rater=2,
        min_view=0.5,
    )
    with in_thread(app) as url:
        yield app, url


@pytest.mark.parametrize(
    "served, window",
    [("acr", "390,844"), ("appropriateness", "1280,900")],
    indirect=["served"],
    ids=["phone", "desktop"],
)
def test_sound_check_and_a_trial_with_sound(served, window, tmp_path):
    from helpers.browser import waiting
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as EC

    app, url = served
    browser = chrome(tmp_path, window)
    try:
        wait = waiting(browser, 60)
        browser.get(url + "/?PROLIFIC_PID=soundpid1")
        assert "headphones" in browser.find_element(By.ID, "welcome").text.lower()
        browser.find_element(By.ID, "consent").click()
        wait.until(EC.element_to_be_clickable((By.ID, "start"))).click()
        shots = os.environ.get("SAVE_SCREENSHOTS") == "1"
        shot = IMG / f"sound_check_{window.split(',')[0]}.png" if shots else None
        pass_sound_check(browser, wait, app, screenshot=shot)
        wait.until(EC.visibility_of_element_located((By.ID, "intro")))
        browser.find_element(By.ID, "intro-go").click()

        answered = 0
        for _ in range(12):
            wait.until(lambda d: d.execute_script(STATE)["section"] in ("trial", "pair", "rating-intro"))
            s = browser.execute_script(STATE)
            if s["section"] == "rating-intro":
                browser.find_element(By.ID, "rating-go").click()
                wait.until(lambda d: d.execute_script(STATE)["section"] != "rating-intro")
                continue
            assert s["unmuted"], "a study with sound plays its videos unmuted"
            # With sound nothing plays by itself: the rater taps the (first) video.
            first = browser.find_element(By.CSS_SELECTOR, "#trial video" if s["section"] == "trial" else "#video-a")
            first.click()
            wait.until(lambda d: all(d.execute_script(STATE)["ended"]))
            s = browser.execute_script(STATE)
            assert all(n > 0 for n in s["decoded"] if n is not None), s  # their sound was decoded while they played
            if s["label"] == "Example":
                button = (By.ID, "continue") if s["section"] == "trial" else (By.ID, "pair-continue")
            else:
                button = (
                    By.CSS_SELECTOR,
                    "button.rate[data-rating='4']" if s["section"] == "trial" else "button.pref[data-preference='1']",
                )
                answered += 1
            if shots and s["label"] != "Example":
                browser.save_screenshot(str(IMG / f"sound_trial_{app.config['STUDY_DESIGN']}.png"))
            wait.until(EC.element_to_be_clickable(button)).click()
            if answered == 1:
                break
            # the page moves on once the server has acknowledged the answer
            key = (s["section"], s["label"], s["count"])
            wait.until(lambda d: (lambda t: (t["section"], t["label"], t["count"]) != key)(d.execute_script(STATE)))
        assert answered == 1
        errors = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
        assert not errors, errors
    finally:
        browser.quit()
