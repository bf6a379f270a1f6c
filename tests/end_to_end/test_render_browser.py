"""The rendering targets, done when: a study built from a ZeroEGGS-like speaker (75 joints, fingers, cm, 30 fps,
with speech) and a made-up second system with units = "auto", view = "front", framing = "upper" and
style = ["stick", "solid"] is served to a real browser (on SQLite and on PostgreSQL), which passes the sound check
and rates a few trials with their sound playing; the videos it played, decoded, are at 30 fps and carry the
speech, the figure from the hips to the head fills most of the frame's height, both hands stay inside it, the
solid body covers several times the stick figure's pixels and left and right are told apart by colour."""

import csv
from pathlib import Path

import numpy as np
import pytest
import requests
from helpers.browser import live_server_manifest
from helpers.bvh_fixtures import SPEAKER, write_zeroeggs
from helpers.figure_pixels import classes, decode, height_share, touches_edge
from helpers.own_study_data import NO_GESTURE_MEASURES, speech
from helpers.sound_check import pass_sound_check

from generation.make_stimuli import main as make_stimuli

pytestmark = pytest.mark.browser

STUDY = (
    """reference = "speaker"
seed = 1
n_training = 0
[conditions]
speaker = "real"
SYS_A = "sys_a"
[catch]
n = 0
[skeleton]
units = "auto"
[render]
view = "front"
framing = "upper"
style = ["stick", "solid"]
[audio]
folder = "audio"
"""
    + NO_GESTURE_MEASURES
)  # the gesture measures are not this study's subject


@pytest.fixture(scope="module")
def app_stimuli(tmp_path_factory):
    """The study's manifest: two items, each clip 1.5 s (the browser plays them in real time) in both styles."""
    root = tmp_path_factory.mktemp("speaker")
    (root / "audio").mkdir()
    for k in range(2):
        speech(root / "audio" / f"item{k:02d}.wav", f"item {k + 1}, look at my hands", 1.5)
        for sub, seed in (("real", k), ("sys_a", 100 + k)):
            (root / sub).mkdir(exist_ok=True)
            write_zeroeggs(root / sub / f"item{k:02d}.bvh", frames=45, seed=seed, turns=SPEAKER, degrees=2.0)
    (root / "study.toml").write_text(STUDY)
    args = ["--study", str(root / "study.toml"), "--out", str(root / "out"), "--size", "240", "--quiet"]
    assert make_stimuli(args) == 0
    return str(root / "out" / "manifest.csv")


def _rate_trials(driver, url, n, app):
    """Take a rater (in `driver`) through consent, the sound check and `n` trials, each started by a tap and
    played to its end with its sound; returns the videos' URLs."""
    from helpers.browser import waiting
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as EC

    wait = waiting(driver, 30)
    driver.get(url + "/?PROLIFIC_PID=renderpid1&STUDY_ID=st1&SESSION_ID=se1")
    driver.find_element(By.ID, "consent").click()
    wait.until(EC.element_to_be_clickable((By.ID, "start"))).click()
    pass_sound_check(driver, wait, app)
    state = (
        "var vis=['intro','trial','rating-intro','done'].filter(function(id){"
        " return !document.getElementById(id).hidden});"
        "var v=document.getElementById('video');"
        "return {section: vis.length ? vis[0] : null, src: v.src, ended: v.ended, muted: v.muted,"
        " decoded: v.webkitAudioDecodedByteCount||0, count: document.getElementById('trial-count').textContent};"
    )
    srcs = []
    while len(srcs) < n:
        wait.until(lambda d: d.execute_script(state)["section"])
        s = driver.execute_script(state)
        assert s["section"] != "done", "the session ended before the trials were rated"
        if s["section"] in ("intro", "rating-intro"):
            driver.find_element(By.ID, "intro-go" if s["section"] == "intro" else "rating-go").click()
            wait.until(lambda d: d.execute_script(state)["section"] == "trial")
            continue
        assert not s["muted"], "a study with sound plays its videos unmuted"
        driver.find_element(By.ID, "video").click()  # with sound nothing plays by itself: the rater taps
        wait.until(lambda d: d.execute_script(state)["ended"])
        assert driver.execute_script(state)["decoded"] > 0  # its speech was decoded while it played
        wait.until(EC.element_to_be_clickable((By.CSS_SELECTOR, 'button.rate[data-rating="3"]'))).click()
        srcs.append(s["src"])
        wait.until(
            lambda d: (
                (d.execute_script(state)["section"], d.execute_script(state)["count"]) != (s["section"], s["count"])
            )
        )
    return srcs


def _check(frames, style):
    """Pixel checks on decoded frames of one clip in `style`; returns its figure's mean pixel count."""
    masks = [classes(f) for f in frames[::3]]
    for f, (trunk, left, right) in zip(frames[::3], masks):
        assert left.sum() > 20 and right.sum() > 20  # left and right, each in its own colour
        # both hands inside the frame: no side's pixels at its left, right or top edge (the legs leave at the bottom)
        assert not touches_edge(left) and not touches_edge(right)
        # from the hips to the head's top; the stick's head disc is smaller than the solid's sphere
        assert height_share(f) >= (0.7 if style == "solid" else 0.62)
    return np.mean([(t | le | r).sum() for t, le, r in masks])


@pytest.mark.parametrize("app_db_url", ["postgres"], indirect=True)  # the database is the app's concern
def test_speaker_study_in_a_real_browser(app_stimuli, live_server, browser, tmp_path, request):
    from sqlalchemy import select

    from rating_app.store.db import Trial, app_engine

    srcs = _rate_trials(browser, live_server, 3, live_server_manifest[1])
    with app_engine(live_server_manifest[1]).connect() as conn:
        clip_of = dict(conn.execute(select(Trial.id, Trial.clip_id)).all())
    rows = list(csv.DictReader(open(app_stimuli, newline="")))
    by_id = {r["clip_id"]: r for r in rows}
    for k, src in enumerate(srcs):
        played = by_id[clip_of[int(src.rsplit("/", 2)[1])]]  # .../trials/ID/video.mp4
        (tmp_path / f"{k}.mp4").write_bytes(requests.get(src, timeout=10).content)
        frames, fps = decode(tmp_path / f"{k}.mp4")
        assert fps == 30.0 and len(frames) == 45
        assert has_speech(tmp_path / f"{k}.mp4")
        pixels = {played["style"]: _check(frames, played["style"])}
        # the same motion in the other style, from the study's folder
        (twin,) = [
            r for r in rows if (r["item"], r["condition"]) == (played["item"], played["condition"]) and r != played
        ]
        frames, fps = decode(Path(app_stimuli).parent / twin["video"])
        assert fps == 30.0
        pixels[twin["style"]] = _check(frames, twin["style"])
        assert pixels["solid"] > 3 * pixels["stick"]


def has_speech(path) -> bool:
    """Whether the video's AAC track, decoded by ffmpeg, holds sound above silence."""
    import subprocess

    import imageio_ffmpeg

    raw = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-i", str(path), "-map", "0:a:0", "-f", "s16le", "-"],
        capture_output=True,
        check=True,
    ).stdout
    pcm = np.frombuffer(raw, "<i2").astype(float)
    return len(pcm) > 0 and np.sqrt(np.mean(pcm**2)) > 100
