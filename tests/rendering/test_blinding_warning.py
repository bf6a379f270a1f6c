"""A study of your own whose catch clips the coded sizes give away is built, but with a warning naming the signal
(CONTRACTS §4): the study's own catch clips of a body that stands still (its first pose held), whose still frames
cost nearly nothing, among test clips that move throughout."""

import csv

import numpy as np
import pytest
from helpers.own_study_data import make_study

from generation.make_stimuli import main as make_stimuli
from generation.stimuli.summary import blinding_warning
from moglow_eval.core.ranks import auc
from rendering.blinding import CHANCE_P, SIZE_AUC_BAND, chance_of_worst, coded_tells, worst_signal
from rendering.mp4_layout import content_signal


def _sizes(pairs):
    return [{"NAL type 1 bytes": float(a), "NAL type 5 bytes": float(b)} for a, b in pairs]


TEST_SIZES = _sizes((i, (7 * i) % 30) for i in range(30))


def test_a_few_catch_clips_outside_the_band_by_chance_are_not_a_give_away():
    """Four catch clips whose sizes fall among the test clips' put a signal outside the band (AUC 0.78) as a random
    split of the same videos often does; four that all cost less than every test clip do not."""
    catch = _sizes(((29.5, 3.5), (27.5, 17.5), (24.5, 9.5), (10.5, 22.5)))
    name, value = worst_signal(catch, TEST_SIZES)
    assert name == "NAL type 1 bytes" and value == pytest.approx(94 / 120) and value > SIZE_AUC_BAND[1]
    assert value == auc([c[name] for c in catch], [t[name] for t in TEST_SIZES])
    assert chance_of_worst(catch, TEST_SIZES) > 2 * CHANCE_P
    still = _sizes(((-1, 3.5), (-2, 17.5), (-3, 9.5), (-4, 22.5)))
    assert worst_signal(still, TEST_SIZES) == ("NAL type 1 bytes", 0.0)
    assert chance_of_worst(still, TEST_SIZES) < CHANCE_P / 10
    assert chance_of_worst(still, TEST_SIZES, seed=3) == chance_of_worst(still, TEST_SIZES, seed=3)  # seeded


@pytest.mark.full  # make_study's takes are in ../shared
def test_a_pool_of_still_catch_clips_is_warned_about(tmp_path, capsys):
    study = make_study(tmp_path / "in", n_items=8)
    (tmp_path / "in" / "still").mkdir()
    for k in range(4):  # four catch items: each item's body, its first pose held (.npy as sys_a's, skeleton.json)
        moving = np.load(tmp_path / "in" / "sys_a" / f"item{k:02d}.npy")
        np.save(tmp_path / "in" / "still" / f"item{k:02d}.npy", np.repeat(moving[:1], len(moving), axis=0))
    text = study.read_text().replace('make = ["jitter", "freeze", "swap"]', 'folder = "still"')
    text = "\n".join(line for line in text.splitlines() if not line.startswith("n = "))
    study.write_text(text.replace("n_training = 1", "n_training = 0\nlength_s = 1.5"))
    assert make_stimuli(["--study", str(study), "--out", str(tmp_path / "out"), "--size", "64", "--quiet"]) == 0
    err = capsys.readouterr().err
    manifest = list(csv.DictReader(open(tmp_path / "out" / "manifest.csv")))
    name, value = coded_tells(
        [tmp_path / "out" / m["video"] for m in manifest if m["condition"] == "BAD"],
        [tmp_path / "out" / m["video"] for m in manifest if m["role"] == "test"],
    )
    assert content_signal(name) and not 0.25 <= value <= 0.75
    assert "% of draws" in err  # how often chance alone is as far out, named
    warned = [line.split("] ", 1)[-1] for line in err.splitlines() if "coded sizes tell" in line]
    assert warned == [blinding_warning(tmp_path / "out", manifest)]  # shown even with --quiet
    assert "4 catch clips" in warned[0] and name in warned[0]
    # with the catch clips left out there is nothing to tell
    assert blinding_warning(tmp_path / "out", [m for m in manifest if m["condition"] != "BAD"]) is None
